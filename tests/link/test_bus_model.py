"""The bus against its model: random buses and operations through the library and the command
line, every answer checked against the simulator's ground truth (tests/busmodel.py), and the
named defects as worked examples. Everything runs on a virtual clock: a window that closes in
silence costs no real time, and a failing example is reproduced by its seed."""

from __future__ import annotations

import os
import sys

import pytest
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, precondition, rule

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import busmodel  # noqa: E402

from zkzap import Bus  # noqa: E402
from zkzap.codec import zap  # noqa: E402
from zkzap.errors import NoReply  # noqa: E402


class BusMachine(RuleBasedStateMachine):
    """A random bus (its seed drawn), then random operations; every step checks its answer."""

    world = None

    @initialize(seed=st.integers(0, 2**31 - 1))
    def bus(self, seed):
        self.world = busmodel.World(seed, faults=busmodel.SUITE_FAULTS)

    def teardown(self):
        if self.world is not None:
            self.world.close()

    def _run(self, op):
        try:
            op()
        except busmodel.Violation as e:
            raise AssertionError(f"reproduce: tests/busmodel.py run({self.world.seed}, ...): {e}") from None

    @precondition(lambda self: self.world is not None)
    @rule(n=st.integers(1, 4))
    def random_steps(self, n):
        for _ in range(n):
            self._run(self.world.step)

    @precondition(lambda self: self.world is not None)
    @rule()
    def load(self):
        self._run(self.world.op_load)

    @precondition(lambda self: self.world is not None)
    @rule()
    def echo(self):
        self._run(self.world.op_echo)

    @precondition(lambda self: self.world is not None)
    @rule()
    def cli_load(self):
        self._run(self.world.cli_load)


BusMachine.TestCase.settings = settings(max_examples=12, stateful_step_count=8, deadline=None,
                                        derandomize=True, suppress_health_check=list(HealthCheck))
test_the_bus_against_its_model = BusMachine.TestCase


# -- the defects, as worked examples (virtual clock: exact and the same on every run) ----------

def virtual(query):
    return f"sim://zap?clock=virtual&{query}"


def test_a_reply_later_than_the_window_is_never_the_next_requests():
    """A 160 ms actuator: every register reads its own value (once 3686, 3686, 0, 1023)."""
    with Bus(virtual("ids=6&faults=6:delay=160")) as bus:
        got = [bus.load(6, name) for name in
               ("long-stroke-limit", "short-stroke-limit", "speed-limit", "current-limit")]
        assert got == [3686, 0, 1023, 800]
        # and its round trip is the true one (once 46 ms on a 200 ms actuator)
    with Bus(virtual("ids=1&faults=1:delay=200")) as bus:
        rtts = [bus.echo(1).rtt for _ in range(5)]
        assert all(r > 0.2 for r in rtts)


@pytest.mark.parametrize("delay", [600, 1000])
def test_a_reply_past_every_window_is_an_error_never_a_value(delay):
    with Bus(virtual(f"ids=6&faults=6:delay={delay}"), retries=0) as bus:
        for name in ("long-stroke-limit", "short-stroke-limit", "speed-limit", "current-limit"):
            try:
                value = bus.load(6, name)
            except NoReply:
                continue
            assert value == zap.REGISTER_BY_NAME[name].default


def test_a_reply_faster_than_the_wire_is_its_requests_own():
    """Behind a link that is not a UART (USB-CDC, a bridge) a reply comes sooner than the wire
    could carry it: it is still the answer, and set-id works (once: 'does not answer after the
    change')."""
    from zkzap.sim import start_zap

    with start_zap(ids=[1], virtual=True, turnaround=0) as sim:
        sim.device.actuator(1).fast = True
        with Bus(sim.url) as bus:
            assert bus.load(1, "model-number") == 0xA112
            assert bus.set_id(1, 5) == 5
            assert bus.load(5, "id") == 5
        assert [a.ident for a in sim.device.actuators] == [5]


@pytest.mark.parametrize("mode", [1, 2])
def test_set_id_with_a_noise_byte_before_the_reply(mode):
    from zkzap.sim import start_zap

    with start_zap(ids=[1], virtual=True, return_mode=mode, faults=["1:noise/1"]) as sim:
        with Bus(sim.url, return_mode=mode) as bus:
            assert bus.set_id(1, 5) == 5
        assert [a.ident for a in sim.device.actuators] == [5]
        stores = [h for h in sim.device.truth or [] if h.packet[5] == zap.STORE_DATA]
        assert len(stores) <= 1


def test_scans_classify_the_same_on_every_run():
    """A reply 160 ms late (past the window): found, identified, the same every run (once left
    out in 1 run of 3)."""
    results = []
    for _ in range(3):
        with Bus(virtual("ids=1,6&faults=6:delay=160")) as bus:
            results.append([(r["id"], r["status"], r["model"]) for r in bus.scan()])
    assert results[0] == results[1] == results[2] == [(1, "ok", 0xA112), (6, "ok", 0xA112)]


