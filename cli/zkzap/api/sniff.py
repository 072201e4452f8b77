"""A passive sniffer for both protocols: it reads ports and never writes a byte.

- ZK (:class:`ZkSniffer`): one port sees whatever mixture arrives (control and status frames are
  told apart by the framer), or two receive-only taps of a flight-controller <-> ECU link, one
  per direction (the host's TX line, the ECU's TX line), merged by time into one stream with a
  ``dir`` field; status frames decode version-aware (the protocol version from status ID 6).
- mightyZAP (:class:`ZapSniffer`): one adapter on the half-duplex bus sees both directions;
  every feedback is paired with the request it answers under the bus's timing policy
  (:class:`zkzap.link.zap_timing.Pairing`: the latest request to its ID whose late window,
  ``reply_timeout``, is still open, even when the host has sent others since), with its
  ``latency_ms``; a request that expects an answer and gets none within ``reply_timeout``
  becomes a ``missing`` record, and a feedback from an ID nobody asked (``pairing:
  unexpected-id``, with the ``expected_id`` still open) or with no request at all
  (``unsolicited``) is marked.

Records carry ``time`` (ISO 8601 UTC), ``t`` (seconds since the sniffer started), ``dir``
(``h2d`` host -> device, ``d2h`` device -> host) and the decoded frame with its ``frame`` hex.
:class:`Stats` keeps the live summary: frames per second per direction and per ID, CRC errors,
gaps, the slowest replies. Nothing here imports click or rich.
"""

from __future__ import annotations

import heapq
import queue
import threading
import time
from collections import Counter, deque

from ..codec import zap, zk
from ..codec.framing import SignalLock, ZapFramer, ZkFramer
from ..errors import NoReply, PortError, UsageError
from ..link.clock import wall_now
from ..link.pcapng import INBOUND, OUTBOUND, UNKNOWN
from .capture import iso_utc

#: How long chunks from two ports are held back so they can be merged in time order.
MERGE_WINDOW_S = 0.03
#: Read timeout of each port's reader thread.
READ_SLICE_S = 0.02
#: A mightyZAP request unanswered after this long is a missing reply: the bus's late window
#: (:mod:`zkzap.link.zap_timing`), the same a host waits.
from ..link.zap_timing import LATE_WINDOW as DEFAULT_REPLY_TIMEOUT_S  # noqa: E402
#: A gap in the ECU's status stream: longer than this many status periods without a frame.
GAP_PERIODS = 3
#: How many of the slowest replies the summary keeps.
SLOWEST = 5
#: A line whose bytes are noise for this long (no frame trusted meanwhile) ends the sniff (exit 3).
NOISE_S = 2.0

ROLES = {"both": UNKNOWN, "host": OUTBOUND, "device": INBOUND}


def _dir_name(direction):
    return {INBOUND: "d2h", OUTBOUND: "h2d"}.get(direction)


class Stats:
    """Counters for the live summary and ``--stats``."""

    def __init__(self):
        self.started = time.monotonic()
        self.frames = Counter()            # by dir
        self.by_id = Counter()             # by (dir, id)
        self.recent = deque()              # (t, dir) of the last second
        self.crc_errors = 0
        self.skipped = 0
        self.gaps = 0
        self.longest_gap = 0.0
        self.missing = 0
        self.unexpected = 0
        self.unsolicited = 0
        self.slowest = []                  # heap of (latency, t, id, instruction)
        self.replies = 0
        self.timed = 0                    # replies whose latency is known
        self.latency_sum = 0.0

    def frame(self, t, d, ident):
        self.frames[d] += 1
        self.by_id[(d, ident)] += 1
        self.recent.append((t, d))
        while self.recent and self.recent[0][0] < t - 1.0:
            self.recent.popleft()

    def reply(self, t, ident, instruction, latency):
        """A reply paired with its request; ``latency`` ms, or None where it is not known."""
        self.replies += 1
        if latency is None:
            return
        self.timed += 1
        self.latency_sum += latency
        item = (latency, t, ident, instruction)
        if len(self.slowest) < SLOWEST:
            heapq.heappush(self.slowest, item)
        elif latency > self.slowest[0][0]:
            heapq.heapreplace(self.slowest, item)

    def rates(self, now):
        """Frames per second by direction over the last second before ``now``."""
        c = Counter(d for t, d in self.recent if t >= now - 1.0)
        return dict(c)

    def summary(self, elapsed) -> dict:
        dirs = sorted(self.frames, key=str)
        out = {
            "duration_s": round(elapsed, 3),
            "frames": {str(d): n for d, n in ((d, self.frames[d]) for d in dirs)},
            "frames_per_s": {str(d): round(self.frames[d] / elapsed, 2) if elapsed > 0 else None for d in dirs},
            "by_id": {f"{d}:{i}": n for (d, i), n in sorted(self.by_id.items(), key=lambda x: (str(x[0][0]), x[0][1]))},
            "crc_errors": self.crc_errors,
            "skipped_bytes": self.skipped,
            "gaps": self.gaps,
            "longest_gap_s": round(self.longest_gap, 3),
        }
        if self.replies or self.missing or self.unexpected or self.unsolicited:
            out.update({
                "replies": self.replies,
                "mean_latency_ms": round(self.latency_sum / self.timed, 3) if self.timed else None,
                "missing_replies": self.missing,
                "unexpected_id": self.unexpected,
                "unsolicited": self.unsolicited,
                "slowest": [{"latency_ms": lat, "t": t, "id": i, "instruction": ins}
                            for lat, t, i, ins in sorted(self.slowest, reverse=True)],
            })
        return out


