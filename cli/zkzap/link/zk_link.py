"""The ZK link: status frames in as records, control frames out at a steady rate, and an abort
on the way out.

- :class:`ZkLink`        a port to an ECU: reads whatever arrived (kept byte for byte in a raw
                         log when asked), writes control frames; port failures are
                         :class:`~zkzap.errors.PortError`.
- :class:`LiveSource`, :class:`ReplaySource`
                         status frames with their time since the start, from a port or from a
                         raw log (paced in real time or as fast as possible).
- :class:`Telemetry`     decodes frames into records: one per frame, or snapshot rows with every
                         field's latest value; time stamps, the stale-data rule, health figures,
                         ECU errors and a summary.
- :class:`Session`       the loop: read, decode, hand records over, send the current control frame
                         every ``1/rate`` s, stop on count/duration/end, Ctrl-C (SIGINT), SIGTERM,
                         a port failure, a silent ECU or a new ECU error, and send the abort
                         command on the way out when the session was controlling the engine.
- :class:`Schedule`      a throttle schedule (``time_s,throttle_pct[,state]`` rows) as control
                         frames over time.

Everything about frames comes from :mod:`zkzap.codec.zk`. Nothing here imports click or rich;
pyserial is imported by :func:`zkzap.link.port.open_port`.
"""

from __future__ import annotations

import signal
import threading
import time
from collections import deque

from ..codec import zk
from ..codec.fields import FieldValueError
from ..codec.framing import ZkFramer
from ..errors import DeviceError, NoReply, OutputError, PortError, UsageError, ZkzapError
from ..errors import TERMINATED
from . import stop

#: Control frames per second while a session controls the engine (``--rate``).
DEFAULT_RATE = 20.0
#: Longest silence tolerated from the ECU, at the start and while running (``--timeout``).
DEFAULT_SILENCE_S = 2.0
#: A status ID is stale when it has not been seen for more than this many of its periods.
STALE_PERIODS = 3
#: Frames held back while waiting for the first status ID 6 (the protocol version); more than a
#: full cycle of IDs 1..10.
HOLD_FRAMES = 12
#: Whole status cycles seen before ``--ids`` the ECU never sends are reported.
ID_CHECK_LAPS = 3
#: Abort commands (``--abort``): the control state sent with throttle 0 on an abnormal end.
ABORTS = zk.ABORTS
DEFAULT_ABORT = zk.DEFAULT_ABORT
#: Longest a read blocks, so control frames go out on time and signals are seen promptly.
READ_SLICE_S = 0.01
READ_SIZE = 4096


def is_simulator(url: str) -> bool:
    """True for the in-process simulator (``sim://``): no consent needed there."""
    return url.startswith("sim://")


def controls_engine(frame) -> bool:
    """True when sending ``frame`` controls the engine (see :attr:`zk.ControlFrame.controls_engine`)."""
    return zk.ControlFrame(frame).controls_engine


def abort_frames(kind: str, version=None, pump=False) -> list:
    """The frames of the abort command ``kind`` (``standby``, ``stop`` or ``none``).

    ``standby``/``stop``: control ID 1 with that state and throttle 0; for an ECU of protocol
    version 4 or later (or of unknown version) also ID 6 with state none and RPM factor 0 (leaves
    RPM mode and hands the state back to ID 1, whose SW an ID 6 state would override), then ID 1
    again. With ``pump`` (a pump-on was sent) also the pump-off action.
    """
    if kind not in ABORTS:
        raise UsageError(f"abort: {kind!r}; allowed {', '.join(ABORTS)}")
    if kind == "none":
        return []
    id1 = zk.encode_control("control", sw=kind, throttle_pct=0)[0]
    frames = [id1]
    if version is None or version >= 4:
        frames += [zk.encode_control("mode", sw="none", rpm_factor=0)[0], id1]
    if pump:
        frames.append(zk.encode_control("action", param="pump-off")[0])
    return frames


def describe_abort(kind: str) -> str:
    return "nothing (--abort none)" if kind == "none" else f"{kind}, throttle 0"


#: What a session that controls the engine sends when it ends normally (``--end``): ``hold``
#: sends nothing more and leaves the engine at the last command.
ENDS = ("standby", "stop", "hold")
DEFAULT_END = "standby"


def describe_error(code, name=None, t=None) -> str:
    """The one wording of an ECU error code, in every command: ``ECU error 3 (egt-high: ...) at
    t=4.20 s``."""
    name = name or zk.ERRORS.get(code, f"undocumented-{code}")
    text = zk.ERROR_TEXT.get(code, "undocumented")
    return f"ECU error {code} ({name}: {text})" + (f" at t={t:.2f} s" if t is not None else "")


def iso_utc(ts: float) -> str:
    """``2024-05-01T12:00:00.123Z`` for a POSIX time."""
    sec, ms = divmod(int(round(ts * 1000)), 1000)
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(sec)) + f".{ms:03d}Z"


# --- the port ----------------------------------------------------------------------------------

