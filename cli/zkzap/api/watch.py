"""Live register polling of several actuators: one Load Data per ID per poll.

The IR protocol has no sync read, so a poll asks each actuator in turn. The registers asked
for are read as one contiguous block from the lowest to the highest address (registers in
between come along for free); only when the gap between two asked registers is wider than
what another Load Data costs on the wire (:func:`split_gap`) is the block split.

:class:`Watcher` yields one snapshot row per actuator and poll: ``time`` (ISO 8601 UTC, the
time of the read), ``t`` (seconds since the start), ``poll``, ``id``, each register's raw
value by name, ``errors`` (error bit names), ``status`` (``ok``, ``no-reply``, ``bad-reply``)
and ``rtt_ms``; a port that fails ends the watch (:class:`~zkzap.errors.PortError`). A failed
read gives a row with null values and the watch goes on; per-ID link health is kept in
:attr:`Watcher.health`.

:func:`wire_limit` is the fastest poll rate the line allows: every Load and reply on the wire
at 10 bits a byte, plus a 12Lf's own turnaround per transaction. A read that fails is ``no-reply`` only when nothing came back;
garbled replies (a collision: two actuators with one ID; or a line fault) are ``bad-reply``.

Nothing here imports click or rich.
"""

from __future__ import annotations

import time
from collections import deque

from ..codec import zap
from ..errors import BadReply, NoReply, UsageError
from ..link.port import wire_time
from ..link.stop import pause

#: The actuator's processing time before it answers (seconds): a 12Lf's own, the policy's floor.
from ..link.zap_timing import FLOOR as TURNAROUND  # noqa: E402
#: Bytes of a Load Data command and of a reply without data.
LOAD_BYTES = 9
REPLY_BYTES = 7


#: Registers holding a rod position: with scales, a row gives each in mm too.
MM_REGISTERS = ("goal-position", "present-position", "short-stroke-limit", "long-stroke-limit")


def split_gap(baud: int) -> int:
    """Unrequested bytes worth reading through rather than sending another Load: a second
    transaction costs its own command and reply header plus a turnaround."""
    return LOAD_BYTES + REPLY_BYTES + int(TURNAROUND * baud / 10)


def plan_reads(registers, baud: int = 57600, regmap=None) -> list:
    """[(address, length, [Register, ...]), ...]: the Load Data reads covering ``registers``.
    On a Modbus map (``regmap``, 16-bit registers): ``length`` counts registers, and a read spans
    only addresses the map has (a gap would be answered with an exception)."""
    regs = sorted(set(registers), key=lambda r: r.address)
    if not regs:
        raise UsageError("watch: no register given")
    if regmap is not None and regmap.protocol == "modbus":
        return _modbus_reads(regs, regmap)
    gap = split_gap(baud)
    reads = []
    for reg in regs:
        if reads and reg.address - (reads[-1][0] + reads[-1][1]) <= gap:
            start = reads[-1][0]
            reads[-1][1] = max(reads[-1][1], reg.address + reg.size - start)
            reads[-1][2].append(reg)
        else:
            reads.append([reg.address, reg.size, [reg]])
    for address, length, _ in reads:
        if address + length > 0x100:
            raise UsageError(f"watch: a read from 0x{address:02X} of {length} bytes runs past address 0xFF")
    return [tuple(r) for r in reads]


def _modbus_reads(regs, regmap):
    from ..codec.modbus import MAX_READ

    reads = []
    for reg in regs:
        if reads:
            start, count, got = reads[-1]
            between = range(start + count, reg.address)
            if all(a in regmap.owner for a in between) and reg.address - start < MAX_READ:
                reads[-1][1] = reg.address + 1 - start
                got.append(reg)
                continue
        reads.append([reg.address, 1, [reg]])
    return [tuple(r) for r in reads]


def _read_bytes(length, regs):
    """Bytes of one read on the wire, request and reply: Load Data, or Read Holding Registers."""
    if regs and regs[0].byteorder == "big":
        return 8 + 5 + 2 * length
    return LOAD_BYTES + REPLY_BYTES + length


def poll_time(reads, baud: int, n_ids: int, turnaround: float = TURNAROUND) -> float:
    """Seconds one poll of ``n_ids`` actuators takes on the wire (no host overhead)."""
    per_id = sum(wire_time(_read_bytes(length, regs), baud) + turnaround for _, length, regs in reads)
    return per_id * n_ids


def wire_limit(reads, baud: int, n_ids: int, turnaround: float = TURNAROUND) -> float:
    """Polls per second the line allows."""
    return 1.0 / poll_time(reads, baud, n_ids, turnaround)


class Health:
    """Link health of one actuator, counted in polls (one row each): asked, answered, failed
    (of which garbled), the last round trip, the time of the last good read, the error bits
    seen, and ``silent_s``: the seconds of the watch it did not answer (from each unanswered
    read back to this actuator's read before it, or the start)."""

    __slots__ = ("asked", "answered", "failed", "garbled", "last_rtt", "last_ok", "errors", "last_status",
                 "silent_s", "last_read")

    def __init__(self):
        self.asked = self.answered = self.failed = self.garbled = 0
        self.last_rtt = None
        self.last_ok = None
        self.errors = set()
        self.last_status = None
        self.silent_s = 0.0
        self.last_read = None

    @property
    def loss(self) -> float:
        return self.failed / self.asked if self.asked else 0.0


#: The share of a watch an actuator may go unanswered before the watch fails (``zap watch``:
#: exit 3): more than half of the run, a bus that was dead for most of it.
MOSTLY_SILENT = 0.5


