"""zkzap.Bus and Actuator against the bus simulator (in-process, and over a real pty)."""

from __future__ import annotations

import warnings

import pytest

import zkzap
from zkzap import Bus, GoalClamped, Moved, Permission, Reading
from zkzap.codec import zap
from zkzap.errors import CheckFailed, DeviceError, IdTaken, NoReply, UsageError


@pytest.mark.zap_sim(ids=[1, 2])
def test_registers_by_name_address_and_attribute(zap_sim):
    with Bus(zap_sim) as bus:
        assert bus.load(1, "goal-speed") == 1023
        assert bus.load(1, 0x88) == 1023
        assert bus.load(1, "goal_speed") == 1023
        bus[1].goal_speed = 600
        assert bus[1].goal_speed == 600
        bus[2]["goal-speed"] = 500
        assert bus[2]["goal_speed"] == 500
        assert bus.load(1, "model-number", 3) == {"model-number": bus.load(1, "model-number"),
                                                   "firmware-version": bus.load(1, "firmware-version")}


def test_reading_carries_unit_and_raw(zap_sim):
    with Bus(zap_sim.url) as bus:
        v = bus[1].present_voltage
    assert isinstance(v, Reading) and isinstance(v, float)
    assert v == 12.0 and v.unit == "V" and v.raw == 120
    assert repr(v) == "12.0 V"
    with Bus(zap_sim.url) as bus:
        assert type(bus[1].present_position) is int


def test_unknown_register_attribute(zap_sim):
    with Bus(zap_sim) as bus:
        with pytest.raises(AttributeError, match="no register 'goal_positon'; did you mean goal_position"):
            bus[1].goal_positon  # noqa: B018
        assert "goal_position" in dir(bus[1])


@pytest.mark.zap_sim(ids=[1, 2], speed=20)
def test_move_waits_and_sync_move(zap_sim):
    with Bus(zap_sim) as bus:
        seen = []
        final = bus.move(1, 3000, on_progress=lambda pos, goal, first: seen.append(pos))
        assert abs(final - 3000) <= 5 and seen and seen[-1] == final
        assert bus[1].move(1000) == pytest.approx(1000, abs=5)
        bus.sync_move({1: 2000, 2: 2000})
        assert bus.move(2, 2000) == pytest.approx(2000, abs=5)
        assert bus.move(1, 500, wait=False) is None


def test_move_clamped_goal_is_said_in_the_result_and_a_warning(zap_sim):
    notes = []
    with Bus(zap_sim) as bus:
        with pytest.warns(GoalClamped, match="ID 1: goal 4000 clamped to 3686 by the stroke limits") as w:
            final = bus.move(1, 4000, notify=notes.append, timeout=30)
        assert (w[0].message.ident, w[0].message.requested, w[0].message.goal) == (1, 4000, 3686)
        assert w[0].filename == __file__                     # said at the caller's line
        assert isinstance(final, Moved) and abs(final - 3686) <= 5 and str(final) == str(int(final))
        assert (final.requested, final.goal, final.clamped, final.ident) == (4000, 3686, True, 1)
        assert final.as_dict() == {"id": 1, "requested": 4000, "goal": 3686, "clamped": True,
                                   "position": final.position}
        with warnings.catch_warnings():
            warnings.simplefilter("error")                  # a goal inside the limits warns nothing
            again = bus.move(1, 1000, timeout=30)
        assert not again.clamped and again.goal == again.requested == 1000
    assert notes == []                                      # notify is for interruptions


@pytest.mark.parametrize("stop", [True, False])
def test_move_interrupted_stops_the_rod_where_it_is(zap_sim, stop):
    notes = []

    def ctrl_c(pos, goal, first):
        if pos > first + 50:
            raise KeyboardInterrupt

    with Bus(zap_sim) as bus:
        with pytest.raises(KeyboardInterrupt):
            bus.move(1, 3000, speed=100, on_progress=ctrl_c, notify=notes.append, stop=stop)
        goal = bus[1].goal_position
        if stop:
            assert goal < 3000 and abs(goal - bus[1].present_position) <= 5
            assert notes == [f"interrupted: ID 1 stopped at {goal} (goal-position set to the present position)"]
        else:
            assert goal == 3000 and notes == ["interrupted: ID 1 keeps moving to its goal"]


@pytest.mark.zap_sim(ids=[1, 2, 5])
def test_scan_streams_records(zap_sim):
    probes = []
    with Bus(zap_sim) as bus:
        found = list(bus.scan(range(0, 8), on_probe=lambda b, i, n: probes.append(i)))
    assert [r["id"] for r in found] == [1, 2, 5]
    assert {r["status"] for r in found} == {"ok"} and found[0]["return_mode"] == 1
    assert probes == list(range(8))


def test_dump(zap_sim):
    with Bus(zap_sim) as bus:
        records = bus[1].dump()
    by_name = {r["register"]: r for r in records}
    assert len(records) == len(zap.REGISTERS)
    assert by_name["present-voltage"]["physical"] == 12.0 and by_name["id"]["memory"] == "NV"


@pytest.mark.zap_sim(ids=[1, 2], virtual=True)        # the census's horizon in no time
def test_set_id_verified_and_refused_when_taken(zap_sim):
    with Bus(zap_sim) as bus:
        assert bus.set_id(1, 7) == 7
        assert bus[7].id == 7
        with pytest.raises(CheckFailed, match="ID 2 is already taken") as e:
            bus.set_id(7, 2)
    # a refusal before anything was written: IdTaken, a CheckFailed whose exit status is 2
    assert isinstance(e.value, IdTaken) and e.value.taken and e.value.code == 2