class ZkLink:
    """A port to a ZK ECU. :meth:`read` returns the bytes that arrived within a short slice
    (``b""`` if none) and appends them to the raw log; :meth:`write` sends a frame."""

    def __init__(self, ser, url, raw_log=None, baud=None, slice_s=READ_SLICE_S, stop_bits=1):
        self.ser = ser
        self.url = url
        self.raw_log = raw_log
        self.baud = baud if baud is not None else getattr(ser, "baudrate", None)
        self.slice_s = slice_s
        self.stop_bits = stop_bits
        self.bytes_in = 0
        self.frames_out = 0

    @classmethod
    def open(cls, url, baud, raw_log=None, slice_s=READ_SLICE_S, stop_bits=1):
        from .port import open_port
        from .shared import shared

        lent = shared("zk")
        if lent is not None:        # a batch: the one open port, left open by close()
            return lent.borrow(raw_log, slice_s)
        ser = open_port(url, baud, timeout=slice_s, write_timeout=1.0, stop_bits=stop_bits)
        return cls(ser, url, raw_log, baud, slice_s, stop_bits)

    def reopen(self) -> None:
        """Close the failed port and open the same device again (PortError while it is absent)."""
        from .port import close_port, open_port

        close_port(self.ser)
        self.ser = open_port(self.url, self.baud, timeout=self.slice_s, write_timeout=1.0,
                             stop_bits=self.stop_bits)

    def borrow(self, raw_log=None, slice_s=READ_SLICE_S):
        """A link over this one's port for one command; its close() leaves the port open."""
        self.ser.timeout = slice_s
        link = ZkLink(self.ser, self.url, raw_log)
        link.close = lambda: None
        return link

    @property
    def device(self):
        """The simulated device behind a ``sim://`` port (None otherwise)."""
        return getattr(self.ser, "device", None)

    def read(self) -> bytes:
        try:
            data = self.ser.read(READ_SIZE)
        except ZkzapError:       # a capture that cannot be written (exit 7)
            raise
        except Exception as e:   # SerialException, OSError, and whatever a URL handler raises
            raise port_failed(self.url, e) from None
        if data:
            self.bytes_in += len(data)
            if self.raw_log is not None:
                self.raw_log.write(data)
                self.raw_log.flush()
        return data

    def write(self, frame: bytes) -> None:
        stop.check()                 # a stop requested (a batch's Ctrl-C) ends the command here
        try:
            self.ser.write(frame)
            self.ser.flush()
        except ZkzapError:
            raise
        except Exception as e:
            raise port_failed(self.url, e) from None
        self.frames_out += 1

    def close(self):
        from .port import close_port

        close_port(self.ser)


def port_failed(url, e):
    from .port import port_failed as failed

    return failed(url, e)


# --- frame sources -----------------------------------------------------------------------------

#: Pause between two attempts to reopen a vanished port (seconds).
REOPEN_INTERVAL = 0.25


class LiveSource:
    """Status frames from a :class:`ZkLink`, stamped with seconds since the source started.

    With ``reconnect`` (seconds), a port that fails or vanishes is reopened (the same device
    path or URL) every :data:`REOPEN_INTERVAL` for up to that long: meanwhile :meth:`poll`
    returns no frames and :attr:`down` is the time it failed; once it is back, :attr:`gap` is
    ``(t_down, t_up, reason)`` until :meth:`take_gap`. After ``reconnect`` seconds the port
    failure is raised as it would have been without it.
    """

    live = True

    def __init__(self, link: ZkLink, reconnect=None):
        self.link = link
        self.reconnect = reconnect
        self.framer = ZkFramer("status")
        # An in-process simulator (sim://...?speed=N) runs in model time: so does the session
        # (durations, schedules, control rate, record times), or a schedule would run N times
        # slower than the engine it drives. ``speed`` converts back to real time (silences).
        clock = getattr(link.ser, "clock", None)
        self._clock = clock.now if clock is not None and callable(getattr(clock, "now", None)) else time.monotonic
        self.speed = float(getattr(clock, "speed", 1.0)) if clock is not None else 1.0
        self.t0 = self._clock()
        self.wall0 = time.time()
        self.down = None                  # model time the port failed, while it is away
        self.gap = None
        self.reconnects = 0
        self._error = None
        self._next_try = 0.0

    def now(self) -> float:
        return self._clock() - self.t0

    def poll(self):
        """Frames read within one slice, as ``[(t, frame), ...]``."""
        if self.down is not None:
            return self._retry()
        try:
            data = self.link.read()
        except PortError as e:
            if not self.reconnect:
                raise
            self._fail(e)
            return []
        if not data:
            return []
        t = self.now()
        return [(t, f) for f in self.framer.feed(data)]

    def _fail(self, e):
        self.down = self.now()
        self._error = e
        self._next_try = 0.0
        self.framer.flush()                # a frame cut by the drop-out is not glued to new bytes

    def _retry(self):
        now = self.now()
        if now - self.down > self.reconnect:
            raise PortError(f"{self._error}; not back within --reconnect {self.reconnect:g} s")
        if now < self._next_try:
            time.sleep(min(0.05, self._next_try - now))
            return []
        self._next_try = now + REOPEN_INTERVAL
        try:
            self.link.reopen()
        except (PortError, UsageError):
            return []
        self.gap = (self.down, self.now(), str(self._error))
        self.down = None
        self.reconnects += 1
        return []

    def take_gap(self):
        gap, self.gap = self.gap, None
        return gap

    def write(self, frame):
        if self.down is not None:
            return                         # nothing to write to while the port is away
        try:
            self.link.write(frame)
        except PortError as e:
            if not self.reconnect:
                raise
            self._fail(e)

    def close(self):
        self.framer.flush()
        self.link.close()


