"""The one clock of a ZK session: :class:`SessionClock`.

A session counts its time from its start, in *session seconds*: real seconds on a real port,
model seconds on an in-process simulator that runs faster than real time
(``sim://zk?speed=10``). Everything of a session reads this one clock — the control rate,
``--for``/``--duration``, a schedule's rows, ``--timeout``, ``--reconnect``, every record's
``t`` — and every wall-clock date it writes (a record's ``time``, MCAP log times, the logbook's
``started``/``ended``) is the real moment that session time corresponds to
(:meth:`SessionClock.wall`). The port's reads are sliced in real seconds derived from it
(:meth:`SessionClock.real`), so a control rate holds whatever the simulator's speed.

Replays have a clock of their own (:class:`ReplayClock`): the recording's time, and the
recording's dates where it has them (a pcapng capture), none for a raw log.
"""

from __future__ import annotations

import time


_ANCHOR: list = []


def wall_now() -> float:
    """The wall-clock time now, as the process's first reading of it plus the monotonic time
    since: the stamps of a capture (and of a sniffer's ports) are dates whose differences are
    true durations even while the system clock is slewed or stepped (round trips measured on the
    monotonic clock and read from a capture then agree)."""
    if not _ANCHOR:
        _ANCHOR.extend((time.time(), time.monotonic()))
    return _ANCHOR[0] + (time.monotonic() - _ANCHOR[1])


def iso_utc(ts: float) -> str:
    """``2024-05-01T12:00:00.123Z`` for a POSIX time."""
    sec, ms = divmod(int(round(ts * 1000)), 1000)
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(sec)) + f".{ms:03d}Z"


class SessionClock:
    """Session seconds since :meth:`start` (or since it was made), and what they mean in real
    time. ``model`` is a simulator's clock (``now()`` in model seconds, ``speed`` model seconds
    per real second); None means real time."""

    def __init__(self, model=None):
        now = getattr(model, "now", None)
        self._now = now if callable(now) else time.monotonic
        self.speed = float(getattr(model, "speed", 1.0)) if callable(now) else 1.0
        # a virtual clock (its time passes only while the host waits): a sleep is a jump
        self._advance = model.advance if callable(now) and getattr(model, "virtual", False) else None
        self.virtual = self._advance is not None
        self.start()

    @classmethod
    def of_port(cls, ser) -> "SessionClock":
        """The clock of a session on the pyserial port ``ser``: the model clock of an in-process
        simulator, real time for anything else."""
        return cls(getattr(ser, "clock", None))

    def start(self) -> None:
        """Make now the session's time 0 (and its wall-clock origin)."""
        self.t0 = self._now()
        self.wall0 = time.time()

    def now(self) -> float:
        """Session seconds since the start."""
        return self._now() - self.t0

    def real(self, seconds: float) -> float:
        """Real seconds that ``seconds`` of session time take."""
        return seconds / self.speed

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of session time."""
        if seconds > 0:
            if self._advance is not None:
                self._advance(seconds)
            else:
                time.sleep(seconds / self.speed)

    def wall(self, t: float):
        """The POSIX time at session time ``t``: the real moment it happened."""
        return self.wall0 + t / self.speed

    def iso(self, t: float):
        """:meth:`wall` as ISO 8601 UTC (``2024-05-01T12:00:00.123Z``)."""
        return iso_utc(self.wall(t))


class ReplayClock:
    """The clock of a replay: ``now`` gives the replay's time; ``wall0`` the recording's date at
    time 0 (None for a raw log, which holds no dates: records get ``time: null``)."""

    speed = 1.0

    def __init__(self, now, wall0=None):
        self.now = now
        self.wall0 = wall0

    def real(self, seconds: float) -> float:
        """Real seconds that ``seconds`` of the replay take (a replay runs in real time)."""
        return seconds

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds``."""
        if seconds > 0:
            time.sleep(seconds)

    def wall(self, t: float):
        """The recording's POSIX time at ``t`` (None when it holds no dates)."""
        return None if self.wall0 is None else self.wall0 + t

    def iso(self, t: float):
        """:meth:`wall` as ISO 8601 UTC, or None."""
        w = self.wall(t)
        return None if w is None else iso_utc(w)