@pytest.mark.zap_sim(virtual=True)                   # the census's horizon in no time
def test_set_baud_switches_the_port(zap_sim):
    with Bus(zap_sim) as bus:
        assert bus.set_baud(1, 115200) == 115200
        assert bus.baud == 115200
        assert bus.load(1, "baud-rate") == zap.BAUD_TO_CODE[115200]


def test_no_reply_carries_facts_not_hints(zap_sim):
    with Bus(zap_sim, retries=1) as bus:
        with pytest.raises(NoReply) as e:
            bus.echo(9)
    err = e.value
    assert (err.ident, err.baud, err.tries, err.code) == (9, 57600, 2, 3)
    assert err.timeout > 0 and "zap scan" not in str(err)


def test_cli_adds_the_hint(cli):
    r = cli("zap", "echo", "--id", "9", "--sim", "--sim-ids", "1", "--retries", "0")
    assert r.exit_code == 3
    assert "check the ID, the baud rate ('zap scan --baud all'), power and wiring" in r.stderr


@pytest.mark.zap_sim(faults=[(1, "overload", None, None)])
def test_device_error_carries_the_reply(zap_sim):
    with Bus(zap_sim) as bus:
        with pytest.raises(DeviceError) as e:
            bus.echo(1)
    assert e.value.errors == ["overload"] and e.value.reply.ident == 1 and e.value.code == 5


def test_protocol_change_refused_without_force(zap_sim):
    with Bus(zap_sim) as bus:
        with pytest.raises(UsageError, match="Modbus RTU") as e:
            bus.store(1, "protocol-type", 0)
        assert e.value.missing == Permission.IDENTITY | Permission.SILENCING


@pytest.mark.zap_sim(return_mode=0)
def test_return_mode_auto(zap_sim):
    with Bus(zap_sim, return_mode="auto") as bus:
        with pytest.raises(UsageError, match="feedback-return-mode 0"):
            bus.load(1, "present-position")
        assert bus.return_mode_of(1) == 0
        assert bus.return_mode == 1            # assumed of the others: each actuator has its own


@pytest.mark.zap_sim(ids=[1, 2])
def test_return_mode_is_each_actuators_own(zap_sim):
    """One actuator told to answer every command changes nothing of how the others are waited
    for: a write to another one is sent once and not waited for."""
    with Bus(zap_sim) as bus:
        bus.store(1, "feedback-return-mode", 2)
        assert (bus.return_mode_of(1), bus.return_mode_of(2), bus.return_mode) == (2, 1, 1)
        sent = bus.link.sent
        bus[2].goal_position = 1000
        assert bus.link.sent == sent + 1 and bus.link.retried == 0
        assert bus.store(1, "led", 2) is not None           # mode 2: acknowledged
        assert bus[2].goal_position == 1000
        zap_sim.device.actuator(2).set("feedback-return-mode", 2)
        assert bus.detect_return_mode(2) == 2 and bus.return_mode_of(1) == 2 and bus.return_mode == 1


@pytest.mark.zap_sim(ids=[1], transport="pty")
def test_over_a_real_pty(zap_sim):
    assert zap_sim.url.startswith("/dev/")
    with Bus(zap_sim) as bus:
        assert bus[1].present_voltage == 12.0
        assert bus.move(1, 100, timeout=30) == pytest.approx(100, abs=5)


def test_lazy_top_level_names():
    assert zkzap.Bus is Bus
    with pytest.raises(AttributeError):
        zkzap.Nothing  # noqa: B018


@pytest.mark.zap_sim(ids=[1, 2], turnaround=25)
def test_latencies_are_learned_per_actuator_and_shared_by_every_bus_on_the_port(zap_sim):
    with Bus(zap_sim.url) as bus:
        for _ in range(3):
            bus.echo(1)
        learned = bus.latencies
        assert learned[1]["samples"] == 3 and learned[1]["latency_ms"] >= 25 and 2 not in learned
    with Bus(zap_sim.url) as again:                   # the same port in this process: what was learned
        assert again.latencies[1]["samples"] == 3
        r = again.echo(2)
        assert r.rtt * 1000 >= 25 and r.latency * 1000 >= 25
        assert again.latencies[2]["samples"] == 1


def test_the_late_window_and_the_latency_hint_from_python():
    from zkzap.sim import start_zap

    with start_zap(ids=[1], turnaround=300) as sim:
        with Bus(sim.url, retries=0, latency=0.3) as bus:                  # a known slow setup
            assert bus.echo(1).rtt >= 0.3
        with Bus(sim.url, retries=0, timeout=0.5) as bus:                  # or a wider window
            assert bus.echo(1).rtt >= 0.3
        with Bus(sim.url, retries=0) as bus:
            # what was learned of the port serves the next Bus on it: an actuator known to answer
            # after the window is waited for as long as it takes
            assert bus.echo(1).rtt >= 0.3
    with start_zap(ids=[1], turnaround=300) as sim:
        with Bus(sim.url, retries=0) as bus:                               # the default window: 150 ms
            with pytest.raises(NoReply) as e:
                bus.echo(1)
            assert e.value.window == pytest.approx(0.15)
