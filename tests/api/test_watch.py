"""api.watch: read planning, the wire limit, polling with faults and --until."""

import pytest

from zkzap.api import expr
from zkzap.api.watch import Watcher, plan_reads, poll_time, until_fields, wire_limit
from zkzap.codec import zap
from zkzap.link.zap_bus import open_bus

R = zap.REGISTER_BY_NAME


@pytest.fixture
def bus():
    b = open_bus("sim://zap?ids=1,2,3", 57600)
    yield b
    b.close()


def test_adjacent_registers_are_one_block_far_ones_are_split():
    reads = plan_reads([R["moving"], R["present-position"], R["present-current"]])
    assert [(a, n, [r.name for r in regs]) for a, n, regs in reads] == [
        (0x8C, 11, ["present-position", "present-current", "moving"])]
    reads = plan_reads([R["model-number"], R["present-position"]])
    assert [(a, n) for a, n, _ in reads] == [(0x00, 2), (0x8C, 2)]
    # a small gap is read through: cheaper than a second transaction
    assert [(a, n) for a, n, _ in plan_reads([R["id"], R["long-stroke-limit"]])] == [(0x03, 7)]


def test_wire_limit_counts_bytes_both_ways_and_turnaround():
    reads = plan_reads([R["present-position"]])
    # Load (9 bytes) + reply (7 + 2) = 18 bytes at 10 bits, plus 2 ms, per ID
    assert poll_time(reads, 57600, 1) == pytest.approx(18 * 10 / 57600 + 0.002)
    assert wire_limit(reads, 57600, 4) == pytest.approx(1 / (4 * (18 * 10 / 57600 + 0.002)))


def test_rows_per_id_and_poll(bus):
    w = Watcher(bus, [1, 2], [R["present-position"], R["present-voltage"]], count=3)
    rows = list(w.rows())
    assert [(r["poll"], r["id"]) for r in rows] == [(1, 1), (1, 2), (2, 1), (2, 2), (3, 1), (3, 2)]
    assert all(r["status"] == "ok" and r["present-voltage"] == 120 and r["errors"] == [] for r in rows)
    assert rows[0]["time"].endswith("Z") and rows[-1]["t"] >= rows[0]["t"]
    # one Load per ID per poll, even for registers 6 bytes apart
    loads = [p for p in bus.port.device.received if p[5] == 0xF2]
    assert len(loads) == 6 and {p[6] for p in loads} == {0x8C}


def test_faults_during_watch_give_rows_and_the_watch_goes_on(bus):
    bus.port.device.inject(2, "silent", count=2)
    bus.port.device.inject(3, "corrupt", count=1)
    w = Watcher(bus, [1, 2, 3], [R["present-position"]], count=4)
    rows = list(w.rows())
    status = {(r["poll"], r["id"]): r["status"] for r in rows}
    assert status[(1, 2)] == status[(2, 2)] == "no-reply" and status[(3, 2)] == "ok"
    assert status[(1, 3)] == "bad-reply" and status[(2, 3)] == "ok"
    failed = next(r for r in rows if r["status"] == "no-reply")
    assert failed["present-position"] is None and failed["rtt_ms"] is None
    assert (w.health[2].asked, w.health[2].answered, w.health[2].failed) == (4, 2, 2)
    assert w.health[1].loss == 0.0


def test_error_bits_are_recorded(bus):
    bus.port.device.inject(1, "overload")
    rows = list(Watcher(bus, [1], [R["present-position"]], count=1).rows())
    assert rows[0]["errors"] == ["overload"] and rows[0]["status"] == "ok"


def test_until_every_id_stops_moving(bus):
    for ident, goal in ((1, 2000), (2, 1000)):
        bus.store(ident, R["goal-position"], goal)
    cond = expr.parse("moving==0", until_fields())
    w = Watcher(bus, [1, 2], [R["present-position"]], until=[cond])
    rows = list(w.rows())
    assert w.stopped_by == "until"
    assert "moving" in rows[0]                 # the condition's register is read too, in the same block
    last = {r["id"]: r for r in rows[-2:]}
    assert last[1]["present-position"] == 2000 and last[2]["present-position"] == 1000
    assert any(r["moving"] == 1 for r in rows)


def test_rate_paces_the_polls(bus):
    w = Watcher(bus, [1], [R["present-position"]], rate=50, duration=0.3)
    rows = list(w.rows())
    assert w.stopped_by == "duration"
    assert 5 <= len(rows) <= 17                # 15 at 50 Hz; generous on a loaded machine


def test_an_actuator_silent_for_most_of_the_watch_is_named(bus):
    w = Watcher(bus, [1, 2], [R["present-position"]], count=10)
    for row in w.rows():
        if (row["poll"], row["id"]) == (1, 2):
            bus.port.device.inject(2, "silent")           # the bus dies after the first poll
    h = w.health[2]
    assert (h.answered, h.failed) == (1, 9) and h.silent_s > 0.5 * w.elapsed
    assert list(w.mostly_silent()) == [2] and w.health[1].silent_s == 0.0
    bus.port.device.clear_faults()
    w = Watcher(bus, [1], [R["present-position"]], count=2)
    bus.port.device.inject(1, "silent", count=1)          # one lost read of two: not most of the watch
    list(w.rows())
    assert w.health[1].failed == 1 and w.mostly_silent() == {}