class Watcher:
    """Poll ``registers`` of ``ids`` on ``bus``.

    ``rate`` (Hz, None: as fast as the line allows) paces the polls; :meth:`rows` yields
    snapshot rows until ``count`` polls, ``duration`` seconds, or every ID meets every
    ``until`` condition (:class:`zkzap.api.expr.Condition` on register names). ``history``
    keeps the last values per ID and register (for sparklines).
    """

    def __init__(self, bus, ids, registers, *, rate=None, count=None, duration=None, until=(), retries=0,
                 history=40, clock=time.monotonic, sleep=pause, scales=None):
        self.bus = bus
        self.ids = list(ids)
        self.registers = list(dict.fromkeys(registers))
        for c in until:
            c.field = c.field.replace("_", "-")
        regmap = bus.family.regmap
        self.reads = plan_reads(self.registers + [regmap.register(c.field) for c in until], bus.baud, regmap)
        self.shown = [r for _, _, regs in self.reads for r in regs]
        self.rate = rate
        self.count = count
        self.duration = duration
        self.until = list(until)
        self.retries = retries
        self.health = {i: Health() for i in self.ids}
        self.latest = {i: {} for i in self.ids}
        self.history = {i: {r.name: deque(maxlen=history) for r in self.shown} for i in self.ids}
        self.polls = 0
        self.started = None
        self._clock = clock
        self._sleep = sleep
        self.stopped_by = None
        self.scales = scales or {}
        """{ID: :class:`zkzap.api.units.Scale`}: rows get ``NAME_mm`` beside each position register."""
        self.mm = [r for r in self.shown if r.name in MM_REGISTERS] if self.scales else []

    @property
    def elapsed(self) -> float:
        return 0.0 if self.started is None else self._clock() - self.started

    @property
    def achieved(self) -> float:
        """Polls per second so far."""
        t = self.elapsed
        return self.polls / t if t > 0 else 0.0

    def limit(self) -> float:
        return wire_limit(self.reads, self.bus.baud, len(self.ids))

    def _read(self, ident):
        row = {"time": None, "t": None, "poll": self.polls + 1, "id": ident}
        for r in self.shown:
            row[r.name] = None
        h = self.health[ident]
        status, errors, rtt = "ok", [], 0.0
        for address, length, regs in self.reads:
            try:
                reply, values = self.bus.read_block(ident, address, length, check=False, retries=self.retries)
            except NoReply:
                status = "no-reply"
            except BadReply:
                status = "bad-reply"
            else:
                rtt += reply.rtt
                errors = sorted(set(errors) | set(reply.errors))
                for reg, raw in values:
                    if reg.name in row:
                        row[reg.name] = raw
                continue
        h.asked += 1
        if status != "ok":
            h.failed += 1
        if status == "bad-reply":
            h.garbled += 1
        now = self._clock()
        if status != "ok":
            h.silent_s += now - (self.started if h.last_read is None else h.last_read)
        h.last_read = now
        row["time"] = _iso(time.time())
        row["t"] = round(now - self.started, 4)
        scale = self.scales.get(ident)
        for r in self.mm:
            row[f"{r.name}_mm"] = None if scale is None or row[r.name] is None else scale.mm(row[r.name])
        row["errors"] = errors
        row["status"] = status
        row["rtt_ms"] = round(rtt * 1000, 2) if status == "ok" else None
        h.last_status = status
        if status == "ok":
            h.answered += 1
            h.last_rtt = rtt
            h.last_ok = now
            h.errors.update(errors)
            self.latest[ident] = row
            for r in self.shown:
                self.history[ident][r.name].append(row[r.name])
        return row

    def mostly_silent(self, share: float = MOSTLY_SILENT) -> dict:
        """``{ID: silent seconds}`` of the actuators that answered at some time but were silent
        for more than ``share`` of the watch, in time and in reads (a bus that died: its rows
        are there, but most are empty; a failed read waits its whole window, so one lost read of
        a short watch is not "most of it"). Those that never answered are not here
        (:attr:`health` says so: answered 0)."""
        t = self.elapsed
        return {i: h.silent_s for i, h in self.health.items()
                if h.answered and t > 0 and h.silent_s > share * t and h.failed > share * h.asked}

    def done(self) -> bool:
        if self.count is not None and self.polls >= self.count:
            self.stopped_by = "count"
            return True
        if self.duration is not None and self.elapsed >= self.duration:
            self.stopped_by = "duration"
            return True
        if self.until and self.polls and all(
                all(c.holds(self.latest[i].get(c.field)) for c in self.until) for i in self.ids):
            self.stopped_by = "until"
            return True
        return False

    def rows(self):
        """Snapshot rows, poll after poll, until a stop condition holds."""
        self.started = self._clock()
        period = 1.0 / self.rate if self.rate else 0.0
        while not self.done():
            if period:
                due = self.started + self.polls * period
                wait = due - self._clock()
                if wait > 0:
                    if self.duration is not None:
                        wait = min(wait, max(0.0, self.started + self.duration - self._clock()))
                    self._sleep(wait)
                    if self.done():
                        break
            batch = [self._read(i) for i in self.ids]
            self.polls += 1
            yield from batch


def _iso(t: float) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(t)) + f".{int(t % 1 * 1000):03d}Z"


def until_fields(registers=None):
    """Names allowed in ``--until``: every register of the map (``registers``; default the
    12Lf's), in kebab or snake case."""
    names = {r.name for r in (zap.REGISTERS if registers is None else registers)}
    return names | {n.replace("-", "_") for n in names}