def test_an_id_that_gave_more_replies_than_it_was_asked_gives_no_value():
    """Two actuators with ID 3, one answering in 2 ms and one in 200 ms: every value read is the
    first one's own; once more replies came than requests went out (the second's, heard while
    the program paused), every read and Echo of that ID says it is shared, until a census finds
    one actuator there."""
    from zkzap.errors import BadReply
    from zkzap.sim import start_zap

    names = ("long-stroke-limit", "short-stroke-limit", "speed-limit", "current-limit")
    with start_zap(ids=[3, 3], virtual=True) as sim:
        sim.device.actuators[1].own_turnaround = 0.2
        with Bus(sim.url, retries=0) as bus:
            for name in names:
                assert bus.load(3, name) == zap.REGISTER_BY_NAME[name].default
            bus.link.linger(0.3)                  # the program pauses: the second's replies come
            for name in names:
                with pytest.raises(BadReply) as e:
                    bus.load(3, name)
                assert e.value.facts["kind"] == "shared" and e.value.facts["duplicate"]
            with pytest.raises(BadReply):
                bus.echo(3)
            assert bus.link.census([3]) == {3: "shared"}
            sim.device.actuators.pop()            # the second unit taken off the bus
            assert bus.link.census([3]) == {3: "one"}
            assert bus.load(3, "speed-limit") == zap.REGISTER_BY_NAME["speed-limit"].default


def test_the_late_acknowledgement_of_a_write_assumed_unanswered_is_that_writes():
    """An actuator in return mode 2 taking 336 ms, on a bus that assumes mode 1: the
    acknowledgement of a Store comes long after the line was free again; it is that Store's,
    never an Echo's reply (once the census counted it as a second reply: shared)."""
    from zkzap.sim import start_zap

    with start_zap(ids=[4], virtual=True, return_mode=2) as sim:
        sim.device.actuators[0].own_turnaround = 0.336
        with Bus(sim.url, retries=0) as bus:
            bus.store(4, "goal-speed", 512)
            assert bus.link.census([4]) == {4: "one"}


def test_the_simulator_logs_its_ground_truth():
    from zkzap.sim.zap_actuators import from_options

    bus = from_options(ids="1")
    truth = bus.record_truth()
    bus.receive(zap.echo(1), 0.0, 57600)
    assert [(h.ident, h.packet, h.reply) for h in truth] == [(1, zap.echo(1), zap.packet(1, 0))]


# -- what the model once found (random buses, each a seed that reproduced it) -----------------
FOUND = {
    5: "a baud change made two actuators of one ID at a rate the host was not listening at",
    7: "set-id moved two actuators sharing an ID (their replies did not meet) onto another",
    11: "backup read an ID two actuators have, whose replies do not meet, as one's",
    13: "a scan reported return mode 0 for an actuator slower than the window",
    130: "a baud change made two actuators of one ID",
    163: "backup read an ID two actuators have, whose replies do not meet, as one's",
    81: "a scan reported return mode 0 for an actuator in mode 2, 616 ms late",
    99: "a scan found the old ID of an actuator whose ID was changed, by the late acknowledgement of the change",
    251: "a scan found an ID no actuator has",
    321: "an attempt whose window held another ID's garbled reply was not remembered: its reply was the next "
         "request's value",
    339: "a reply sent twice was taken for the retry's reply, and the retry's reply for the next request's",
    416: "a reply sent twice, in one burst, answered the Echo that decides return mode 0",
    424: "the acknowledgement of a slow actuator in another return mode was taken for a later Echo's reply",
    36: "the latency learned of an ID stayed when its actuator moved away: a 290 ms actuator given that ID "
        "later was judged by another's 22 ms, an earlier Echo's reply taken for a later one's, and its "
        "return mode reported 0",
    109: "two actuators share an ID: the slower one's reply to an Echo of a scan was the next Echo's answer",
    131: "two actuators share an ID: a reply to an earlier request was the value of the next Load of that shape",
    140: "two actuators share an ID: the slower one's reply (sent twice) came over the next Echo, which neither "
         "heard, and was its answer",
    274: "two actuators share an ID: a late reply of the second answered the next Echo",
    372: "two actuators share an ID: a late reply of the second was the next Load's value",
    427: "two actuators share an ID: the second's reply to a Load of present-position was goal-speed's value",
    492: "two actuators share an ID: the second's reply to a Load of model-number was a watch's present "
         "position",
    384: "a 336 ms actuator in return mode 2 acknowledged a write assumed unanswered after the write was "
         "forgotten: the acknowledgement answered the census's first Echo, that Echo's reply the second's (5 ms "
         "learned), and a scan reported return mode 0",
    632: "set-baud's census took two actuators with one ID for one: each ask's second reply met the first on "
         "the line, and only bytes that made no packet came after a clean reply",
}


@pytest.mark.parametrize("seed", sorted(FOUND), ids=lambda s: f"seed{s}")
def test_what_the_model_once_found(seed):
    busmodel.run(seed, 200)
