"""The signal module in-process: a library user's process is left alone; the phases of a program."""

from __future__ import annotations

import signal

import pytest

from zkzap import signals


@pytest.fixture
def program(monkeypatch):
    """The module's state as in a program, restored (with the handlers) afterwards."""
    old = {s: signal.getsignal(s) for s in signals.SIGNALS}
    monkeypatch.setattr(signals, "_state", {"phase": None, "first": None})
    yield
    for s, h in old.items():
        signal.signal(s, h)


def test_importing_zkzap_installs_nothing():
    assert not signals.is_program()            # pytest, not zk/zap/zkzap
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler or not signals.installed()


def test_running_phase_raises_and_counts_only_the_first(program):
    signals.install()
    signals.running()
    with pytest.raises(signals.Terminated):
        signal.raise_signal(signal.SIGTERM)
    assert signals.first() == signal.SIGTERM
    signal.raise_signal(signal.SIGTERM)        # a repeat: ignored
    signal.raise_signal(signal.SIGINT)         # another kind after the first: ignored too
    assert signals.exit_status(KeyboardInterrupt()) == 143


def test_exit_status(program):
    assert signals.exit_status(KeyboardInterrupt()) == 130
    assert signals.exit_status(signals.Terminated()) == 143
    signals.received(signal.SIGTERM)            # not a program: nothing recorded
    assert signals.first() is None and signals.exit_status(KeyboardInterrupt()) == 130
