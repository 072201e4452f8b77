"""SIGINT and SIGTERM for the command-line programs, from the first instant of the process.

:func:`install` runs before click and the command modules are imported. Until :func:`running`
is called (the command is about to parse its arguments), a signal ends the process at once,
quietly, with 130 (SIGINT) or 143 (SIGTERM): nothing has been opened or written yet. From then
on SIGINT raises :class:`KeyboardInterrupt` and SIGTERM :class:`Terminated` (a subclass, so
every ``except KeyboardInterrupt`` that cleans up or prints a summary runs for both), and the
program exits 130 or 143.

Only the first signal counts: a repeat (``timeout`` signals the command and then its process
group, so the command gets SIGTERM twice; an impatient second Ctrl-C) is recorded and
otherwise ignored, so the clean-up it would interrupt (an engine abort, a summary) completes
and the exit status stays that of the first signal.

:class:`SignalGuard` is the loop-level alternative for a session that must stop between two
records and send an abort: while it is active, SIGINT and SIGTERM (and SIGBREAK on Windows) only
set a flag the loop checks. Stdlib only.
"""

from __future__ import annotations

import os
import signal
import threading

SIGNALS = (signal.SIGINT, signal.SIGTERM)
EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143}


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C's KeyboardInterrupt; exit status 143."""


_state = {"phase": None, "first": None}


def _handler(signum, frame):
    if _state["phase"] == "starting":
        os._exit(EXIT.get(signum, 128 + signum))
    if _state["first"] is not None:
        return                       # a repeat: the first signal is already being handled
    _state["first"] = signum
    raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def install() -> None:
    """Handle SIGINT and SIGTERM from now on (the start-up phase: exit at once)."""
    if threading.current_thread() is not threading.main_thread():
        return
    _state["phase"] = "starting"
    _state["first"] = None
    for s in SIGNALS:
        try:
            if signal.getsignal(s) is signal.SIG_IGN:   # nohup, a shell's background job
                continue
            signal.signal(s, _handler)
        except (ValueError, OSError):   # pragma: no cover - embedded interpreters
            pass


def running() -> None:
    """The command runs: signals become exceptions (KeyboardInterrupt, Terminated)."""
    if _state["phase"] is not None:
        _state["phase"] = "running"


def installed() -> bool:
    """Whether :func:`install` ran (this process is one of the programs)."""
    return _state["phase"] is not None


def received(signum) -> None:
    """Record a signal handled elsewhere (a session's own handler), so repeats are ignored
    (only in a program: a library user's process keeps its own state)."""
    if _state["phase"] is not None and _state["first"] is None:
        _state["first"] = signum


def forget() -> None:
    """Forget the signals received so far (a shell back at its prompt): the next one counts as a
    first one again."""
    _state["first"] = None


def first():
    """The first signal received since :func:`install` (None: none)."""
    return _state["first"]


def exit_status(exc) -> int:
    """130 for Ctrl-C, 143 for SIGTERM (``exc``: the KeyboardInterrupt raised)."""
    if isinstance(exc, Terminated) or _state["first"] == signal.SIGTERM:
        return EXIT[signal.SIGTERM]
    return EXIT[signal.SIGINT]


from ._program import is_program  # noqa: E402,F401 - part of this module's interface


#: The signals that end a session: SIGINT (Ctrl-C), SIGTERM, and on Windows SIGBREAK (Ctrl-Break),
#: which ends it like Ctrl-C.
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGBREAK") if hasattr(signal, n))
INTERRUPT_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGBREAK") if hasattr(signal, n))


def handle(sigs, handler) -> dict:
    """Install ``handler`` for each of ``sigs`` (only the main thread may; elsewhere nothing
    changes); returns the handlers replaced, for :func:`restore`."""
    old = {}
    if threading.current_thread() is threading.main_thread():
        for s in sigs:
            try:
                old[s] = signal.signal(s, handler)
            except (ValueError, OSError):   # pragma: no cover - embedded interpreters, other platforms
                pass
    return old


def restore(old) -> None:
    """Put back the handlers :func:`handle` replaced."""
    for s, h in old.items():
        signal.signal(s, h)


class held:
    """``with held():`` SIGINT and SIGTERM wait until the block ends (in the main thread, where
    handlers run; elsewhere, and where the platform cannot mask signals, nothing changes): a
    write of a whole block or line is never cut short by a handler raising in the middle."""

    __slots__ = ("_old",)

    def __enter__(self):
        self._old = None
        if threading.current_thread() is threading.main_thread() and hasattr(signal, "pthread_sigmask"):
            self._old = signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
        return self

    def __exit__(self, *exc):
        if self._old is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, self._old)
        return False


class SignalGuard:
    """Turn SIGINT and SIGTERM into a flag the session loop checks, so it stops between two
    records (files stay whole) and can send the abort command. Only the first signal counts: a
    repeat (``timeout`` signals twice; a second Ctrl-C) neither interrupts the abort nor changes
    the exit status."""

    def __init__(self):
        self.signum = None
        self.repeats = 0             # signals after the first (a second Ctrl-C ends a rundown)
        self._old = {}

    def _handler(self, signum, frame):
        if self.signum is not None:
            self.repeats += 1
            return
        self.signum = signum
        received(signum)
        from .link import stop

        stop.note(signum)            # a batch's stop request, taken by this session

    def __enter__(self):
        from .link import stop

        self.signum = stop.take()    # a stop requested before the session began ends it at once
        self._old = handle(STOP_SIGNALS, self._handler)
        return self

    def __exit__(self, *exc):
        restore(self._old)
        self._old = {}
        return False