class ReplaySource:
    """Status frames from a raw log (the exact bytes a monitor received).

    A raw log holds bytes, not times: frame times are rebuilt from the status rate the frames
    themselves report (status ID 6; 20 Hz until one is seen), so frame *n* is at the sum of the
    periods before it. ``fast`` returns frames as fast as they can be decoded; otherwise they
    are paced in real time.
    """

    live = False

    def __init__(self, path, fast=False):
        try:
            self.file = open(path, "rb")
        except OSError as e:
            raise UsageError(f"replay: cannot read {path}: {e.strerror}") from None
        self.path = path
        self.fast = fast
        self.framer = ZkFramer("status")
        self.queue = deque()
        self.period = 1.0 / 20
        self.next_t = 0.0
        self.last_t = 0.0
        self.eof = False
        self.t0 = time.monotonic()
        self.wall0 = time.time()

    def _fill(self):
        while not self.queue and not self.eof:
            try:
                block = self.file.read(READ_SIZE)
            except OSError as e:
                raise UsageError(f"replay: cannot read {self.path}: {e.strerror or e}") from None
            if block:
                frames = self.framer.feed(block)
            else:
                self.eof = True
                frames = self.framer.flush()      # frames held for look-ahead come out here
            for f in frames:
                self.queue.append((self.next_t, f))
                if f[0] == zk.VERSION_HEAD:
                    rate = zk.decode_status(f).get("status_rate_hz")
                    if rate:
                        self.period = 1.0 / rate
                self.next_t += self.period

    def now(self) -> float:
        return self.last_t if self.fast else time.monotonic() - self.t0

    def poll(self):
        """Due frames as ``[(t, frame), ...]``; None at the end of the log."""
        self._fill()
        if not self.queue:
            return None
        if self.fast:
            out = list(self.queue)
            self.queue.clear()
        else:
            elapsed = time.monotonic() - self.t0
            first = self.queue[0][0]
            if first > elapsed:
                time.sleep(min(first - elapsed, 0.05))
                elapsed = time.monotonic() - self.t0
            out = []
            while self.queue and self.queue[0][0] <= elapsed:
                out.append(self.queue.popleft())
        if out:
            self.last_t = out[-1][0]
        return out

    def write(self, frame):   # pragma: no cover - sessions never control a replay
        raise UsageError("replay: nothing can be sent to a replay")

    def close(self):
        self.file.close()


# --- decoding, snapshot, staleness -------------------------------------------------------------

def parse_ids(text):
    """``"1,2,6"`` or ``"1-3,9"`` -> frozenset of status IDs (1..14)."""
    ids = set()
    import re

    # "1 2" is two IDs (never 12); spaces around a range's dash are allowed ("1 - 3")
    for part in re.split(r"[,\s]+", re.sub(r"\s*-\s*", "-", str(text).strip())):
        if not part:
            continue
        lo, sep, hi = part.partition("-")
        try:
            a = int(lo)
            b = int(hi) if sep else a
        except ValueError:
            raise UsageError(f"ids: {part!r} is not an ID or a range such as 1-3") from None
        for v in (a, b):
            if not 1 <= v <= 14:
                raise UsageError(f"ids: {v} is out of range; allowed status IDs 1..14")
        if b < a:
            raise UsageError(f"ids: {part!r} is an empty range")
        ids.update(range(a, b + 1))
    if not ids:
        raise UsageError("ids: no ID given; allowed status IDs 1..14, e.g. 1,2,6 or 1-3")
    return frozenset(ids)


def status_keys(ids=None):
    """Status keys in table order, restricted to the keys of ``ids`` (None: all)."""
    if ids is None:
        return list(zk.STATUS_KEYS)
    keep = set()
    for s in zk.STATUS:
        if s.id in ids:
            keep.update(s.layout.keys())
    return [k for k in zk.STATUS_KEYS if k in keep]


def record_columns(snapshot: bool, ids=None):
    """The fixed column set of monitor records (CSV header)."""
    keys = status_keys(ids)
    if snapshot:
        return ["time", "t", "id"] + keys + ["stale", "stale_ids"]
    return ["time", "t", "kind", "id"] + keys + ["payload", "frame", "stale", "stale_ids"]


