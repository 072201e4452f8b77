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


def test_every_signal_that_ends_a_program_is_handled_and_an_ignored_one_stays_ignored(program):
    signal.signal(signal.SIGHUP, signal.SIG_IGN)                # nohup (the fixture puts it back)
    signals.install()
    assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    for s in signals.STOP_SIGNALS:
        if s != signal.SIGHUP:
            assert signal.getsignal(s) is signals._handler, signals.name(s)
    for s in (signal.SIGKILL, signal.SIGSEGV, signal.SIGPIPE, signal.SIGCHLD):
        assert s not in signals.STOP_SIGNALS


@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1, signal.SIGALRM])
def test_another_signal_raises_terminated_with_its_status(program, sig):
    signals.install()
    signals.running()
    with pytest.raises(signals.Terminated) as e:
        signal.raise_signal(sig)
    assert e.value.signum == sig and signals.first() == sig
    assert signals.exit_status(e.value) == 128 + sig and signals.terminated_status(128 + sig)


def test_signal_names_and_statuses():
    assert signals.status(signal.SIGINT) == 130 and signals.status(signal.SIGTERM) == 143
    assert signals.name(signal.SIGHUP) == "SIGHUP"
    assert not signals.terminated_status(130) and not signals.terminated_status(2)
    if hasattr(signal, "SIGRTMIN"):
        assert signals.name(signal.SIGRTMIN + 2) == "SIGRTMIN+2"
