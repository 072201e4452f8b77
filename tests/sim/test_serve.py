"""The serving loop's wait: with ``precise`` (a simulator in a process of its own), the end of a
wait for a due reply byte polls instead of sleeping, so the byte goes out when it is due, and so
does the time just after a reply, so the host's next request is heard when it comes. Judged
by order, never by how fast a loaded machine is: a wait never ends before its time unless the
host's bytes came, and the host's bytes end it at once."""

from __future__ import annotations

import os
import selectors
import time

import pytest

from zkzap.sim import serve


@pytest.fixture
def line():
    r, w = os.pipe()
    sel = selectors.SelectSelector()
    sel.register(r, selectors.EVENT_READ, "data")
    yield sel, w
    sel.close()
    os.close(r)
    os.close(w)


@pytest.fixture
def calls(line, monkeypatch):
    """The timeouts the wait gives select(2), in order (each call returns at once)."""
    sel, _ = line
    made = []
    real = sel.select
    monkeypatch.setattr(sel, "select", lambda t=None: made.append(t) or real(0))
    return made


@pytest.mark.parametrize("precise", [False, True])
@pytest.mark.parametrize("wait", [0.0002, 0.002])      # within the poll, and a sleep then the poll
def test_a_wait_for_a_due_byte_ends_no_earlier_than_its_time(line, precise, wait):
    sel, _ = line
    t0 = time.monotonic()
    assert serve._select(sel, wait, precise) == []
    assert time.monotonic() - t0 >= wait


@pytest.mark.parametrize("wait", [0.0002, 0.05, serve.IDLE_S])
def test_the_hosts_bytes_end_a_precise_wait(line, wait):
    sel, w = line
    os.write(w, b"\xff")
    events = serve._select(sel, wait, True)
    assert [key.data for key, _ in events] == ["data"]


def test_the_idle_wait_is_a_plain_sleep(line, calls):
    sel, _ = line
    serve._select(sel, serve.IDLE_S, True)           # nothing due: no poll loop
    assert calls == [serve.IDLE_S]
    calls.clear()
    serve._select(sel, 0.01, True)                   # due in 10 ms: a sleep, then polls
    assert calls[0] == pytest.approx(0.01 - serve.SPIN_S) and set(calls[1:]) == {0}


def test_after_a_reply_the_loop_polls_for_the_next_request_then_sleeps(line, calls):
    sel, _ = line
    serve._select(sel, serve.IDLE_S, True, time.monotonic() + serve.LISTEN_S)
    # polls while the host may ask again at once, then the rest of the idle wait as one sleep
    assert len(calls) >= 2 and set(calls[:-1]) == {0}
    assert 0 < calls[-1] <= serve.IDLE_S


def test_a_request_while_listening_ends_the_wait_at_once(line, calls):
    sel, w = line
    os.write(w, b"\xff")
    events = serve._select(sel, serve.IDLE_S, True, time.monotonic() + serve.LISTEN_S)
    assert [key.data for key, _ in events] == ["data"] and calls == [0]


def test_a_listen_past_its_time_changes_nothing(line, calls):
    sel, _ = line
    serve._select(sel, serve.IDLE_S, True, time.monotonic() - 1.0)
    assert calls == [serve.IDLE_S]