class Telemetry:
    """Status frames -> records, with the state a live view and a summary need.

    - Until the first status ID 6 reveals the protocol version, frames are held back (at most
      :data:`HOLD_FRAMES`) so that every voltage decodes in the ECU's own unit; with a given
      ``protocol_version`` nothing is held. Without an ID 6 the default version is used and
      :attr:`version_note` says so.
    - ``snapshot=True``: one row per frame with every field's latest value; otherwise one record
      per frame, as ``zk decode`` gives it. Both carry ``time`` (ISO 8601 UTC), ``t`` (seconds
      since the start), and ``stale``/``stale_ids``.
    - Stale rule: an ID is stale when it has not been seen for more than ``stale_periods`` of its
      period; the period of one ID is (IDs in the ECU's cycle) / (status rate from ID 6; 20 Hz
      until seen), as the ECU sends one frame per period, the IDs in turn.
    - ECU errors: the error code of the first ID 1 frame is where the session starts; a non-zero
      code different from it (or one that comes back after a 0) is a *new error*
      (:attr:`new_error`).
    """

    def __init__(self, protocol_version=None, ids=None, snapshot=False, stale_periods=STALE_PERIODS,
                 wall0=None, wall_clock=True, speed=1.0):
        self.decoder = zk.ZkDecoder(protocol_version)
        #: False for a replay: a raw log holds no times, so records carry ``time: null``
        self.wall_clock = wall_clock
        self.holding = protocol_version is None
        self.held = []
        self.ids = ids
        self.snapshot_rows = snapshot
        self.stale_periods = stale_periods
        self.wall0 = time.time() if wall0 is None else wall0
        self.speed = speed            # model seconds per real second: ``time`` stays wall-clock time
        self.keys = status_keys(ids)
        self.latest = dict.fromkeys(zk.STATUS_KEYS)
        self.last_seen = {}
        self.rate = 20
        self.frames = 0
        self.records = 0
        self.version_note = None
        # ECU errors
        self._baseline = None
        self.initial_error = None     # (code, name) of an error the ECU reported from the start
        self.new_error = None
        self.errors = {}
        # summary
        self.first_t = None
        self.last_t = None
        self.max_rpm = None
        self.max_egt = None
        self.fuel_first = None
        self.fuel_last = None
        self.states = []
        self._rate_window = deque()
        #: ``on_frame(t, record)`` sees every decoded frame (before --ids); a dict it returns is
        #: added to the frame's row (limit entries)
        self.on_frame = None

    # frames in, records out
    def feed(self, t, frame) -> list:
        if self.holding:
            self.held.append((t, frame))
            if frame[0] == zk.VERSION_HEAD or len(self.held) >= HOLD_FRAMES:
                return self._release()
            return []
        return self._emit(t, frame)

    def flush(self) -> list:
        """Records of frames still held (end of the stream)."""
        return self._release() if self.held else []

    def _release(self):
        self.holding = False
        six = next((f for _, f in self.held if f[0] == zk.VERSION_HEAD), None)
        if six is not None:
            self.decoder.decode(six)
        else:
            self.version_note = (f"no status ID 6 frame among the first {len(self.held)}: voltages assume "
                                 f"protocol version {zk.DEFAULT_PROTOCOL_VERSION}; set --protocol-version "
                                 f"if the ECU is older")
        out = []
        for t, f in self.held:
            out += self._emit(t, f)
        self.held = []
        return out

    def _emit(self, t, frame):
        rec = self.decoder.decode(frame)
        sid = rec["id"]
        extra = self.on_frame(t, rec) if self.on_frame is not None else None
        self.frames += 1
        self.last_seen[sid] = t
        if self.first_t is None:
            self.first_t = t
        self.last_t = t
        win = self._rate_window
        win.append(t)
        while win and win[0] < t - 1.0:
            win.popleft()
        latest = self.latest
        for k, v in rec.items():
            if k in latest:
                latest[k] = v
        latest[zk.OUT_OF_RANGE] = rec.get(zk.OUT_OF_RANGE)   # this frame's, never a stale one
        rpm = rec.get("rpm")
        if rpm is not None and (self.max_rpm is None or rpm > self.max_rpm):
            self.max_rpm = rpm
        if sid == 1:
            self._engine(t, rec)
        elif sid == 6 and rec.get("status_rate_hz"):
            self.rate = rec["status_rate_hz"]
        elif sid == 7 and rec.get("fuel_used_l") is not None:
            if self.fuel_first is None:
                self.fuel_first = rec["fuel_used_l"]
            self.fuel_last = rec["fuel_used_l"]
        if self.ids is not None and sid not in self.ids:
            return []
        stale = self.stale_ids(t)
        self.records += 1
        when = iso_utc(self.wall0 + t / self.speed) if self.wall_clock else None
        if self.snapshot_rows:
            row = {"time": when, "t": round(t, 3), "id": sid}
            for k in self.keys:
                row[k] = latest[k]
        else:
            row = {"time": when, "t": round(t, 3)}
            row.update(rec)
            row["frame"] = frame.hex(" ").upper()
        row["stale"] = bool(stale)
        row["stale_ids"] = stale
        if extra:
            row.update(extra)
        return [row]

    def _engine(self, t, rec):
        egt = rec.get("egt_c")
        if egt is not None and (self.max_egt is None or egt > self.max_egt):
            self.max_egt = egt
        name = rec.get("engine_state_name")
        if name and (not self.states or self.states[-1] != name):
            self.states.append(name)
        code = rec.get("error_code") or 0
        if self._baseline is None:
            self._baseline = code
            self.initial_error = (code, rec.get("error_name")) if code else None
        if code and code not in self.errors:
            self.errors[code] = t
        if code == 0:
            self._baseline = 0
        elif code != self._baseline:
            self._baseline = code
            self.new_error = (code, rec.get("error_name"), t)

    # views
    def period(self, sid=None) -> float:
        """Expected seconds between two frames of one ID."""
        return max(len(self.last_seen), 1) / self.rate

    def stale_ids(self, t) -> list:
        limit = self.stale_periods * self.period()
        return sorted(i for i, seen in self.last_seen.items()
                      if t - seen > limit and (self.ids is None or i in self.ids))

    def snapshot(self, t) -> dict:
        snap = dict(self.latest)
        snap["time_s"] = round(t, 3)
        return snap

    def health(self, t, framer=None) -> dict:
        win = self._rate_window
        while win and win[0] < t - 1.0:
            win.popleft()
        if self.last_seen:
            stale = bool(self.stale_ids(t))
        else:
            stale = t > self.stale_periods / self.rate
        return {
            "frames": self.frames,
            "frames_per_s": float(len(win)) if t >= 1.0 else (len(win) / t if t > 0 else 0.0),
            "crc_errors": framer.bad if framer is not None else 0,
            "skipped": framer.skipped if framer is not None else 0,
            "stale": stale,
            "protocol_version": self.decoder.version,
            "version_source": self.decoder.version_source,
        }

    def summary(self) -> dict:
        fuel = None
        if self.fuel_first is not None:
            fuel = round(self.fuel_last - self.fuel_first, 1)
        return {
            "frames": self.frames,
            "records": self.records,
            "max_rpm": self.max_rpm,
            "max_egt_c": self.max_egt,
            "fuel_used_l": fuel,
            "fuel_total_l": self.fuel_last,
            "states": list(self.states),
            "errors": [{"code": c, "name": zk.ERRORS.get(c, f"undocumented-{c}"), "t": round(t, 3)}
                       for c, t in self.errors.items()],
            "protocol_version": self.decoder.version,
            "version_source": self.decoder.version_source,
        }


