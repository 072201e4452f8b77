"""The same bus-truth and safety guarantees on both mightyZAP protocol families: each test runs
over the IR protocol (12Lf) and Modbus RTU (17Lf), through the one Bus API, against the
simulator's ground truth."""

import pytest

from zkzap import BadReply, Bus, NoReply, Permission, PermissionNeeded
from zkzap.sim import start_zap

PROTOCOLS = ["ir", "modbus"]


@pytest.fixture(params=PROTOCOLS)
def rig(request):
    protocol = request.param
    with start_zap(ids=[1, 2], protocol=protocol) as sim:
        with Bus(sim.url, protocol=protocol, timeout=0.03, retries=1) as bus:
            yield sim, bus, protocol


def _truth(sim, ident, name):
    with sim.lock:
        return sim.device.actuator(ident).get(name)


def test_a_read_is_the_simulators_value(rig):
    sim, bus, _ = rig
    with sim.lock:
        sim.device.actuator(2).set("goal-position", 1500)
        sim.device.actuator(2).set("present-position", 1500)
    assert bus.read(2, "present-position") == 1500 == _truth(sim, 2, "present-position")


def test_a_reply_from_another_id_is_never_a_value(rig):
    sim, bus, _ = rig
    with sim.lock:
        sim.device.inject(1, "wrong-id", 2)
    with pytest.raises(BadReply):
        bus.read(1, "goal-speed")


def test_a_corrupt_reply_is_never_a_value_and_a_retry_gets_the_truth(rig):
    sim, bus, _ = rig
    with sim.lock:
        sim.device.inject(1, "corrupt", count=1)
    assert bus.read(1, "goal-speed") == _truth(sim, 1, "goal-speed")
    assert bus.link.retried == 1
    with sim.lock:
        sim.device.inject(1, "corrupt")
    with pytest.raises(BadReply):
        bus.read(1, "goal-speed")


def test_a_cut_reply_is_never_a_value(rig):
    sim, bus, _ = rig
    with sim.lock:
        sim.device.inject(1, "truncate", 2)
    with pytest.raises(BadReply):
        bus.read(1, "goal-speed")


def test_silence_is_no_reply(rig):
    sim, bus, _ = rig
    with sim.lock:
        sim.device.inject(2, "silent")
    with pytest.raises(NoReply):
        bus.read(2, "goal-speed")


def test_a_late_reply_is_not_the_next_requests_answer(rig):
    sim, _, protocol = rig
    with sim.lock:
        sim.device.actuator(1).set("goal-speed", 111)
        sim.device.actuator(2).set("goal-speed", 222)
        sim.device.inject(1, "delay", 250, count=1)      # later than the 100 ms window
    with Bus(sim.url, protocol=protocol, timeout=0.1, retries=0) as bus:
        with pytest.raises(NoReply):
            bus.read(1, "goal-speed")
        assert bus.read(2, "goal-speed") == 222          # never 111, the late reply of ID 1
        bus.link.linger(0.3)                             # the late reply comes, and is accounted for
        assert bus.read(1, "goal-speed") == 111          # then ID 1's own answer is its own


def test_a_stored_write_needs_consent_on_a_real_port_and_sends_nothing(rig):
    sim, bus, _ = rig
    bus.link.simulated = False                           # as on a real port
    before = len(sim.device.received)
    with pytest.raises(PermissionNeeded) as e:
        bus.store(1, "speed-limit", 500)
    assert Permission.STORED & e.value.missing and len(sim.device.received) == before
    bus.store(1, "speed-limit", 500, allow=Permission.STORED)
    assert _truth(sim, 1, "speed-limit") == 500


def test_an_identity_write_needs_force_even_on_the_simulator(rig):
    sim, bus, _ = rig
    with pytest.raises(PermissionNeeded) as e:
        bus.store(1, "id", 9)
    assert Permission.IDENTITY & e.value.missing and _truth(sim, 1, "id") == 1
    assert bus.set_id(1, 9) == 9 and [a.ident for a in sim.device.actuators] == [9, 2]


def test_set_id_refuses_a_taken_id(rig):
    from zkzap import CheckFailed

    sim, bus, _ = rig
    with pytest.raises(CheckFailed, match="already taken"):
        bus.set_id(1, 2)
    assert [a.ident for a in sim.device.actuators] == [1, 2]


def test_a_read_only_register_is_refused_before_sending(rig):
    sim, bus, _ = rig
    before = len(sim.device.received)
    with pytest.raises(ValueError, match="read-only"):
        bus.store(1, "present-position", 5)
    assert len(sim.device.received) == before


def test_scan_names_two_actuators_with_one_id(rig):
    _, bus, protocol = rig
    with start_zap(ids=[4, 4, 6], protocol=protocol) as sim:
        with Bus(sim.url, protocol=protocol) as other:
            found = {r["id"]: r["status"] for r in other.scan(range(1, 9))}
    assert found[6] == "ok" and found[4] in ("garbled", "duplicate")


def test_a_move_waited_for_ends_where_the_rod_stopped(rig):
    """Regression: the final position and "stopped" must belong together (on the 17Lf they are
    two reads: moving first, then the position)."""
    sim, bus, _ = rig
    for goal in (3000, 1200, 2900):
        final = bus.move(1, goal, poll=0)
        assert final == _truth(sim, 1, "present-position") == goal


# -- a stateful model: random reads and writes under random faults, on both protocols ------------

from hypothesis import settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.stateful import RuleBasedStateMachine, initialize, rule  # noqa: E402

from zkzap import DeviceError  # noqa: E402

FAULTS = ["corrupt", "truncate", "wrong-id", "silent", "delay"]
VOLATILE = ["goal-speed", "goal-current"]


def _machine(protocol):
    class BusTruth(RuleBasedStateMachine):
        """Every value a read returns is the simulator's; every write the bus says it made is in
        the simulator; a fault gives an error, never a wrong value."""

        @initialize()
        def start(self):
            self.sim = start_zap(ids=[1, 2], protocol=protocol)
            self.bus = Bus(self.sim.url, protocol=protocol, timeout=0.02, retries=1)

        def teardown(self):
            if hasattr(self, "bus"):
                self.bus.close()
                self.sim.close()

        @rule(ident=st.sampled_from([1, 2]), kind=st.sampled_from(FAULTS), count=st.integers(1, 3))
        def fault(self, ident, kind, count):
            with self.sim.lock:
                self.sim.device.inject(ident, kind, 35 if kind == "delay" else None, count=count)

        @rule(ident=st.sampled_from([1, 2]), name=st.sampled_from(VOLATILE))
        def read(self, ident, name):
            try:
                value = self.bus.read(ident, name)
            except (NoReply, BadReply, DeviceError):
                return
            assert value == _truth(self.sim, ident, name)

        @rule(ident=st.sampled_from([1, 2]), name=st.sampled_from(VOLATILE), value=st.integers(0, 1000))
        def write(self, ident, name, value):
            try:
                self.bus.store(ident, name, value)
            except (NoReply, BadReply, DeviceError):
                return                          # unconfirmed: the value may or may not be there
            if protocol == "modbus":            # acknowledged: it is there
                assert _truth(self.sim, ident, name) == value

    BusTruth.TestCase.settings = settings(max_examples=6, stateful_step_count=12, deadline=None)
    return BusTruth.TestCase


TestBusTruthIr = _machine("ir")
TestBusTruthModbus = _machine("modbus")
