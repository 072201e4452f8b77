"""Status frames from a ZK ECU, each with its time since the start: :class:`LiveSource` reads
them from a :class:`~zkzap.link.zk_port.ZkLink` (and reopens a port that vanished, when asked),
:class:`ReplaySource` from a raw log (paced in real time or as fast as possible).

A source has ``now()``, ``poll()`` (``[(t, frame), ...]``; None at the end of a replay),
``write(frame)``, ``close()``, its ``framer`` and its ``clock`` (the session's one clock, see
:mod:`zkzap.link.clock`); :class:`zkzap.api.session.Session` runs one.
"""

from __future__ import annotations

import time
from collections import deque

from ..codec import zk
from ..codec.framing import SignalLock, ZkFramer
from ..errors import PortError, UsageError
from ..infile import open_input
from .clock import ReplayClock, SessionClock
from .zk_port import READ_SIZE, READ_SLICE_S, ZkLink

#: Pause between two attempts to reopen a vanished port (seconds).
REOPEN_INTERVAL = 0.25
#: The least time between two frames' stamps (session seconds): the resolution of a record's
#: ``t`` and ``time``, so that no two records share a time.
MIN_SPACING_S = 0.001


class LiveSource:
    """Status frames from a :class:`ZkLink`, stamped with session seconds (:attr:`clock`).

    Frames are handed on only from a stream that is an ECU's: :attr:`signal` (a
    :class:`~zkzap.codec.framing.SignalLock`) holds back the CRC-valid frames that random
    bytes give by chance, so a line carrying noise is as silent as one carrying nothing.

    With ``reconnect`` (session seconds), a port that fails or vanishes is reopened (the same
    device path or URL) every :data:`REOPEN_INTERVAL` for up to that long: meanwhile
    :meth:`poll` returns no frames and :attr:`down` is the time it failed. The port is back when
    bytes come from it again, not when it opens: a port that opens and fails again before
    anything came (a TCP bridge whose device is gone, a USB adapter flapping) is the same
    outage, still counted from its first failure. Once it is back, :attr:`gap` is ``(t_down,
    t_up, reason)`` until :meth:`take_gap`. ``reconnect`` seconds after the first failure the
    port failure is raised as it would have been without it (at most one read slice later: a
    reopen attempt is given no more than the time left, so one that hangs — a TCP connect that
    pyserial would wait 5 s for — is given up when the window ends).
    """

    live = True

    def __init__(self, link: ZkLink, reconnect=None):
        self.link = link
        self.reconnect = reconnect
        self.framer = ZkFramer("status")
        self.signal = SignalLock(self.framer)
        #: The session's one clock: model time on an in-process simulator (sim://zk?speed=N),
        #: so durations, schedules, the control rate and timeouts follow the simulated engine.
        self.clock = SessionClock.of_port(link.ser)
        self.speed = self.clock.speed
        self.down = None                  # session time the port failed, while it is away
        self._reopened = False            # away, but open again: back once bytes come
        self.gap = None
        self.reconnects = 0
        self._error = None
        self._next_try = 0.0
        self._wire_s = None
        self._last_t = None

    @property
    def wall0(self) -> float:
        """The POSIX time of the session's time 0."""
        return self.clock.wall0

    def now(self) -> float:
        """Session seconds since the source started (model seconds on a sped-up simulator)."""
        return self.clock.now()

    def restart(self) -> None:
        """Make now the session's time 0 (a session begins after listening first)."""
        self.clock.start()
        self._last_t = None

    def pace(self, period: float) -> None:
        """Read in slices short enough for something due every ``period`` session seconds:
        half of it, in real seconds, at most :data:`~zkzap.link.zk_port.READ_SLICE_S`."""
        self.link.set_slice(min(READ_SLICE_S, self.clock.real(period) / 2))

    def poll(self):
        """Frames read within one slice, as ``[(t, frame), ...]``."""
        if self.down is not None and not self._reopened:
            return self._retry()
        try:
            data = self.link.read()
        except PortError as e:
            if not self.reconnect:
                raise
            self._fail(e)
            return []
        if self.down is not None:          # open again: back only once bytes come
            if not data:
                self._give_up()
                return []
            self._back()
        if not data:
            return []
        t = self.now()
        frames = self.framer.feed(data)
        return self.signal.admit(len(data), frames, self._stamp(t, frames))

    def _stamp(self, t, frames):
        """Each frame of one read with its own time: the last one ends at the read, each one
        before it a frame's time on the wire earlier (they came back to back, or they would not
        share a read); never before the session's start, nor within :data:`MIN_SPACING_S` of the
        frame before it (the records' times resolve milliseconds: each gets its own) — and never
        after the read: a stamp is never ahead of the clock. Frames that come faster than one a
        millisecond (no ECU does: an overspeed simulator over TCP) share what is left of the time
        up to the read evenly, so their records may repeat a millisecond; ``--for`` and every
        duration stay the clock's."""
        n = len(frames)
        if not n:
            return []
        wire = self._wire_s
        if wire is None:
            ser = self.link.ser
            baud = getattr(ser, "baudrate", None) or 115200
            bits = 1 + 8 + (2 if getattr(ser, "stopbits", 1) == 2 else 1)
            # session seconds per frame on the wire, and at least the records' time resolution
            wire = self._wire_s = max(MIN_SPACING_S, 7 * bits / baud * self.speed)
        out = []
        last = self._last_t
        for k, f in enumerate(frames):
            tk = max(0.0, t - (n - 1 - k) * wire)
            if last is not None and tk < last + MIN_SPACING_S:
                tk = last + MIN_SPACING_S
                if tk > t:                # faster than one a millisecond: up to the read, no further
                    tk = max(last, min(t, last + (t - last) / (n - k)))
            out.append((tk, f))
            last = tk
        self._last_t = last
        return out

    def noise_facts(self) -> dict:
        """What the line carried when no status frame came: ``bytes`` received and
        ``chance_frames`` (CRC-valid frames taken for chance), when it was noise."""
        sig = self.signal
        if not sig.noise or sig.accepted:
            return {}                      # nothing came, a frame's worth at most, or an ECU
        return {"bytes": sig.bytes, "chance_frames": sig.rejected + len(sig.held)}

    def _fail(self, e):
        if self.down is None:              # a failure while reopened is the same outage
            self.down = self.now()
            self._error = e
        self._reopened = False
        self._next_try = 0.0 if self._error is e else self.now() + REOPEN_INTERVAL
        self.framer.flush()                # a frame cut by the drop-out is not glued to new bytes

    def _give_up(self):
        if self.now() - self.down > self.reconnect:
            raise PortError(f"{self._error}; not back within --reconnect {self.reconnect:g} s")

    def _back(self):
        self.gap = (self.down, self.now(), str(self._error))
        self.down = None
        self._reopened = False
        self.reconnects += 1

    def _retry(self):
        self._give_up()
        now = self.now()
        if now < self._next_try:
            self.clock.sleep(min(0.05, self._next_try - now))
            return []
        self._next_try = now + REOPEN_INTERVAL
        try:                               # an attempt never outlasts the window
            self.link.reopen(within=self.clock.real(self.reconnect - (now - self.down)))
        except (PortError, UsageError):
            self._give_up()                # an attempt that took long may end the window
            return []
        self._reopened = True
        return []

    def take_gap(self):
        """The last drop-out ``(t_down, t_up, reason)`` once the port is back (then None)."""
        gap, self.gap = self.gap, None
        return gap

    def write(self, frame):
        """Send a control frame (nothing while the port is away)."""
        if self.down is not None and not self._reopened:
            return                         # nothing to write to while the port is away
        try:
            self.link.write(frame)
        except PortError as e:
            if not self.reconnect:
                raise
            self._fail(e)

    def close(self):
        """Close the port."""
        self.framer.flush()
        self.link.close()