# --- signals ---------------------------------------------------------------------------------

#: The signals that end a session: SIGINT (Ctrl-C), SIGTERM, and on Windows SIGBREAK (Ctrl-Break),
#: which ends it like Ctrl-C.
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGBREAK") if hasattr(signal, n))
INTERRUPT_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGBREAK") if hasattr(signal, n))


class SignalGuard:
    """Turn SIGINT and SIGTERM into a flag the session loop checks, so it stops between two
    records (files stay whole) and can send the abort command. Only the first signal counts: a
    repeat (``timeout`` signals twice; a second Ctrl-C) neither interrupts the abort nor changes
    the exit status."""

    def __init__(self):
        self.signum = None
        self._old = {}

    def _handler(self, signum, frame):
        from .. import signals

        if self.signum is not None:
            return
        self.signum = signum
        signals.received(signum)
        stop.note(signum)            # a batch's stop request, taken by this session

    def __enter__(self):
        self.signum = stop.take()    # a stop requested before the session began ends it at once
        if threading.current_thread() is threading.main_thread():
            for s in STOP_SIGNALS:
                try:
                    self._old[s] = signal.signal(s, self._handler)
                except (ValueError, OSError):   # pragma: no cover - embedded interpreters
                    pass
        return self

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)
        self._old = {}
        return False


# --- the session loop ----------------------------------------------------------------------------

class Outcome:
    """How a session ended. ``reason``: ``count``, ``duration``, ``end`` (replay or schedule
    done), ``interrupted``, ``terminated``, ``port``, ``silence``, ``ecu-error``, ``limit``, ``pipe``,
    ``output`` (an output file could not be written)."""

    def __init__(self, reason, error=None, aborted=None):
        self.reason = reason
        self.error = error
        self.aborted = aborted   # the abort kind sent, or None

    @property
    def ok(self):
        return self.reason in ("count", "duration", "end")

    @property
    def exit_code(self) -> int:
        """The exit status that goes with this outcome."""
        from ..errors import INTERRUPTED

        if self.ok or self.reason == "pipe":
            return 0
        if self.reason == "interrupted":
            return INTERRUPTED
        if self.reason == "terminated":
            return TERMINATED
        return getattr(self.error, "code", 1)

    def raise_for_status(self):
        """Raise the exception (exit status) that goes with this outcome, if any."""
        r = self.reason
        if r == "interrupted":
            raise KeyboardInterrupt
        if r == "terminated":
            from ..signals import Terminated

            raise Terminated()
        if r == "pipe":
            raise BrokenPipeError
        if self.error is not None:
            raise self.error


