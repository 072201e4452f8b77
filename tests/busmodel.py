"""The model-based checker of the mightyZAP bus: random buses, random operations through the
library and the command line, every answer checked against the simulator's ground truth.

A :class:`World` is one random bus (1-8 actuators; a reply latency from 0.1 ms to 1 s each, with
jitter; some behind a link that is not a UART, answering sooner than the wire could carry it;
return mode 0, 1 or 2 each; an echoing adapter; duplicate IDs; an actuator at another baud
rate) on a simulator with a virtual clock (a window that closes in silence costs no real time,
and a seed reproduces a run exactly). :meth:`World.step` runs one operation, drawn at random
(scan, load, store, set-id, move, sync-move, echo, backup, diff, apply, watch, a mode change,
a baud change; through :class:`zkzap.Bus` or the ``zap`` commands), with a one-shot line fault
now and then (a dropped, garbled or extra byte, a reply sent twice, silence), and checks what
it returned against :attr:`zkzap.sim.zap_actuators.ActuatorBus.truth`, the record of what each
actuator heard and answered:

- a value returned (a return value, a command's exit 0 and its output) is the reply an
  actuator with that ID gave to a request of this operation; otherwise the operation raised or
  flagged it (a named error, a non-zero exit, a record's status or doubt);
- nothing was written that the operation did not ask for (every write an actuator heard is
  one of the operation's own packets, to the ID it named);
- zkzap never gave two actuators one ID (a duplicate that was not there before).

A violation raises :class:`Violation` with the seed and the steps so far. Used by
tests/link/test_bus_model.py (a Hypothesis state machine, CI-sized) and
benchmarks/bus_truth.py (at least 100,000 operations).
"""

from __future__ import annotations

import collections
import json
import random

from zkzap.codec import zap
from zkzap.errors import ZkzapError

R = zap.REGISTER_BY_NAME
#: Registers the model reads (their values do not change by themselves).
STATIC = ("model-number", "firmware-version", "long-stroke-limit", "short-stroke-limit", "speed-limit",
          "current-limit", "alarm-led", "acceleration", "deceleration", "goal-speed", "led")
#: Volatile registers the model writes.
WRITABLE = {"led": (0, 1, 2, 4), "goal-speed": (100, 512, 1023)}
IDS = range(0, 8)
BAUDS = (57600, 115200)


#: The one-shot line faults drawn: every kind (the suite's and the benchmark's).
FAULTS = ("noise", "drop", "corrupt", "silent", "twice", "truncate")
SUITE_FAULTS = FAULTS


class Violation(AssertionError):
    """The bus gave a wrong answer (or wrote what it was not asked to, or made a duplicate ID)."""


def _latency(rng: random.Random) -> float:
    """A reply latency: mostly a real actuator's few ms, often a USB adapter's tens, now and then
    one past the window, up to 1 s (log-uniform within each band)."""
    band = rng.random()
    lo, hi = (0.0001, 0.005) if band < 0.55 else (0.005, 0.12) if band < 0.85 else (0.12, 1.0)
    return lo * (hi / lo) ** rng.random()