class PacedReplay:
    """What the replays share: recorded frames handed out at their times, paced in real time
    or, with ``fast``, as fast as they decode (at most :attr:`FAST_BATCH` a poll, so a
    session looks at its signals between them). A subclass gives ``_peek()`` (the next
    ``(t, frame)``, None at the end) and ``_pop()`` (that frame is taken), and sets ``fast``
    and ``t0`` (the monotonic start)."""

    live = False
    FAST_BATCH = 256
    #: The recording's date at time 0 (None: a raw log holds no dates; records get ``time: null``).
    wall0 = None

    @property
    def clock(self) -> ReplayClock:
        """The replay's clock: its own time, and the recording's dates where it has them."""
        return ReplayClock(self.now, self.wall0)

    def pace(self, period: float) -> None:
        """Nothing to pace: a replay is read as it was recorded."""

    def now(self) -> float:
        """The replay's time: the last frame's with ``fast``, else seconds since the start."""
        return self.last_t if self.fast else time.monotonic() - self.t0

    def poll(self):
        """Due frames as ``[(t, frame), ...]``; None at the end of the recording."""
        head = self._peek()
        if head is None:
            return None
        out = []
        if self.fast:
            while head is not None and len(out) < self.FAST_BATCH:
                out.append(head)
                self._pop()
                head = self._peek()
        else:
            elapsed = time.monotonic() - self.t0
            if head[0] > elapsed:
                time.sleep(min(head[0] - elapsed, 0.05))
                elapsed = time.monotonic() - self.t0
            while head is not None and head[0] <= elapsed:
                out.append(head)
                self._pop()
                head = self._peek()
        if out:
            self.last_t = out[-1][0]
        return out

    def write(self, frame):   # pragma: no cover - sessions never control a replay
        """Refused: nothing can be sent to a replay."""
        raise UsageError("replay: nothing can be sent to a replay")


class ReplaySource(PacedReplay):
    """Status frames from a raw log (the exact bytes a monitor received).

    A raw log holds bytes, not times: frame times are rebuilt from the status rate the frames
    themselves report (status ID 6; 20 Hz until one is seen), so frame *n* is at the sum of the
    periods before it. ``fast`` returns frames as fast as they can be decoded; otherwise they
    are paced in real time.
    """

    def __init__(self, path, fast=False):
        try:
            self.file = open_input(path)
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

    def _peek(self):
        self._fill()
        return self.queue[0] if self.queue else None

    def _pop(self):
        self.queue.popleft()

    def close(self):
        """Close the log."""
        self.file.close()