class Session:
    """Run a source through telemetry into ``sink`` while sending control frames.

    ``control(t)`` returns the frame to send at time ``t`` (None: nothing); it is called every
    ``1/rate`` s. Ends on ``count`` records, ``duration`` seconds, the end of a replay, a signal,
    a port failure, ``silence`` seconds without a status frame, or (``stop_on_error``) a new ECU
    error. On an abnormal end — or at the end when ``abort_at_end`` — the abort command is sent if
    the frames sent controlled the engine (see :func:`controls_engine`).
    """

    def __init__(self, source, telemetry, sink, *, control=None, rate=DEFAULT_RATE, abort=DEFAULT_ABORT,
                 count=None, duration=None, silence=DEFAULT_SILENCE_S, stop_on_error=False,
                 abort_at_end=False, on_update=None, notify=None, update_interval=0.1, limits=None, end=None,
                 end_label="end of schedule"):
        self.source = source
        self.telemetry = telemetry
        self.sink = sink
        self.control = control
        self.period = 1.0 / rate
        self.abort = abort
        self.count = count
        self.duration = duration
        self.silence = silence
        self.stop_on_error = stop_on_error
        self.abort_at_end = abort_at_end
        self.end = end                  # sent at a normal end (ENDS); None: the abort if abort_at_end
        self.end_label = end_label
        self.on_update = on_update
        self.notify = notify or (lambda message: None)
        self.update_interval = update_interval
        self.limits = limits     # an api.limits.LimitSet: its first violation ends the session
        self.sent = 0
        self.last_sent = None
        self.ended_t = None
        self.written = 0
        self.controlling = False
        self.pump_on = False
        self.last_frame_t = None
        # the status IDs seen, until the ECU's cycle is known (an ID comes again): then --ids
        # that the ECU never sends are reported (all of them: the session ends)
        self._cycle = set() if telemetry.ids is not None else None
        self._back_t = 0.0
        self.interrupted = None           # PortError text when a reconnect cut engine control

    def _check_ids(self, sid):
        cycle = self._cycle
        if not cycle:
            self._first, self._laps = sid, 0
        cycle.add(sid)
        if sid == self._first:
            self._laps += 1
        if self._laps <= ID_CHECK_LAPS:     # whole cycles, so a lost frame is not a missing ID
            return None
        self._cycle = None
        wanted = self.telemetry.ids
        never = sorted(wanted - cycle)
        if not never:
            return None
        sends = _id_list(cycle)
        if len(never) == len(wanted):
            return Outcome("silence", NoReply(
                f"ids: the ECU never sends status ID{'s' if len(never) > 1 else ''} {_id_list(never)} "
                f"(its cycle is IDs {sends}); nothing to log"))
        self.notify(f"ids: the ECU never sends status ID{'s' if len(never) > 1 else ''} {_id_list(never)} "
                    f"(its cycle is IDs {sends})")
        return None

    def _reconnected(self, gap):
        """The port is back after a drop-out: abort first (a session that controlled the engine
        stops controlling it), then a gap record, then logging goes on."""
        down, up, reason = gap
        self._back_t = up
        if self.controlling and self.abort != "none":
            frames = abort_frames(self.abort, self.telemetry.decoder.known, pump=self.pump_on)
            for f in frames:
                self.source.write(f)
            self.notify(f"port back after {up - down:.1f} s: sent {describe_abort(self.abort)}; "
                        "no longer controlling the engine")
            self.control = None
            self.interrupted = (f"{reason}; the port came back after {up - down:.1f} s and the abort "
                                f"({describe_abort(self.abort)}) was sent")
        elif self.controlling:
            self.notify(f"port back after {up - down:.1f} s (--abort none: nothing sent); "
                        "no longer controlling the engine")
            self.control = None
            self.interrupted = f"{reason}; the port came back after {up - down:.1f} s"
        else:
            self.notify(f"port back after {up - down:.1f} s ({reason})")
        rec = {"time": iso_utc(self.telemetry.wall0 + up), "t": round(up, 3), "kind": "gap",
               "gap_s": round(up - down, 3), "since_t": round(down, 3), "reason": reason}
        self.sink(rec)

    def _send(self, frame):
        self.source.write(frame)
        self.sent += 1
        self.last_sent = frame
        if not self.controlling and controls_engine(frame):
            self.controlling = True
        if frame[1] >> 4 == 2:
            action = zk.ACTIONS.get(frame[2])
            if action == "pump-on":
                self.pump_on = True
            elif action == "pump-off":
                self.pump_on = False

    def run(self) -> Outcome:
        src, tel = self.source, self.telemetry
        written = 0
        next_send = 0.0
        next_update = 0.0
        outcome = None
        told = False
        with SignalGuard() as guard:
            try:
                while outcome is None:
                    if guard.signum is not None:
                        outcome = Outcome("interrupted" if guard.signum in INTERRUPT_SIGNALS else "terminated")
                        break
                    now = src.now()
                    if self.duration is not None and now >= self.duration:
                        if self.control is not None:     # the command in force at the end (a
                            frame = self.control(self.duration)   # schedule's last row)
                            if frame is not None and frame != self.last_sent:
                                self._send(frame)
                        outcome = Outcome("duration")
                        break
                    if self.control is not None and now >= next_send:
                        frame = self.control(now)
                        if frame is not None:
                            self._send(frame)
                        next_send += self.period
                        if next_send <= now:
                            next_send = now + self.period
                    got = src.poll()
                    if got is None:
                        outcome = Outcome("end")
                        break
                    if getattr(src, "gap", None) is not None:
                        self._reconnected(src.take_gap())
                    for t, frame in got:
                        if self.duration is not None and t + 1e-9 >= self.duration:
                            outcome = Outcome("duration")     # a fast replay's batch reaches past it
                            break
                        self.last_frame_t = t
                        if self._cycle is not None:
                            outcome = self._check_ids(frame[0] & 0x0F)
                            if outcome is not None:
                                break
                        if not told and tel.initial_error is not None and self.controlling:
                            told = True
                            self.notify(f"the ECU reports error {tel.initial_error[0]} ({tel.initial_error[1]}) "
                                        f"from before; an ECU starts again only after stop or standby")
                        for rec in tel.feed(t, frame):
                            self.sink(rec)
                            written += 1
                            if self.count is not None and written >= self.count:
                                outcome = Outcome("count")
                                break
                        if outcome is not None:
                            break
                        if tel.new_error is not None and self.stop_on_error:
                            code, name, et = tel.new_error
                            outcome = Outcome("ecu-error", DeviceError(describe_error(code, name, et)))
                            break
                        if self.limits is not None and self.limits.tripped is not None:
                            outcome = Outcome("limit", self.limits.tripped)
                            break
                    if outcome is not None:
                        break
                    now = src.now()
                    if self.on_update is not None and now >= next_update:
                        self.on_update(tel.snapshot(now), tel.health(now, src.framer))
                        next_update = now + self.update_interval
                    if src.live and self.silence is not None and getattr(src, "down", None) is None:
                        since = self.last_frame_t if self.last_frame_t is not None else 0.0
                        since = max(since, self._back_t)
                        # a silence is measured in real seconds, whatever the session's clock
                        if (now - since) / getattr(src, "speed", 1.0) > self.silence:
                            where = getattr(getattr(src, "link", None), "url", "the port")
                            if self.last_frame_t is None:
                                msg = (f"no status frame from the ECU on {where} within {self.silence:g} s "
                                       f"(check the port, baud rate and wiring)")
                            else:
                                msg = f"the ECU on {where} fell silent: no status frame for {self.silence:g} s"
                            outcome = Outcome("silence", NoReply(msg))
                            break
            except PortError as e:
                outcome = Outcome("port", e)
            except OutputError as e:           # a full disk under -o or --raw-log
                outcome = Outcome("output", e)
            except BrokenPipeError:
                outcome = Outcome("pipe")
            finally:
                if outcome is None:            # an unexpected exception: still try to abort
                    self._abort(Outcome("error"))
            if outcome.reason != "count":
                try:
                    for rec in tel.flush():
                        if self.count is not None and written >= self.count:
                            break
                        self.sink(rec)
                        written += 1
                except BrokenPipeError:
                    outcome = Outcome("pipe")
            self._abort(outcome)
        if self.interrupted is not None and outcome.ok:
            outcome = Outcome("port", PortError(self.interrupted), aborted=self.abort)
        self.ended_t = now = src.now()
        if self.on_update is not None:
            self.on_update(tel.snapshot(now), tel.health(now, src.framer))
        self.written = written
        return outcome

    def _abort(self, outcome):
        if outcome.aborted is not None or not self.controlling:
            return
        kind = self.abort
        if outcome.ok:
            kind = self.end if self.end is not None else (self.abort if self.abort_at_end else None)
            if kind == "hold":
                outcome.aborted = "hold"
                self.notify(f"{self.end_label}: --end hold: nothing more sent; the engine keeps the last "
                            f"command")
                return
        if kind is None or kind == "none":
            return
        if outcome.reason == "limit" and not self.limits.abort:
            return
        known = self.telemetry.decoder.known
        frames = abort_frames(kind, known, pump=self.pump_on)
        try:
            for f in frames:
                self.source.write(f)
            time.sleep(0.02)
            self.source.write(frames[0])
        except PortError as e:
            self.notify(f"could not send the abort command ({describe_abort(kind)}): {e}")
            outcome.aborted = "failed"
            return
        outcome.aborted = kind
        why = {"interrupted": "interrupted", "terminated": "terminated", "port": "port failure",
               "silence": "ECU silent", "ecu-error": "ECU error", "pipe": "output closed",
               "output": "output failed", "error": "error", "limit": "limit violated"}.get(outcome.reason,
                                                                                          self.end_label)
        self.notify(f"{why}: sent {describe_abort(kind)}")