class World:
    """One random bus and the programs driving it (see the module's description)."""

    def __init__(self, seed: int, *, cli: bool = True, faults=FAULTS) -> None:
        from zkzap import Bus
        from zkzap.sim.base import VirtualClock, keep_wire_time
        from zkzap.sim.launch import Simulator
        from zkzap.sim.zap_actuators import Actuator, ActuatorBus

        self.seed = seed
        self.rng = rng = random.Random(seed)
        self.cli = cli
        self.faults = faults
        n = rng.randint(1, 8)
        ids = rng.sample(list(IDS), n)
        if n > 1 and rng.random() < 0.15:
            ids[-1] = ids[0]                         # two actuators with one ID
        acts = []
        for slot, ident in enumerate(ids):
            baud = BAUDS[1] if rng.random() < 0.1 else BAUDS[0]
            a = Actuator(slot, ident, baud)
            a.own_turnaround = _latency(rng)
            a.jitter = a.own_turnaround * rng.choice((0.0, 0.05, 0.3))
            a.fast = a.own_turnaround < 0.002 and rng.random() < 0.4
            a.set("feedback-return-mode", rng.choice((0, 1, 1, 2)))
            acts.append(a)
        self.device = ActuatorBus(acts, echo=rng.random() < 0.2)
        self.truth = self.device.record_truth(seed)
        self.clock = VirtualClock()
        self.sim = Simulator("zap", keep_wire_time(self.device, self.clock), self.clock)
        self.bus = Bus(self.sim.url, retries=rng.choice((0, 2, 2)),
                       timeout=rng.choice((None, None, 0.05, 0.3)))
        self.steps: list[str] = []
        self.recent: collections.deque = collections.deque(maxlen=6)
        self.checked = 0
        self.wrong = 0
        self.doubts = 0
        self.errors = 0
        self.ops = 0

    def close(self) -> None:
        self.bus.close()
        self.sim.close()

    # -- truth ---------------------------------------------------------------------------------

    def describe(self) -> str:
        parts = [f"seed {self.seed}:"]
        for a in self.device.actuators:
            parts.append(f"[slot {a.slot} id {a.ident} {a.baud} mode {a.return_mode} "
                         f"{a.own_turnaround * 1000:.2f}+{a.jitter * 1000:.2f} ms{' fast' if a.fast else ''}]")
        parts.append(f"echo={self.device.echo} timeout={self.bus.link.timeout} retries={self.bus.link.retries}")
        return " ".join(parts)

    def fail(self, text: str) -> None:
        self.wrong += 1
        raise Violation(f"{text}\n{self.describe()}\nsteps: " + "; ".join(self.steps[-12:]))

    def since(self, t0: float) -> list:
        return [h for h in self.truth if h.t >= t0]

    def answered(self, t0: float, ident: int, packet: bytes) -> list:
        """The clean replies actuators with ``ident`` gave to ``packet`` since ``t0``."""
        return [h.reply for h in self.since(t0) if h.ident == ident and h.packet == packet and h.reply]

    def ids_now(self) -> list:
        return sorted(a.ident for a in self.device.actuators)

    def dupes(self) -> set:
        """(ID, baud) that two actuators share (at one line speed: an actuator at another one is
        not on the line the host talks on)."""
        ids = sorted((a.ident, a.baud) for a in self.device.actuators)
        return {i for i in ids if ids.count(i) > 1}

    def check_writes(self, t0: float, allowed) -> None:
        """Every write an actuator heard is one of the packets an operation that began before
        it asked for (``allowed``, of this one or of one of the last few: a write that is not
        answered is heard after the call that sent it returned)."""
        self.recent.append((t0, set(allowed)))
        for h in self.truth[self.checked:]:
            if h.packet[5] in (zap.ECHO, zap.LOAD_DATA):
                continue
            if not any(t <= h.t + 1e-9 and h.packet in ok for t, ok in self.recent):
                self.fail(f"unasked write heard by slot {h.slot} (ID {h.ident}): {h.packet.hex(' ')}")
        self.checked = len(self.truth)

    # -- one step ------------------------------------------------------------------------------

    def step(self) -> None:
        rng = self.rng
        if rng.random() < 0.15:
            self._fault()
        ops = [self.op_load, self.op_load, self.op_echo, self.op_store, self.op_move, self.op_sync,
               self.op_mode, self.op_backup, self.op_scan, self.op_set_id, self.op_watch, self.op_baud,
               self.op_diff_apply]
        if self.cli:
            ops += [self.cli_load, self.cli_echo, self.cli_store]
        op = rng.choice(ops)
        dupes = self.dupes()
        self.ops += 1
        op()
        made = self.dupes() - dupes
        if made:
            self.fail(f"{self.steps[-1]}: made two actuators with ID {sorted(made)}")

    def _fault(self) -> None:
        a = self.rng.choice(self.device.actuators)
        kind = self.rng.choice(self.faults)
        a.faults[kind] = _fault(kind)
        self.steps.append(f"fault slot {a.slot} {kind}")

    def _ident(self) -> int:
        if self.rng.random() < 0.85:
            return self.rng.choice(self.device.actuators).ident
        return self.rng.choice(list(IDS))

    def _call(self, what: str, fn):
        """``fn()``; a ZkzapError is a legitimate answer (counted), returned as None."""
        self.steps.append(what)
        try:
            return fn()
        except ZkzapError:
            self.errors += 1
            return None

    # -- operations through the library -----------------------------------------------------

    def op_load(self) -> None:
        ident, name = self._ident(), self.rng.choice(STATIC)
        reg = R[name]
        t0 = self.clock.now()
        got = self._call(f"load {name} from {ident}", lambda: self.bus.load(ident, reg))
        if got is None:
            return
        pkt = zap.load(ident, reg.address, reg.size)
        values = {int.from_bytes(r[6:-1], "little") for r in self.answered(t0, ident, pkt)}
        if got not in values:
            self.fail(f"load {name} from ID {ident} returned {got}; the actuator answered {sorted(values)}")
        self.check_writes(t0, ())

    def op_echo(self) -> None:
        ident = self._ident()
        t0 = self.clock.now()
        r = self._call(f"echo {ident}", lambda: self.bus.echo(ident, check=False))
        if r is None:
            return
        if not self.answered(t0, ident, zap.echo(ident)):
            self.fail(f"echo {ident} answered, but no actuator with ID {ident} answered it")
        if r.doubt is None:
            # the attempt it is credited to was heard at least the actuator's turnaround before it
            heard = [h for h in self.since(t0) if h.ident == ident and h.packet == zap.echo(ident) and h.reply
                     and h.at is not None]
            if not any(r.rtt + 1e-6 >= h.at - h.t for h in heard):
                self.fail(f"echo {ident}: round trip {r.rtt * 1000:.3f} ms, shorter than the actuator took "
                          f"({', '.join(f'{(h.at - h.t) * 1000:.3f}' for h in heard)} ms)")

    def op_store(self) -> None:
        ident = self._ident()
        name = self.rng.choice(list(WRITABLE))
        value = self.rng.choice(WRITABLE[name])
        t0 = self.clock.now()
        pkt = zap.store(ident, name, value)
        r = self._call(f"store {name}={value} to {ident}", lambda: self.bus.store(ident, name, value))
        self.check_writes(t0, (pkt,))
        if r is not None and not self.answered(t0, ident, pkt):
            self.fail(f"store to {ident} acknowledged, but no actuator acknowledged it")

    def op_move(self) -> None:
        ident = self._ident()
        pos = self.rng.randrange(0, 3687, 97)
        t0 = self.clock.now()
        self._call(f"move {ident} to {pos}", lambda: self.bus.move(ident, pos, wait=False))
        self.check_writes(t0, (zap.store(ident, "goal-position", pos),))

    def op_sync(self) -> None:
        targets = {a.ident: self.rng.randrange(0, 3687, 101) for a in self.device.actuators}
        t0 = self.clock.now()
        self._call(f"sync-move {targets}", lambda: self.bus.sync_move(targets))
        self.check_writes(t0, tuple(zap.symmetric_store("goal-position", targets)))

    def op_mode(self) -> None:
        ident = self._ident()
        mode = self.rng.choice((0, 1, 2))
        t0 = self.clock.now()
        pkt = zap.store(ident, "feedback-return-mode", mode, force=True)
        self._call(f"mode {mode} to {ident}", lambda: self.bus.store(ident, "feedback-return-mode", mode, force=True))
        self.check_writes(t0, (pkt,))

    def op_backup(self) -> None:
        from zkzap.api import fleet

        ids = sorted({self._ident() for _ in range(2)})
        t0 = self.clock.now()
        doc = self._call(f"backup {ids}", lambda: fleet.read_bus(self.bus.link, ids))
        self.check_writes(t0, ())
        if doc is None:
            return
        for ident, entry in fleet.check_document(doc, "backup").items():
            # (an actuator at another baud rate is not on the line the backup read)
            owners = [a for a in self.device.actuators if a.ident == ident and a.baud == entry.baud]
            if len(owners) != 1:
                self.fail(f"backup read ID {ident} at {entry.baud} baud, which {len(owners)} actuators have there")
            a = owners[0]
            for reg, value in entry.values.items():
                if not reg.stored or reg.name in ("id", "baud-rate", "feedback-return-mode"):
                    continue
                if value != a.get(reg.name):
                    self.fail(f"backup: ID {ident} {reg.name} = {value}, the actuator holds {a.get(reg.name)}")

    def op_scan(self) -> None:
        ids = range(0, 8)
        t0 = self.clock.now()
        recs = self._call("scan 0-7", lambda: list(self.bus.scan(ids, retries=self.bus.link.retries)))
        self.check_writes(t0, ())
        if recs is None:
            return
        baud = self.bus.baud
        for rec in recs:
            ident = rec["id"]
            owners = [a for a in self.device.actuators if a.ident == ident and a.baud == baud]
            if not owners:
                self.fail(f"scan found ID {ident} at {baud}, where no actuator has it")
            if rec["status"] == "ok" and len(owners) == 1:
                a = owners[0]
                if rec["model"] is not None and rec["model"] != a.get("model-number"):
                    self.fail(f"scan: ID {ident} model {rec['model']}")
                if rec["return_mode"] is not None and rec["return_mode"] != a.return_mode:
                    self.fail(f"scan: ID {ident} return mode {rec['return_mode']}, it is in {a.return_mode}")

    def op_set_id(self) -> None:
        ident = self._ident()
        new = self.rng.choice(list(IDS))
        t0 = self.clock.now()
        pkt = zap.store(ident, "id", new, force=True)
        got = self._call(f"set-id {ident} -> {new}", lambda: self.bus.set_id(ident, new))
        self.check_writes(t0, (pkt,))
        if got is not None and new != ident:
            if not any(a.ident == new for a in self.device.actuators):
                self.fail(f"set-id {ident} -> {new} said done; no actuator has ID {new}")

    def op_watch(self) -> None:
        ident = self._ident()
        t0 = self.clock.now()
        pkt = zap.load(ident, R["present-position"].address, 2)
        for _ in range(3):
            got = self._call(f"watch {ident}", lambda: self.bus.load(ident, "present-position"))
            if got is None:
                break
            values = {int.from_bytes(r[6:-1], "little") for r in self.answered(t0, ident, pkt)}
            if got not in values:
                self.fail(f"watch present-position of {ident}: {got}; the actuator answered {sorted(values)}")
        self.check_writes(t0, ())

    def op_baud(self) -> None:
        ident = self._ident()
        baud = self.rng.choice(BAUDS)
        was = self.bus.baud
        t0 = self.clock.now()
        code = zap.BAUD_TO_CODE[baud]
        allowed = (zap.store(ident, "baud-rate", code, force=True), zap.restart(ident),
                   zap.store(ident, "baud-rate", zap.BAUD_TO_CODE[was], force=True))
        self._call(f"baud {ident} -> {baud}", lambda: self.bus.set_baud(ident, baud))
        self.check_writes(t0, allowed)
        for a in self.device.actuators:
            stored = zap.BAUD_CODES.get(a.get("baud-rate"))
            if a.ident == ident and stored != a.baud and any(h.slot == a.slot for h in self.since(t0)):
                self.fail(f"baud: ID {ident} stores {stored} baud but answers at {a.baud}")
        if self.bus.baud != was:
            self.bus.baud = was

    def op_diff_apply(self) -> None:
        from zkzap.api import fleet

        ident = self._ident()
        t0 = self.clock.now()
        doc = self._call(f"diff {ident}", lambda: fleet.read_bus(self.bus.link, [ident]))
        self.check_writes(t0, ())
        if doc is None:
            return
        entries = fleet.check_document(doc, "model")
        live = self._call(f"diff {ident} again", lambda: fleet.read_entries(self.bus.link, sorted(entries),
                                                                            required=False))
        if live is None:
            return
        rows = [r for r in fleet.diff(entries, live) if r["register"] != "(actuator)"]
        if rows:
            self.fail(f"diff of ID {ident} against its own backup just made: {rows[:3]}")

    # -- operations through the command line -----------------------------------------------

    def _cli(self, args):
        from click.testing import CliRunner

        from zkzap.commands import root, run
        from zkzap.link.shared import sharing

        self.steps.append("cli " + " ".join(args))
        with sharing("zap", self.bus.link), CliRunner().isolation() as streams:
            code = run(root, "zkzap", ["zap", *args, "-p", self.sim.url])
            out = streams[0].getvalue().decode()
        if code:
            self.errors += 1
        return _Result(code, out)

    def cli_load(self) -> None:
        ident, name = self._ident(), self.rng.choice(STATIC)
        reg = R[name]
        t0 = self.clock.now()
        r = self._cli(["load", name, "--id", str(ident), "-f", "jsonl"])
        self.check_writes(t0, ())
        if r.code:
            return
        rec = json.loads(r.out.strip().splitlines()[-1])
        pkt = zap.load(ident, reg.address, reg.size)
        values = {int.from_bytes(x[6:-1], "little") for x in self.answered(t0, ident, pkt)}
        if rec["value"] not in values:
            self.fail(f"zap load {name} --id {ident} printed {rec['value']}; the actuator answered {sorted(values)}")

    def cli_echo(self) -> None:
        ident = self._ident()
        t0 = self.clock.now()
        r = self._cli(["echo", "--id", str(ident), "--count", "2"])
        if not r.code and not self.answered(t0, ident, zap.echo(ident)):
            self.fail(f"zap echo --id {ident} exit 0; no actuator with ID {ident} answered")
        self.check_writes(t0, ())

    def cli_store(self) -> None:
        ident = self._ident()
        value = self.rng.choice(WRITABLE["led"])
        t0 = self.clock.now()
        self._cli(["store", "led", str(value), "--id", str(ident)])
        self.check_writes(t0, (zap.store(ident, "led", value),))


class _Result:
    __slots__ = ("code", "out")

    def __init__(self, code, out):
        self.code, self.out = code, out


def _fault(kind):
    from zkzap.sim.zap_actuators import Fault

    return Fault(kind, None, 1)


def run(seed: int, steps: int, *, cli: bool = True) -> World:
    """One world of ``steps`` random operations from ``seed`` (raises :class:`Violation`)."""
    world = World(seed, cli=cli)
    try:
        for _ in range(steps):
            world.step()
    finally:
        world.close()
    return world