class _Reader(threading.Thread):
    """Reads one port until stopped; chunks go to the shared queue with their time (and to the
    capture). A read returns as soon as bytes arrive (one byte, then whatever is waiting), so a
    request and its reply come in separate chunks with their own times."""

    def __init__(self, index, port, url, out, capture=None):
        super().__init__(daemon=True, name=f"sniff-{index}")
        self.index, self.port, self.url, self.out = index, port, url, out
        self.capture = capture            # (Writer, interface ID, direction) or None
        self.stopping = threading.Event()

    def run(self):
        port = self.port
        while not self.stopping.is_set():
            try:
                data = port.read(1)
                if data:
                    waiting = getattr(port, "in_waiting", 0)
                    if waiting:
                        data += port.read(waiting)
                    ts = wall_now()           # when the chunk's last byte had arrived
                    if self.capture is not None:
                        w, if_id, direction = self.capture
                        w.packet(if_id, ts, bytes(data), direction)
            except Exception as e:  # noqa: BLE001 - SerialException, OSError; an OutputError of the capture
                self.out.put((wall_now(), self.index, e))
                return
            if data:
                self.out.put((ts, self.index, bytes(data)))


class Sniffer:
    """The part both protocols share: ports, reader threads, the merge by time, stop rules."""

    protocol = ""

    def __init__(self, ports, baud, *, capture=None, stop_bits=1):
        """``ports``: [(url, role)], role 'both' (one port sees both directions), 'host' (the
        host's TX line) or 'device' (the device's TX line). ``capture``: a pcapng path;
        ``stop_bits``: the line's (1 or 2)."""
        self.ports_spec = list(ports)
        self.baud = baud
        self.stop_bits = stop_bits
        self.capture = capture
        self.ports = []
        self.readers = []
        self.queue = queue.Queue()
        self.stats = Stats()
        self.t0 = None
        self.wall0 = None
        self._held = []
        self._ready = []
        self._seq = 0
        self._last_ts = {}
        self.framers = []
        self.locks = []                   # one SignalLock per port: frames, or noise?
        self.heard = None                 # monotonic time of the last frame trusted (or the start)

    # -- ports ---------------------------------------------------------------------------------
    def open(self):
        from ..link import capture as cap
        from ..link.port import close_port, open_port

        taps = []
        try:
            for url, role in self.ports_spec:
                # capture=(): no tap by open_port; the reader threads record whole chunks themselves
                p = open_port(url, self.baud, timeout=READ_SLICE_S, capture=(), stop_bits=self.stop_bits)
                self.ports.append(p)
                if self.capture:
                    w = cap.writer_for(self.capture, self.protocol)
                    taps.append((w, w.interface(self.protocol, url, self.baud), ROLES[role]))
                else:
                    taps.append(None)
                self.framers.append(self._framer(role))
                self.locks.append(SignalLock(self.framers[-1], confirm=1))   # records as they happen
        except BaseException:
            for p in self.ports:
                close_port(p)
            raise
        self.t0 = self.heard = time.monotonic()
        self.wall0 = wall_now()
        for i, p in enumerate(self.ports):
            r = _Reader(i, p, self.ports_spec[i][0], self.queue, taps[i])
            self.readers.append(r)
            r.start()
        return self

    def close(self):
        from ..link.port import close_port

        for r in self.readers:
            r.stopping.set()
        for r in self.readers:
            r.join(1.0)
        for p in self.ports:
            close_port(p)
        if self.capture:
            from ..link import capture as cap

            cap.finish()

    def __enter__(self):
        return self.open()

    def __exit__(self, *exc):
        self.close()

    # -- the loop ------------------------------------------------------------------------------
    def poll(self, wait=0.1):
        """Records from the chunks read since the last call, in time order."""
        try:
            item = self.queue.get(timeout=wait)
        except queue.Empty:
            item = None
        items = [] if item is None else [item]
        while True:
            try:
                items.append(self.queue.get_nowait())
            except queue.Empty:
                break
        for ts, index, data in items:
            if isinstance(data, BaseException):
                from ..errors import ZkzapError

                if isinstance(data, ZkzapError):
                    raise data
                url = self.ports_spec[index][0]
                raise PortError(f"port {url} failed: {data}")
            heapq.heappush(self._held, (ts, index, data))
        # with one port the chunks are in order already; with two, chunks and then records are
        # held for the window, so both lines merge into one stream in time order
        window = MERGE_WINDOW_S if len(self.ports) > 1 else 0.0
        horizon = wall_now() - window
        fresh = []
        while self._held and self._held[0][0] <= horizon:
            ts, index, data = heapq.heappop(self._held)
            fresh += self.chunk(ts, index, data)
        fresh += self.tick(wall_now())
        if not window:
            return fresh
        for rec in fresh:
            self._seq += 1
            heapq.heappush(self._ready, (rec["t"], self._seq, rec))
        out = []
        limit = horizon - window - self.wall0
        while self._ready and self._ready[0][0] <= limit:
            out.append(heapq.heappop(self._ready)[2])
        return out

    def drain(self):
        """Records of everything still held (the end)."""
        out = []
        while self._held:
            ts, index, data = heapq.heappop(self._held)
            out += self.chunk(ts, index, data)
        now = wall_now()
        for i, framer in enumerate(self.framers):
            frames = framer.flush()
            for t, frame in self.locks[i].admit(0, frames, [(now, f) for f in frames]):
                out += self.frame(t, i, frame)
            self.locks[i].finish()
        out += self.finish(now)
        self._count_framers()
        for rec in out:
            self._seq += 1
            heapq.heappush(self._ready, (rec["t"], self._seq, rec))
        out = []
        while self._ready:
            out.append(heapq.heappop(self._ready)[2])
        return out

    def chunk(self, ts, index, data):
        """Records of the frames a chunk completes. A chunk's time is when it was read (its last
        byte had arrived); each frame is dated when its own last byte was on the line: the
        chunk time less the line time of the bytes after it (never before the port's previous
        frame, so each port's frames stay in order)."""
        out = []
        frames = self.framers[index].feed(data)
        byte_s = (9.0 + self.stop_bits) / self.baud
        n = len(data)
        after = sum(len(f) for f in frames)
        last = self._last_ts.get(index, 0.0)
        stamped = []
        for frame in frames:
            after -= len(frame)
            t = max(last, ts - min(after, n) * byte_s)
            last = t
            stamped.append((t, frame))
        self._last_ts[index] = last
        # noise gives CRC-valid frames by chance: only a port's trusted stream makes records
        trusted = self.locks[index].admit(n, frames, stamped)
        if trusted:
            self.heard = time.monotonic()
        for t, frame in trusted:
            out += self.frame(t, index, frame)
        self._count_framers()
        return out

    @property
    def frames_trusted(self) -> int:
        """Frames handed on as records (not taken for chance in noise)."""
        return sum(lock.accepted for lock in self.locks)

    def noise(self):
        """The :class:`~zkzap.errors.NoReply` to end with when the line has carried only noise
        (bytes, too few of them in frames) for :data:`NOISE_S` without a frame trusted; else
        None. Facts: ``protocol``, ``port``, ``baud``, ``noise``, ``bytes``, ``chance_frames``."""
        if time.monotonic() - self.heard < NOISE_S:
            return None
        noisy = [i for i, lock in enumerate(self.locks) if lock.noise]
        if not noisy:
            return None
        i = noisy[0]
        lock, url = self.locks[i], self.ports_spec[i][0]
        what = {"zk": "ZK frames", "modbus": "Modbus RTU frames"}.get(self.protocol, "mightyZAP packets")
        chance = lock.rejected + len(lock.held)
        return NoReply(f"{url}: {lock.bytes:,} bytes in {self.elapsed():.1f} s, but not as {what} at "
                       f"{self.baud} baud ({chance} valid by chance among them): line noise, another "
                       f"device, or a wrong baud rate or stop bits", protocol=self.protocol, port=url,
                       baud=self.baud, noise=True, bytes=lock.bytes, chance_frames=chance, sniff=True)

    def silent(self):
        """The :class:`~zkzap.errors.NoReply` for a sniff that ended without one frame."""
        what = {"zk": "ZK frame", "modbus": "Modbus RTU frame"}.get(self.protocol, "mightyZAP packet")
        ports = ", ".join(url for url, _ in self.ports_spec)
        got = sum(lock.bytes for lock in self.locks)
        chance = sum(lock.rejected + len(lock.held) for lock in self.locks)
        tail = (f": {got:,} bytes came, none as a stream of frames ({chance} valid by chance)" if got
                else ": nothing came")
        return NoReply(f"no {what} on {ports} at {self.baud} baud in {self.elapsed():.1f} s{tail}",
                       protocol=self.protocol, port=ports, baud=self.baud, noise=bool(got), bytes=got,
                       chance_frames=chance, sniff=True)

    def _count_framers(self):
        self.stats.crc_errors = sum(f.bad for f in self.framers)
        self.stats.skipped = sum(f.skipped for f in self.framers)

    def _base(self, ts, direction):
        return {"time": iso_utc(ts), "t": round(ts - self.wall0, 6), "dir": _dir_name(direction)}

    def elapsed(self):
        return time.monotonic() - self.t0

    # -- per protocol --------------------------------------------------------------------------
    def _framer(self, role):  # pragma: no cover - abstract
        raise NotImplementedError

    def frame(self, ts, index, frame):  # pragma: no cover - abstract
        raise NotImplementedError

    def tick(self, now):
        return []

    def finish(self, now):
        return []


