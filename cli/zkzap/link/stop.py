"""Stop requests: Ctrl-C, SIGTERM or another signal that ends a command after its current transaction.

Alone, a command takes Ctrl-C as a :class:`KeyboardInterrupt` raised wherever it is. Under
:class:`deferring` (what ``zap batch``, ``zk batch`` and ``zkzap shell`` run their commands in)
the first SIGINT, SIGTERM or other stop signal only *requests* a stop; the transaction entry points —
:meth:`zkzap.link.zap_bus.ZapBus.transact` (one request and its reply or timeout),
:meth:`zkzap.link.zk_port.ZkLink.write` (one control frame) — and the waits between them
(:func:`pause`) call :func:`check`, which raises the interruption there, once: between two
transactions, never in the middle of one. The command then ends as it ends on Ctrl-C when run
alone (a scan reports what it found, a move stops the rod, a ZK session — which watches for
signals itself, between records — sends its abort), and its own clean-up transactions are not
interrupted again. A second signal interrupts at once.

Outside :class:`deferring` every function here is a no-op. Stdlib only.
"""

from __future__ import annotations

import time

from ..signals import STOP_SIGNALS, interruption as _interruption

#: The signals a deferred stop is requested by: every one that ends a program
#: (:data:`zkzap.signals.STOP_SIGNALS`).
SIGNALS = STOP_SIGNALS

#: ``active``: a :class:`deferring` block runs; ``signum``: the first signal received in it;
#: ``taken``: the interruption was raised (or a ZK session took the signal itself).
_state = {"active": 0, "signum": None, "taken": False}

#: The longest sleep of :func:`pause` between two looks at the request (seconds).
PAUSE_SLICE = 0.02


def request(signum) -> None:
    """Ask the running command to stop after its current transaction (the first request
    counts)."""
    if _state["active"] and _state["signum"] is None:
        _state["signum"] = signum


def note(signum) -> None:
    """Record a signal that a ZK session handles itself (it stops between records): the
    request is made and already taken, so no transaction raises it again."""
    if _state["active"] and _state["signum"] is None:
        _state["signum"] = signum
        _state["taken"] = True


def requested():
    """The signal that requested a stop in this block (None: none)."""
    return _state["signum"]


def pending():
    """The requested stop not raised yet (its signal number), else None."""
    return _state["signum"] if not _state["taken"] else None


def take():
    """Take the pending request (its signal number; None: none): it is not raised again."""
    signum = pending()
    if signum is not None:
        _state["taken"] = True
    return signum


def check() -> None:
    """Raise the pending stop request here (KeyboardInterrupt; Terminated for any other signal), once.
    Called before each transaction."""
    if _state["signum"] is not None and not _state["taken"]:
        _state["taken"] = True
        raise _interruption(_state["signum"])


def pause(seconds: float) -> None:
    """``time.sleep(seconds)`` that ends early with :func:`check`'s interruption when a stop is
    requested meanwhile."""
    if not _state["active"]:
        time.sleep(seconds)
        return
    end = time.monotonic() + seconds
    while True:
        check()
        left = end - time.monotonic()
        if left <= 0:
            return
        time.sleep(min(PAUSE_SLICE, left))


class deferring:
    """``with deferring() as d:``: while the block runs, the first stop signal requests a stop
    (see the module) instead of interrupting; a second one interrupts at once (KeyboardInterrupt,
    Terminated for any other signal). ``d.signum`` is the first signal (None: none). Leaving the block
    restores the signal handlers and forgets the request. Only the main thread handles signals:
    elsewhere the block changes nothing."""

    def __init__(self):
        self._old = {}

    @property
    def signum(self):
        return _state["signum"]

    def _handler(self, signum, frame):
        from .. import signals

        if _state["signum"] is not None:
            raise _interruption(signum)
        _state["signum"] = signum
        signals.received(signum)     # the program's own handler, back after the block, ignores repeats

    def __enter__(self):
        from .. import signals

        self._old = signals.handle(SIGNALS, self._handler)
        if self._old:
            _state.update(active=_state["active"] + 1, signum=None, taken=False)
        return self

    def __exit__(self, *exc):
        from .. import signals

        signals.restore(self._old)
        if self._old:
            _state.update(active=_state["active"] - 1, signum=None, taken=False)
        self._old = {}
        return False


__all__ = ["deferring", "request", "note", "requested", "pending", "take", "check", "pause"]
