"""zkzap.link.stop: a signal under ``deferring`` is a stop request, raised between transactions."""

from __future__ import annotations

import signal
import time

import pytest

from zkzap import signals
from zkzap.link import stop
from zkzap.sim import start_zap
from zkzap.link.zap_bus import open_bus


def test_outside_deferring_everything_is_a_no_op():
    stop.request(signal.SIGINT)
    assert stop.requested() is None and stop.pending() is None and stop.take() is None
    stop.check()
    t0 = time.monotonic()
    stop.pause(0.01)
    assert time.monotonic() - t0 >= 0.01


def test_first_signal_requests_check_raises_once_second_interrupts_at_once():
    before = signal.getsignal(signal.SIGINT)
    with stop.deferring() as d:
        signal.raise_signal(signal.SIGINT)           # no exception here: a request
        assert d.signum == signal.SIGINT and stop.pending() == signal.SIGINT
        with pytest.raises(KeyboardInterrupt) as e:
            stop.check()
        assert not isinstance(e.value, signals.Terminated)
        stop.check()                                 # once: the command's clean-up goes on
        assert stop.pending() is None and stop.requested() == signal.SIGINT
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)       # a second one: at once
    assert signal.getsignal(signal.SIGINT) is before
    assert stop.requested() is None                  # forgotten with the block


def test_sigterm_raises_terminated_and_pause_ends_early():
    with stop.deferring():
        signal.raise_signal(signal.SIGTERM)
        t0 = time.monotonic()
        with pytest.raises(signals.Terminated):
            stop.pause(30)
        assert time.monotonic() - t0 < 5


def test_a_session_that_takes_the_signal_itself_is_not_interrupted_again():
    with stop.deferring():
        stop.note(signal.SIGINT)
        assert stop.requested() == signal.SIGINT and stop.pending() is None
        stop.check()


def test_a_bus_transaction_raises_the_request_before_anything_is_written():
    with start_zap(ids=[1]) as sim, open_bus(sim.url) as bus:
        assert bus.ping(1) is not None
        sent = bus.sent
        with stop.deferring():
            stop.request(signal.SIGINT)
            with pytest.raises(KeyboardInterrupt):
                bus.ping(1)
            assert bus.sent == sent                  # nothing on the wire
            assert bus.ping(1) is not None           # taken: the next transactions run