class ZkSniffer(Sniffer):
    protocol = "zk"

    def __init__(self, ports, baud, *, capture=None, protocol_version=None, stop_bits=1):
        super().__init__(ports, baud, capture=capture, stop_bits=stop_bits)
        self.decoder = zk.ZkDecoder(protocol_version)
        self.rate = 20
        self.last_status = None
        self.roles = [role for _, role in self.ports_spec]

    def _framer(self, role):
        return ZkFramer({"both": "both", "host": "control", "device": "status"}[role])

    def frame(self, ts, index, frame):
        rec = self.decoder.decode(frame)
        direction = OUTBOUND if rec["kind"] == "control" else INBOUND
        out = self._base(ts, direction)
        out.update(rec)
        out["frame"] = frame.hex(" ").upper()
        t = out["t"]
        self.stats.frame(t, out["dir"], rec["id"])
        if rec["kind"] == "status":
            if rec["id"] == 6 and rec.get("status_rate_hz"):
                self.rate = rec["status_rate_hz"]
            if self.last_status is not None:
                gap = t - self.last_status
                if gap > GAP_PERIODS / self.rate:
                    self.stats.gaps += 1
                    self.stats.longest_gap = max(self.stats.longest_gap, gap)
            self.last_status = t
        return [out]


class ZapSniffer(Sniffer):
    protocol = "zap"

    def __init__(self, ports, baud, *, capture=None, reply_timeout=DEFAULT_REPLY_TIMEOUT_S, stop_bits=1):
        from ..link.zap_timing import Pairing

        super().__init__(ports, baud, capture=capture, stop_bits=stop_bits)
        self.decoder = zap.ZapDecoder()
        self.reply_timeout = reply_timeout
        self.pairing = Pairing(window=reply_timeout, margin=0.0)   # ID -> (ts, (instruction, expected))
        self.acks = set()                   # IDs seen acknowledging writes (return mode 2)

    def _framer(self, role):
        return ZapFramer()

    def _expects(self, pkt):
        ident, code = pkt[3], pkt[5]
        if ident == zap.BROADCAST:
            return False
        if code in (0xF1, 0xF2):            # Echo always, Load Data in the usual modes 1 and 2
            return True
        return ident in self.acks

    # what a protocol's frame is (the Modbus sniffer answers these for its frames)
    def _request(self, rec) -> bool:
        return rec["kind"] == "command"

    @staticmethod
    def _ident(pkt) -> int:
        return pkt[3]

    BROADCAST = zap.BROADCAST

    @staticmethod
    def _what(rec) -> str:
        return rec["instruction"]

    #: Requests whose acknowledgement tells that an ID answers writes (return mode 2).
    READS = ("echo", "load")

    def frame(self, ts, index, pkt):
        out = []
        rec = self.decoder.decode(pkt)
        ident = self._ident(pkt)
        if self._request(rec):
            out += self._missing(self.pairing.expired(ts), ts)
            base = self._base(ts, OUTBOUND)
            base.update(rec)
            base["frame"] = pkt.hex(" ").upper()
            self.stats.frame(base["t"], "h2d", rec["id"])
            if ident != self.BROADCAST:
                out += self._missing(self.pairing.command(ident, ts, (self._what(rec), self._expects(pkt))), ts)
            out.append(base)
            return out
        base = self._base(ts, INBOUND)
        base.update(rec)
        base["frame"] = pkt.hex(" ").upper()
        self.stats.frame(base["t"], "d2h", rec["id"])
        got = self.pairing.feedback(ident, ts)
        if got is not None:
            _, (instruction, _), latency = got
            base["pairing"] = "ok"
            base["request"] = instruction
            if latency is None:           # request and reply in one read: not known (never 0)
                base["latency_unknown"] = "request and reply came in one read"
            else:
                latency = round(latency * 1000.0, 3)
            base["latency_ms"] = latency
            self.stats.reply(base["t"], ident, instruction, latency)
            if instruction not in self.READS:
                self.acks.add(ident)
        else:
            others = self.pairing.others(ident)
            if others:
                latest = max(others, key=lambda i: self.pairing.pending[i][0])
                base["pairing"] = "unexpected-id"
                base["request"] = self.pairing.pending[latest][1][0]
                base["expected_id"] = latest
                self.stats.unexpected += 1
            else:
                base["pairing"] = "unsolicited"
                self.stats.unsolicited += 1
        out.append(base)
        return out

    def _missing(self, requests, now):
        """``missing`` records of the requests whose window closed unanswered (those that
        expected an answer)."""
        out = []
        for ident, ts, (instruction, expected) in requests:
            if not expected:
                continue
            self.stats.missing += 1
            rec = self._base(ts, OUTBOUND)
            rec.update({"kind": "missing", "id": ident, "request": instruction,
                        "waited_ms": round((now - ts) * 1000.0, 3)})
            out.append(rec)
        return out

    def tick(self, now):
        if self._held:
            return []
        busy = any(f.pending for f in self.framers)          # a reply is arriving: not missing yet
        return self._missing(self.pairing.expired(now, busy), now)

    def finish(self, now):
        return self._missing(self.pairing.expired(now), now)


