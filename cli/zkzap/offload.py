"""Outputs written off the control path: an output that stops taking data (a pipe nobody reads,
``| less`` at its prompt, a FIFO nobody opened, a stalled network file system) never holds up
the loop that sends control frames, nor the abort.

A :class:`Lane` is one output's writer thread with a bounded queue: the session's thread hands
it each write (``lane.call(fn, *args)``: a record for stdout or ``-o``, the bytes read for
``--raw-log``, a packet for ``--capture``) and goes on at once; the lane makes them in order,
opening the file with the first (a FIFO's open waits there, not in the session). An error of
the output (a full disk, a closed pipe) is raised in the session's thread by its next call —
the same exception the write raised, so a session ends on it as before (``output``, exit 7;
``pipe``), with its abort.

When a lane's queue is full (:data:`LIMIT` writes waiting), :meth:`Lane.call` either raises
:class:`Stalled` at once (in an :class:`urgent` block: a session that controls the engine,
which ends safely on it — abort sent, exit 7, the message says how many writes were not made)
or waits for room (a session that only listens, where waiting loses nothing), until a stop is
requested (a signal): the session then ends by the signal, and the writes that found no room
are counted with those not made. At the end, :meth:`Lane.finish`
waits while the lane makes the writes still queued; one that makes none for :data:`DRAIN_S` is
abandoned (:func:`abandoned`): the program exits without touching its stream again. Stdlib
only.
"""

from __future__ import annotations

import collections
import threading
import time

from .errors import OutputError

#: Writes that may wait in one lane; a full queue is a stalled output.
LIMIT = 4096
#: How long the end of a session waits for a lane's queued writes (seconds).
DRAIN_S = 2.0
#: The longest sleep of a waiting :meth:`Lane.call` between two looks for a stop request.
WAIT_SLICE = 0.05

_abandoned: list = []
_urgent = [0]


class urgent:
    """``with urgent():`` a session controls the engine: a lane whose queue is full raises
    :class:`Stalled` at once instead of waiting for room (see the module)."""

    def __enter__(self):
        _urgent[0] += 1
        return self

    def __exit__(self, *exc):
        _urgent[0] -= 1
        return False


class Stalled(OutputError):
    """An output took nothing while :data:`LIMIT` writes waited (or a stop came while one
    waited): the session ends safely; ``pending``: the writes not made."""


def abandoned() -> list:
    """The lanes given up on (still blocked at the end): their streams must not be flushed
    again (the program exits at once)."""
    return [lane for lane in _abandoned if lane.busy]


def _stopping() -> bool:
    from . import signals
    from .link import stop

    return signals.first() is not None or stop.requested() is not None