def _id_list(ids) -> str:
    """``[1, 2, 3, 5]`` -> ``"1-3,5"``."""
    out = []
    for i in sorted(ids):
        if out and out[-1][1] == i - 1:
            out[-1][1] = i
        else:
            out.append([i, i])
    return ",".join(f"{a}" if a == b else f"{a}-{b}" for a, b in out)


# --- throttle schedules ----------------------------------------------------------------------------

SCHEDULE_STATES = tuple(n for n in zk.CONTROL_SW.values())
_THROTTLE = zk.CONTROL_BY_NAME["control"].layout.by_key["throttle_pct"]
_SW = zk.CONTROL_BY_NAME["control"].layout.by_key["sw"]


class ScheduleError(UsageError):
    pass


class Schedule:
    """Rows of ``time_s,throttle_pct[,state]``: at ``time_s`` the throttle and state apply.

    A header line naming the columns is optional (then ``state`` may be in any column order);
    ``#`` starts a comment; blank lines are skipped. Times must not decrease. A row without a
    state keeps the previous row's; the first row's default is ``default_state`` (run). Before the
    first row's time nothing is sent. ``linear`` interpolates the throttle between rows (the state
    changes at row times). The schedule ends at the last row's time.
    """

    def __init__(self, rows, interpolate="step", name="schedule"):
        if not rows:
            raise ScheduleError(f"{name}: no rows; expected time_s,throttle_pct[,state]")
        self.rows = rows     # [(time_s, throttle_pct, state, line)]
        self.interpolate = interpolate
        self.name = name
        self.notes = []
        self._cache = {}
        self._i = 0

    @classmethod
    def parse(cls, text, name="schedule", interpolate="step", default_state="run"):
        rows = []
        cols = None
        state = default_state
        notes = []
        for lineno, line in enumerate(text.splitlines(), 1):
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            cells = [c.strip() for c in line.split(",")]
            where = f"{name}:{lineno}"
            if cols is None:
                try:
                    float(cells[0])
                    cols = {"time_s": 0, "throttle_pct": 1, "state": 2}
                except ValueError:
                    cols = {c.lower(): i for i, c in enumerate(cells)}
                    missing = [c for c in ("time_s", "throttle_pct") if c not in cols]
                    unknown = [c for c in cols if c not in ("time_s", "throttle_pct", "state")]
                    if missing or unknown:
                        raise ScheduleError(f"{where}: header {line!r}: columns are time_s, throttle_pct "
                                            f"and optionally state")
                    continue
            if len(cells) > 3 or len(cells) < 2:
                raise ScheduleError(f"{where}: {len(cells)} cells; expected time_s,throttle_pct[,state]")
            try:
                t = float(cells[cols["time_s"]])
            except (ValueError, IndexError):
                raise ScheduleError(f"{where}: time_s: {cells[0]!r} is not a number of seconds") from None
            if not t >= 0 or t != t or t == float("inf"):
                raise ScheduleError(f"{where}: time_s: {cells[0]} is out of range; allowed 0 or more")
            if rows and t < rows[-1][0]:
                raise ScheduleError(f"{where}: time_s: {t:g} is before the previous row's {rows[-1][0]:g}; "
                                    f"times must not decrease")
            try:
                throttle = float(cells[cols["throttle_pct"]])
            except (ValueError, IndexError):
                raise ScheduleError(f"{where}: throttle: not a number; allowed "
                                    f"{_THROTTLE.describe_range()}") from None
            si = cols.get("state")
            if si is not None and si < len(cells) and cells[si]:
                state = cells[si].lower()
            try:
                _, note = _THROTTLE.to_raw(throttle)
                state = zk.CONTROL_SW[_SW.to_raw(state)[0]]
            except FieldValueError as e:
                raise ScheduleError(f"{where}: {e}") from None
            if note:
                notes.append(f"{where}: {note}")
            rows.append((t, throttle, state, lineno))
        sched = cls(rows, interpolate, name)
        sched.notes = notes
        return sched

    @property
    def length(self) -> float:
        return self.rows[-1][0]

    def command_at(self, t):
        """(state, throttle_pct) in force at ``t``, or None before the first row."""
        rows = self.rows
        if t < rows[0][0]:
            return None
        i = self._i if self._i < len(rows) and rows[self._i][0] <= t else 0
        while i + 1 < len(rows) and rows[i + 1][0] <= t:
            i += 1
        self._i = i
        t0, thr, state, _ = rows[i]
        if self.interpolate == "linear" and i + 1 < len(rows):
            t1, thr1 = rows[i + 1][0], rows[i + 1][1]
            if t1 > t0:
                thr = thr + (thr1 - thr) * (t - t0) / (t1 - t0)
        return state, thr

    def frame_at(self, t):
        cmd = self.command_at(t)
        if cmd is None:
            return None
        state, thr = cmd
        step = _THROTTLE.scale
        key = (state, round(thr / step))
        frame = self._cache.get(key)
        if frame is None:
            frame = self._cache[key] = zk.encode_control("control", sw=state, throttle_pct=key[1] * step)[0]
        return frame

    def frames(self):
        """Every distinct frame the schedule can send (for consent and validation)."""
        out = []
        for _, thr, state, _ in self.rows:
            f = zk.encode_control("control", sw=state, throttle_pct=round(thr / _THROTTLE.scale) * _THROTTLE.scale)[0]
            out.append(f)
        return out

    def plan(self, rate):
        """``[(t, state, throttle_pct, frame)]``: each change of the frame sent at ``rate`` Hz."""
        out = []
        last = None
        n = int(self.length * rate + 1e-9)
        for i in range(n + 1):
            t = i / rate
            frame = self.frame_at(t)
            if frame is not None and frame != last:
                rec = zk.decode_control(frame)
                out.append((round(t, 3), rec["state"], rec["throttle_pct"], frame))
                last = frame
        return out

    @property
    def final_state(self) -> str:
        return self.rows[-1][2]
