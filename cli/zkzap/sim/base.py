"""The interface every simulated device implements, and the simulation clock."""

from __future__ import annotations

import time

from ..errors import InvalidValue


def parse_flag(key: str, value) -> bool:
    """A simulator's on/off option (a URL query or a command-line value): 1/0, true/false,
    yes/no, on/off; empty is off."""
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("1", "true", "yes", "on"):
        return True
    if text in ("0", "false", "no", "off", ""):
        return False
    raise InvalidValue(f"{key}: {value!r} is not a boolean; allowed 0/1, true/false")


def parse_number(key: str, value, lo=None, hi=None) -> float:
    """A simulator's numeric option (a URL query or a command-line value): a finite number,
    within ``lo..hi`` when given; ValueError naming ``key`` otherwise."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InvalidValue(f"{key}: {value!r} is not a number") from None
    if number != number or number in (float("inf"), float("-inf")):
        raise InvalidValue(f"{key}: {value!r} is not a finite number")
    if (lo is not None and number < lo) or (hi is not None and number > hi):
        allowed = f"{lo:g}..{hi:g}" if lo is not None and hi is not None else (
            f"{lo:g} or more" if lo is not None else f"{hi:g} or less")
        raise InvalidValue(f"{key}: {value} is out of range; allowed {allowed}")
    return number


class Clock:
    """Model time: real monotonic time scaled by ``speed`` (``speed=10`` runs ten times faster)."""

    #: Whether time passes only when a reader waits on it (:class:`VirtualClock`).
    virtual = False

    def __init__(self, speed: float = 1.0):
        if not isinstance(speed, (int, float)) or speed != speed or not 0 < speed < float("inf"):
            raise InvalidValue(f"speed: {speed} is out of range; allowed a finite number > 0")
        self.speed = speed
        self._t0 = time.monotonic()

    def now(self) -> float:
        """Seconds of model time since the clock started."""
        return (time.monotonic() - self._t0) * self.speed

    def real_delay(self, model_seconds: float) -> float:
        """Real seconds until ``model_seconds`` of model time have passed."""
        return max(0.0, model_seconds / self.speed)



class VirtualClock(Clock):
    """Model time that passes only when the host waits (``sim://zap?clock=virtual``): a read
    that finds nothing moves the clock on to the device's next byte or the read's timeout,
    whichever is sooner, and a sleep of the host is a jump. A program that waits 150 ms for a
    reply that never comes takes microseconds; every time it measures (round trips, windows,
    latencies) is the model's, exact and the same on every run, however loaded the machine.
    The clock is the host's too: a bus on such a port reads it instead of the system's."""

    virtual = True

    def __init__(self, start: float = 0.0):
        self.speed = 1.0
        self._t = float(start)

    def now(self) -> float:
        return self._t

    def advance(self, seconds: float) -> None:
        """Let ``seconds`` of model time pass."""
        if seconds > 0:
            self._t += seconds

    def real_delay(self, model_seconds: float) -> float:
        return 0.0


def keep_wire_time(device, clock: "Clock"):
    """Serve ``device`` on ``clock``: whatever the clock's speed, a byte takes its real time on
    the wire (a faster model time shortens turnarounds and moves, never the line: a reply cannot
    come sooner than the baud rate carries it). Returns ``device``."""
    line = getattr(device, "model", device)       # a replay's modelled bus
    if hasattr(line, "wire_scale"):
        line.wire_scale = clock.speed
    return device

class Device:
    """A virtual device on a serial line. All times are model seconds from a :class:`Clock`.

    - :meth:`receive` takes bytes the host wrote (``baud`` is the host's line speed when the
      transport knows it, else None);
    - :meth:`poll` returns the bytes the device sends by ``now`` (possibly ``b""``);
    - :meth:`next_wakeup` says when :meth:`poll` next has something to do (None: only after
      input).
    """

    def receive(self, data: bytes, now: float, baud=None) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def poll(self, now: float) -> bytes:  # pragma: no cover - interface
        raise NotImplementedError

    def next_wakeup(self, now: float):  # pragma: no cover - interface
        return None

    def poll_line(self, now: float, baud=None) -> bytes:
        """What a host listening at ``baud`` (None: unknown, as over TCP) hears by ``now``. A
        device that sends at a fixed line speed returns nothing to a host at another speed:
        transports that know the host's baud call this instead of :meth:`poll`."""
        return self.poll(now)

    def close(self) -> None:
        """Called when the simulator stops (save state, ...)."""