class Lane:
    """The writer thread of one output (see the module). ``what``: the output's name in
    messages (``stdout``, ``--raw-log run.bin``); ``wait``: what a full queue does (see the
    module; None: wait unless an :class:`urgent` block runs); ``limit``: the queue's bound."""

    def __init__(self, what: str, *, wait=None, limit: int = LIMIT):
        self.what = what
        self.wait = wait
        self.limit = limit
        self._queue = collections.deque()
        self._cv = threading.Condition(threading.Lock())
        self._thread = None
        self._error = None          # the exception a write raised: raised by the next call
        self._running = None        # monotonic time the write in progress began (None: idle)
        self._last = time.monotonic()   # when a write last completed
        self._closed = False
        self.done = 0               # writes made
        self.dropped = 0            # writes not queued while a stop was under way (the queue full)
        self.told = False           # the stall was said (by whoever said it)

    @property
    def busy(self) -> bool:
        """A write is in progress or queued."""
        return self._running is not None or bool(self._queue)

    @property
    def pending(self) -> int:
        """Writes queued or in progress, and those dropped (see :meth:`call`)."""
        return len(self._queue) + (self._running is not None) + self.dropped

    def _start(self):
        self._thread = threading.Thread(target=self._run, name=f"zkzap output {self.what}", daemon=True)
        self._thread.start()

    def _run(self):
        cv, queue = self._cv, self._queue
        while True:
            with cv:
                while not queue and not self._closed:
                    cv.wait()
                if not queue:
                    return
                fn, args = queue.popleft()
                self._running = time.monotonic()
            try:
                fn(*args)
            except BaseException as e:    # handed to the caller's thread
                with cv:
                    if self._error is None:
                        self._error = e
                    queue.clear()         # the output failed: the rest would fail too
            finally:
                with cv:
                    self._running = None
                    self._last = time.monotonic()
                    self.done += 1
                    cv.notify_all()

    def stalled(self) -> Stalled:
        """The error of this lane's output stalled (what waited, for how long)."""
        idle = time.monotonic() - (self._running if self._running is not None else self._last)
        n = self.pending
        return Stalled(f"{self.what}: stalled: the output took nothing for {idle:.1f} s while {n} writes waited; "
                       f"they were not made", pending=n)

    def check(self) -> None:
        """Raise the error of a write made meanwhile, if any."""
        if self._error is not None:
            raise self._error

    def call(self, fn, *args) -> None:
        """Make ``fn(*args)`` in the lane, in order; returns at once (see the module for a full
        queue). Raises the error a previous write raised."""
        if self._error is not None:
            raise self._error
        if self._thread is None:
            self._start()
        with self._cv:
            while len(self._queue) >= self.limit:
                wait = self.wait if self.wait is not None else not _urgent[0]
                if not wait:
                    raise self.stalled()
                if _stopping():
                    self.dropped += 1     # the session ends by the signal: counted, said at the end
                    return
                self._cv.wait(WAIT_SLICE)
                if self._error is not None:
                    raise self._error
            self._queue.append((fn, args))
            self._cv.notify_all()

    def wrap(self, fn):
        """``fn`` made in the lane: a callable for the session (a sink, a write)."""
        call = self.call

        def offloaded(*args):
            call(fn, *args)

        return offloaded

    def _settle(self, timeout) -> bool:
        # with the condition held: wait while writes are made; False when none was made for
        # ``timeout`` s (the output is stalled: a slow one that goes on is waited for)
        start = time.monotonic()
        while self.busy:
            idle = time.monotonic() - max(start, self._last)
            if idle >= timeout:
                return False
            self._cv.wait(min(timeout - idle, WAIT_SLICE))
        return True

    def drain(self, timeout: float = DRAIN_S) -> bool:
        """Wait for the queued writes while they are being made; False: none was made for
        ``timeout`` s (stalled)."""
        with self._cv:
            return self._settle(timeout)

    def finish(self, fn=None, timeout: float = DRAIN_S) -> bool:
        """Make the queued writes and then ``fn()`` (the output's close), and end the thread,
        waiting while writes are made. False: none was made for ``timeout`` s (abandoned: the
        writes left and ``fn`` are not made). The error of a write (or of ``fn``) stays for
        :meth:`check`."""
        if self._thread is None:
            if fn is not None:
                fn()
            return True
        if self in _abandoned:
            return False                  # given up on already: no second wait
        with self._cv:
            if fn is not None:
                self._queue.append((fn, ()))
            self._closed = True
            self._cv.notify_all()
            blocked = not self._settle(timeout)
        if blocked:
            self.abandon()
            return False
        self._thread.join(timeout)
        return True

    def abandon(self) -> None:
        """Give up on this lane (still blocked): nothing more is waited for, and the program
        exits without touching its stream again."""
        if self not in _abandoned:
            _abandoned.append(self)

    def lost(self) -> str:
        """What an abandoned lane did not write, in words (it is then :attr:`told`)."""
        self.told = True
        return f"{self.what}: stalled: {self.pending} writes not made at the end (the output took nothing)"


class Proxy:
    """``obj`` whose methods named in ``offloaded`` are made in ``lane`` (the rest are the
    object's own, called in place)."""

    def __init__(self, obj, lane: Lane, offloaded):
        self._obj = obj
        self._lane = lane
        for name in offloaded:
            setattr(self, name, lane.wrap(getattr(obj, name)))

    def __getattr__(self, name):
        return getattr(self._obj, name)


__all__ = ["Lane", "Proxy", "Stalled", "abandoned", "urgent", "LIMIT", "DRAIN_S"]
