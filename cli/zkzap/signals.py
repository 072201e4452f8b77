"""The signals that end the command-line programs, from the first instant of the process.

Every signal whose default action ends the process and that another process (a terminal, ssh,
``timeout``, ``kill``) sends is handled — :data:`STOP_SIGNALS`: SIGINT, SIGTERM, SIGHUP,
SIGQUIT, SIGUSR1, SIGUSR2, SIGALRM, SIGVTALRM, SIGPROF, SIGXCPU, SIGIO, SIGPWR, SIGSTKFLT and
the real-time signals (SIGBREAK on Windows). A signal ignored when the program starts (``nohup``
ignores SIGHUP, a shell's background job SIGINT and SIGQUIT) stays ignored: that is the
convention. Not handled: SIGKILL and SIGSTOP (no process can), the faults of the process
itself (SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT, SIGSYS, SIGTRAP: its state cannot be trusted
to run a clean-up), and SIGPIPE and SIGXFSZ, which Python ignores so that a write fails instead
(a closed stdout ends a session as ``pipe``, with its abort).

:func:`install` runs before click and the command modules are imported. Until :func:`running`
is called (the command is about to parse its arguments), a signal ends the process at once,
quietly, with 128 + its number (130 SIGINT, 143 SIGTERM, 129 SIGHUP, ...): nothing has been
opened or written yet. From then on SIGINT raises :class:`KeyboardInterrupt` and every other
one :class:`Terminated` (a subclass, so every ``except KeyboardInterrupt`` that cleans up,
sends an abort or prints a summary runs for all of them), and the program exits 128 + its
number.

Only the first signal counts: a repeat (``timeout`` signals the command and then its process
group, so the command gets SIGTERM twice; an impatient second Ctrl-C) is recorded and
otherwise ignored, so the clean-up it would interrupt (an engine abort, a summary) completes
and the exit status stays that of the first signal.

:class:`SignalGuard` is the loop-level alternative for a session that must stop between two
records and send an abort: while it is active, SIGINT and SIGTERM (and SIGBREAK on Windows) only
set a flag the loop checks (and every other signal of :data:`STOP_SIGNALS`). Stdlib only.
"""

from __future__ import annotations

import os
import signal
import threading



def _stop_signals() -> tuple:
    names = ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT", "SIGUSR1", "SIGUSR2", "SIGALRM", "SIGVTALRM",
             "SIGPROF", "SIGXCPU", "SIGIO", "SIGPWR", "SIGSTKFLT", "SIGBREAK")
    found = [getattr(signal, n) for n in names if hasattr(signal, n)]
    if hasattr(signal, "SIGRTMIN"):
        found += range(signal.SIGRTMIN, signal.SIGRTMAX + 1)
    out = []
    for s in found:                  # SIGIO and SIGPOLL are one signal on Linux
        if int(s) not in {int(o) for o in out}:
            out.append(s)
    return tuple(out)


#: The signals that end a session (and a program) safely: every one whose default action ends
#: the process and that comes from outside it (see the module).
STOP_SIGNALS = _stop_signals()
#: The signals that end a session as Ctrl-C does (exit 130): SIGINT, and SIGBREAK on Windows.
INTERRUPT_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGBREAK") if hasattr(signal, n))
SIGNALS = STOP_SIGNALS


def status(signum) -> int:
    """The exit status of a program ended by ``signum``: 128 + its number (130 for SIGINT and
    SIGBREAK, as Ctrl-C)."""
    if signum in INTERRUPT_SIGNALS:
        return 130
    return 128 + int(signum)


def name(signum) -> str:
    """``SIGHUP``, ``SIGRTMIN+3``: the signal's name."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        if hasattr(signal, "SIGRTMIN") and signal.SIGRTMIN <= signum <= signal.SIGRTMAX:
            return f"SIGRTMIN+{signum - signal.SIGRTMIN}"
        return f"signal {signum}"


def terminated_status(code) -> bool:
    """True when ``code`` is the exit status of a signal other than Ctrl-C (a shell or batch
    ends too, once its command has stopped)."""
    return isinstance(code, int) and code > 128 and code != 130 and code - 128 in {int(s) for s in STOP_SIGNALS}


class Terminated(KeyboardInterrupt):
    """A signal other than SIGINT (SIGTERM, SIGHUP, ...), raised like Ctrl-C's KeyboardInterrupt;
    ``signum``: which one (exit status 128 + its number: 143 for SIGTERM)."""

    def __init__(self, signum=signal.SIGTERM):
        super().__init__()
        self.signum = signum


def interruption(signum) -> KeyboardInterrupt:
    """What ``signum`` raises: KeyboardInterrupt for Ctrl-C, else :class:`Terminated`."""
    return KeyboardInterrupt() if signum in INTERRUPT_SIGNALS else Terminated(signum)


_state = {"phase": None, "first": None}


def _handler(signum, frame):
    if _state["phase"] == "starting":
        os._exit(status(signum))
    if _state["first"] is not None:
        return                       # a repeat: the first signal is already being handled
    _state["first"] = signum
    raise interruption(signum)


def install() -> None:
    """Handle every signal of :data:`STOP_SIGNALS` from now on (the start-up phase: exit at
    once); one ignored already stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        return
    _state["phase"] = "starting"
    _state["first"] = None
    handle(STOP_SIGNALS, _handler)


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
    """130 for Ctrl-C, 143 for SIGTERM, 128 + N for signal N (``exc``: the KeyboardInterrupt
    raised; the first signal received decides when there was one)."""
    if _state["first"] is not None:
        return status(_state["first"])
    if isinstance(exc, Terminated):
        return status(exc.signum)
    return 130


from ._program import is_program  # noqa: E402,F401 - part of this module's interface


def handle(sigs, handler) -> dict:
    """Install ``handler`` for each of ``sigs`` but those ignored (``nohup``: the convention is
    kept); only the main thread may, elsewhere nothing changes. Returns the handlers replaced,
    for :func:`restore`."""
    old = {}
    if threading.current_thread() is threading.main_thread():
        for s in sigs:
            try:
                if signal.getsignal(s) is signal.SIG_IGN:
                    continue
                old[s] = signal.signal(s, handler)
            except (ValueError, OSError):   # pragma: no cover - embedded interpreters, other platforms
                pass
    return old


def restore(old) -> None:
    """Put back the handlers :func:`handle` replaced."""
    for s, h in old.items():
        signal.signal(s, h)


class held:
    """``with held():`` the signals of :data:`STOP_SIGNALS` wait until the block ends (in the main thread, where
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
    """Turn every signal of :data:`STOP_SIGNALS` into a flag the session loop checks, so it stops between two
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
