"""zkzap.offload in-process: a lane's writes are made in order off the caller's thread, its
errors come back to the caller, a full queue never holds up a session that controls the engine,
and an output that takes nothing is abandoned at the end instead of waited for."""

from __future__ import annotations

import threading
import time

import pytest

from zkzap import offload
from zkzap.errors import OutputError


@pytest.fixture(autouse=True)
def _forget_abandoned():
    yield
    offload._abandoned.clear()


def test_writes_are_made_in_order_in_another_thread():
    got, threads = [], set()

    def write(x):
        got.append(x)
        threads.add(threading.get_ident())

    lane = offload.Lane("test")
    for i in range(500):
        lane.call(write, i)
    assert lane.finish(lambda: got.append("closed"))
    assert got == [*range(500), "closed"] and threading.get_ident() not in threads


def test_an_error_comes_back_to_the_callers_next_call_and_the_rest_is_dropped():
    done = []

    def write(x):
        if x == 3:
            raise OutputError("disk full")
        done.append(x)

    lane = offload.Lane("test")
    for i in range(5):
        lane.call(write, i)
    assert lane.drain()
    with pytest.raises(OutputError, match="disk full"):
        lane.call(write, 9)
    with pytest.raises(OutputError):
        lane.check()
    assert done == [0, 1, 2]


def _blocked_lane(limit, **kw):
    release = threading.Event()
    lane = offload.Lane("stuck", limit=limit, **kw)
    lane.call(release.wait)                       # in progress: never returns until released
    time.sleep(0.05)
    return lane, release


def test_a_full_queue_raises_at_once_while_the_engine_is_controlled():
    lane, release = _blocked_lane(3)
    try:
        for _ in range(3):
            lane.call(time.sleep, 0)
        with offload.urgent():
            t = time.monotonic()
            with pytest.raises(offload.Stalled, match="stuck: stalled: .* 4 writes waited") as e:
                lane.call(time.sleep, 0)
            assert time.monotonic() - t < 0.05 and e.value.code == 7 and e.value.pending == 4
    finally:
        release.set()


def test_a_full_queue_waits_for_room_otherwise():
    lane, release = _blocked_lane(2)
    for _ in range(2):
        lane.call(time.sleep, 0)
    threading.Timer(0.2, release.set).start()
    t = time.monotonic()
    lane.call(time.sleep, 0)                      # waits until the output takes again
    assert time.monotonic() - t >= 0.15
    assert lane.finish()


def test_a_full_queue_drops_and_counts_once_a_stop_is_requested(monkeypatch):
    lane, release = _blocked_lane(1)
    try:
        lane.call(time.sleep, 0)
        monkeypatch.setattr(offload, "_stopping", lambda: True)
        t = time.monotonic()
        lane.call(time.sleep, 0)                  # no room, a signal came: not waited for
        assert time.monotonic() - t < 0.05 and lane.dropped == 1 and lane.pending == 3
    finally:
        release.set()


def test_a_stalled_output_is_abandoned_and_a_slow_one_waited_for():
    lane, release = _blocked_lane(10)
    try:
        lane.call(time.sleep, 0)
        t = time.monotonic()
        assert not lane.finish(timeout=0.2)
        assert 0.2 <= time.monotonic() - t < 1.0
        assert offload.abandoned() == [lane] and "2 writes not made" in lane.lost()
        assert not lane.finish()                  # given up on: no second wait
    finally:
        release.set()
    slow = offload.Lane("slow")
    for _ in range(8):
        slow.call(time.sleep, 0.05)               # 0.4 s in all, each well within the timeout
    assert slow.finish(timeout=0.2)


def test_a_proxy_offloads_only_the_methods_named():
    class Out:
        def __init__(self):
            self.got = []
            self.name = "x"

        def write(self, b):
            self.got.append(b)

    out = Out()
    lane = offload.Lane("proxy")
    p = offload.Proxy(out, lane, ("write",))
    p.write(b"a")
    assert p.name == "x"
    assert lane.finish() and out.got == [b"a"]