class ModbusSniffer(ZapSniffer):
    """A mightyZAP bus speaking Modbus RTU (the 17Lf): frames cut by the RTU framer, named by
    the register map (``regmap``, default the 17Lf's), each reply (an exception reply too) paired
    with the request to its ID; every unicast request expects an answer (Modbus RTU answers
    every one), so one unanswered within the window is a ``missing`` record."""

    protocol = "modbus"
    BROADCAST = 0
    READS = ()

    def __init__(self, ports, baud, *, capture=None, reply_timeout=DEFAULT_REPLY_TIMEOUT_S, stop_bits=1,
                 regmap=None):
        from ..codec import modbus

        super().__init__(ports, baud, capture=capture, reply_timeout=reply_timeout, stop_bits=stop_bits)
        self.decoder = modbus.ModbusDecoder(regmap)

    def _framer(self, role):
        from ..codec.framing import RtuFramer

        return RtuFramer()

    def _request(self, rec) -> bool:
        return rec["kind"] == "request"

    @staticmethod
    def _ident(pkt) -> int:
        return pkt[0]

    @staticmethod
    def _what(rec) -> str:
        return rec["function"]

    def _expects(self, pkt):
        return pkt[0] != self.BROADCAST


def check_ports(protocol: str, ports) -> list:
    """``-p`` values -> [(url, role)]: one port for mightyZAP; one or two for ZK (the host's TX
    line first, then the ECU's). Anything else is a usage error."""
    ports = list(ports)
    if not ports:
        raise UsageError(f"no port: give -p PORT{' (twice for a tapped link: HOST_TX, ECU_TX)' if protocol == 'zk' else ''}")
    if protocol in ("zap", "modbus"):
        if len(ports) != 1:
            raise UsageError(f"port: {len(ports)} ports given; a mightyZAP bus is half-duplex: one adapter "
                             "sees both directions, give one -p")
        return [(ports[0], "both")]
    if len(ports) > 2:
        raise UsageError(f"port: {len(ports)} ports given; give one -p (both directions on one line) or two "
                         "(the host's TX line, then the ECU's)")
    if len(ports) == 1:
        return [(ports[0], "both")]
    if ports[0] == ports[1]:
        raise UsageError(f"port: {ports[0]} given twice; the two -p are the host's TX line and the ECU's")
    return [(ports[0], "host"), (ports[1], "device")]
