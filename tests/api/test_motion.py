"""Trajectories, stops, teaching and physical units, on the simulator's moving model."""

from __future__ import annotations

import io
import json

import pytest

from zkzap import Bus
from zkzap.api import motion, units
from zkzap.errors import UsageError
from zkzap.sim import start_zap


def rows_of(text, **kw):
    return motion.read_path(io.StringIO(text), name="path.csv", **kw)


#: The motion procedures run over both mightyZAP protocols: the same tests, the protocol a parameter.
PROTOCOLS = pytest.mark.parametrize("protocol", ["ir", "modbus"])
#: The end-compliance-margin of each protocol's simulated actuator (the 12Lf's 7, the 17Lf's map default 8).
MARGIN = {"ir": 7, "modbus": 8}


def on(protocol, ids, **kw):
    """A simulator of ``protocol`` and a Bus on it."""
    sim = start_zap(ids=ids, protocol=protocol, **kw)
    return sim, Bus(sim, protocol=protocol)


# -- reading and planning ----------------------------------------------------------------------

def test_rows_of_one_time_are_one_sync_move():
    rows = rows_of('t,id,position,speed\n0,"1,2",100,500\n0,3,300\n1,1,2000\n')
    p = motion.plan(rows)
    assert [s.t for s in p.steps] == [0, 1]
    first = p.steps[0]
    assert first.goals == {1: 100, 2: 100, 3: 300} and first.speeds == {1: 500, 2: 500}
    # goal-speed first, then one Symmetric Store of every goal
    assert [f[5] for f in first.frames] == [0x73, 0x73] and first.frames[1][6] == 0x86
    assert len(first.frames[1]) == 4 + 1 + 2 + 3 * 3 + 1 + 1


@pytest.mark.parametrize("text,needle", [
    ("t,id,position\n0,1,5000\n", "path.csv:2: position: 5000 is out of range"),
    ("t,id,position\n-1,1,5\n", "path.csv:2: t: -1 is before the start"),
    ("t,id,position\n0,1,5\n0,1,6\n", "ID 1 is given twice at t=0"),
    ("t,id,pos\n0,1,5\n", "unknown field 'pos'"),
    ("t,id,position\n0,300,5\n", "id: '300' is not an actuator ID"),
    ("t,id,position\nnan,1,5\n", "t: nan is not a finite number"),
    ("t,id,position\n0,1,2.5\n", "position: 2.5 is not a whole number of counts"),
    ("t,id,position\n", "no rows"),
    ('[{"t": 0, "id": [1, 1], "position": 3}]', "id: 1 is given twice"),
])
def test_a_bad_row_is_refused_naming_the_line(text, needle):
    with pytest.raises(UsageError, match=needle.replace("(", r"\(")):
        rows_of(text)


def test_json_and_json_lines_read_like_csv():
    a = rows_of('[{"t": 0, "id": [1, 2], "position": 10}, {"t": 0.5, "id": 1, "position": 20, "current": 500}]')
    b = rows_of('{"t": 0, "id": [1, 2], "position": 10}\n{"time": 0.5, "ids": 1, "goal": 20, "current": 500}\n')
    assert [(r.t, r.ids, r.position, r.current) for r in a] == [(r.t, r.ids, r.position, r.current) for r in b]


def test_linear_interpolation_keeps_to_its_rate_and_its_keyframes():
    rows = rows_of("t,id,position\n0,1,0\n1,1,1000\n")
    p = motion.plan(rows, interpolate="linear", rate=10)
    assert [round(s.t, 3) for s in p.steps] == [round(k / 10, 3) for k in range(11)]
    assert [s.goals[1] for s in p.steps] == list(range(0, 1001, 100))
    assert "10 Hz" in p.note and "170 Hz" not in p.note


def test_a_rate_the_line_cannot_carry_is_refused_with_the_rate_it_can():
    rows = rows_of('t,id,position\n0,"1,2,3,4,5,6",0\n1,"1,2,3,4,5,6",4000\n')
    assert motion.max_rate(range(1, 7), 57600) == pytest.approx(0.8 / (27 * 10 / 57600))
    with pytest.raises(UsageError, match=r"170 Hz") as e:
        motion.plan(rows, interpolate="linear", rate=200)
    assert e.value.max_rate == 170
    assert motion.plan(rows, interpolate="linear", rate=170).rate == 170
    # at 9600 baud the same path carries 28 Hz: the default 50 Hz becomes what the line carries
    assert motion.plan(rows, baud=9600, interpolate="linear").rate == 28


def test_steps_closer_than_their_frames_take_are_refused():
    rows = rows_of('t,id,position\n0,"1,2,3,4,5,6",0\n0.002,1,10\n')
    with pytest.raises(UsageError, match="2.0 ms apart.*4.69 ms"):
        motion.plan(rows)


def test_a_modbus_step_is_one_answered_write_per_actuator_and_the_line_counts_the_replies():
    from zkzap.api.motion_wire import ModbusWire

    wire = ModbusWire()
    rows = rows_of('t,id,position,speed,current\n0,"1,2",9000,500,600\n', protocol=wire)
    step = motion.plan(rows, protocol="modbus").steps[0]
    # goal-speed and goal-current (adjacent, 208-209) in one frame per actuator, then each goal-position
    assert [f.hex(" ").upper() for f in step.frames] == [
        "01 10 00 D0 00 02 04 01 F4 02 58 BE 67", "02 10 00 D0 00 02 04 01 F4 02 58 B1 23",
        "01 10 00 CD 00 01 02 23 28 AF 63", "02 10 00 CD 00 01 02 23 28 BB 93"]
    # each frame: the 1.75 ms silence, its 11 bytes and the 8-byte reply at 10 bits a byte, two turnarounds
    per = 0.00175 + 19 * 10 / 57600 + 2 * 0.002
    assert motion.max_rate(range(1, 7), 57600, protocol=wire) == pytest.approx(0.8 / (6 * per))
    with pytest.raises(UsageError, match=r"6 answered frames of 11 bytes.*carries 14 Hz"):
        motion.plan(rows_of('t,id,position\n0,"1,2,3,4,5,6",0\n1,"1,2,3,4,5,6",4000\n', protocol=wire),
                    interpolate="linear", rate=20, protocol=wire)


@pytest.mark.parametrize("text,needle", [
    ("t,id,position\n0,1,10001\n", "position: 10001 is out of range; allowed 0..10000"),
    ("t,id,position\n0,248,5\n", "id: '248' is not an actuator ID 1..247"),
    ("t,id,position\n0,0,5\n", "id: '0' is not an actuator ID 1..247"),
])
def test_a_modbus_path_is_checked_against_the_17lf_map(text, needle):
    from zkzap.api.motion_wire import ModbusWire

    with pytest.raises(UsageError, match=needle):
        rows_of(text, protocol=ModbusWire())
    assert rows_of("t,id,position\n0,1,10000\n", protocol=ModbusWire())[0].position == 10000


def test_a_plan_for_one_protocol_is_refused_on_the_other():
    with start_zap(ids=[1], protocol="modbus") as sim, Bus(sim, protocol="modbus") as bus:
        with pytest.raises(UsageError, match="frames are of the ir protocol"):
            motion.Player(bus, motion.plan(rows_of("t,id,position\n0,1,5\n")))


def test_a_modbus_stop_holds_every_actuator_it_can_and_says_which_it_could_not():
    # ID 3 is not on the bus: its position cannot be read, the others are still held (one write each)
    with start_zap(ids=[1, 2], protocol="modbus", virtual=True) as sim, Bus(sim, protocol="modbus") as bus:
        bus.write(1, {"goal-position": 9000})
        bus.write(2, {"goal-position": 9000})
        held = motion.stop_all(bus, [1, 3, 2])
        assert held[3] is None and held[1] is not None and held[2] is not None
        for i in (1, 2):
            assert sim.device.actuator(i).get("goal-position") == held[i]
        assert "ID 3 force off" in motion.describe_stop(held, "hold")


# -- playing on the simulator ------------------------------------------------------------------

@PROTOCOLS
def test_play_logs_goal_against_present_and_ends_at_the_goals(protocol):
    sim, bus = on(protocol, [1, 2], speed=2)
    with sim, bus:
        rows = []
        player = bus.play(io.StringIO("t,id,position\n0,\"1,2\",1000\n0.3,1,3000\n"), on_row=rows.append)
        assert player.stopped is None and player.sent == 2 and not player.unsettled
        assert {r["id"] for r in rows} == {1, 2}
        moving = [r for r in rows if r["tracking_error"]]
        assert moving and all(r["current_ma"] > 100 for r in moving)          # the model draws current moving
        last = {r["id"]: r for r in rows}
        # the log ends once every rod is within its end-compliance-margin of its goal
        m = MARGIN[protocol]
        assert abs(last[1]["present"] - 3000) <= m and abs(last[2]["present"] - 1000) <= m
        s = player.summary()
        assert s["lateness_p99_ms"] is not None and s["steps"] == 2
        if protocol == "modbus":          # present-voltage has no unit in the 17Lf's map: raw, never a guess
            assert all(r["voltage_v"] is None and r["voltage_raw"] == 120 for r in rows if r["status"] == "ok")
            assert s["frames"] == 3       # one answered write per actuator and goal: 2 at t=0, 1 at t=0.3


@PROTOCOLS
def test_a_current_over_the_limit_stops_every_actuator_where_it_is(protocol):
    sim, bus = on(protocol, [1, 2], speed=2)
    with sim, bus:
        player = bus.play(io.StringIO('t,id,position\n0,"1,2",4000\n'), limit=100)
        assert player.stopped.reason == "current-limit" and "over the limit of 100 mA" in player.stopped.message
        held = player.stopped.positions
        for ident in (1, 2):
            a = sim.device.actuator(ident)
            assert held[ident] is not None and a.get("goal-position") == held[ident] < 4000


@PROTOCOLS
def test_a_hardware_error_stops_every_actuator_force_off_when_asked(protocol):
    # (on Modbus RTU the error bits are the hardware-error register's, read with the log)
    sim, bus = on(protocol, [1, 2], faults=["2:overload"])
    with sim, bus:
        player = bus.play(io.StringIO('t,id,position\n0,"1,2",3000\n'), stop_mode="off")
        assert player.stopped.reason == "device-error" and "overload" in player.stopped.message
        assert sim.device.actuator(1).get("force-on-off") == 0


@PROTOCOLS
def test_loops_repeat_the_path(protocol):
    sim, bus = on(protocol, [1], speed=4)
    with sim, bus:
        player = bus.play(io.StringIO("t,id,position\n0,1,500\n0.2,1,1500\n"), loops=3, log=False)
        assert player.sent == 6 and len(player.lateness) == 6


@PROTOCOLS
def test_taught_waypoints_play_back(protocol):
    sim, bus = on(protocol, [1, 2])
    with sim, bus:
        teacher = motion.Teacher(bus, [1, 2], interval=0.5)
        for pos in (100, 900):
            for i in (1, 2):
                sim.device.actuator(i).set("goal-position", pos + i)     # moved by hand: it stays there
                sim.device.actuator(i).set("present-position", pos + i)
            rows = teacher.take()
        assert rows == [{"t": 0.5, "id": 1, "position": 901, "counts": 901},
                        {"t": 0.5, "id": 2, "position": 902, "counts": 902}]
        buf = io.StringIO()
        motion.write_path(buf, [{"t": 0.0, "id": 1, "position": 101}] + rows)
        back = motion.read_path(io.StringIO(buf.getvalue()), protocol=motion.wire_of(bus))
        assert [(r.t, r.ids, r.position) for r in back] == [(0, (1,), 101), (0.5, (1,), 901), (0.5, (2,), 902)]


# -- units -------------------------------------------------------------------------------------

def test_the_rated_stroke_ends_at_the_factory_long_stroke_limit():
    s = units.Scale(27.0)
    assert s.mm(units.RATED_COUNTS) == 27.0 and s.mm(0) == 0.0
    assert s.counts(13.5) == 1843
    assert units.stroke_of_part("12Lf-20PT-27") == 27.0 and units.stroke_of_part("L12-20PT-6") == 56.0
    with pytest.raises(UsageError, match="not in the model table"):
        units.stroke_of_part("12Lf-20PT-99")
    with pytest.raises(UsageError, match="outside the rod's travel"):
        s.counts(31)
    with pytest.raises(UsageError, match="max_speed_mm_s"):
        s.speed_raw(10)


def test_a_calibration_counts_from_the_retracted_end():
    s = units.Scale(27.0, calibration={"retracted": 100, "extended": 3700, "travel_mm": 27.0}, max_speed_mm_s=40)
    assert s.mm(100) == 0 and s.mm(3700) == 27.0 and s.counts(27.0) == 3700
    assert s.speed_raw(20) == 512 and s.speed_mm_s(1023) == 40


def test_motion_entries_in_the_fleet_file(tmp_path):
    path = str(tmp_path / "fleet.json")
    units.record_motion(path, 1, {"part": "12Lf-20PT-27"})
    units.record_motion(path, 2, {"stroke_mm": 56})
    units.record_motion(path, 2, {"calibration": {"retracted": 0, "extended": 3686, "travel_mm": 56.5}})
    doc = json.load(open(path))
    assert doc["actuators"]["2"]["motion"] == {"stroke_mm": 56, "calibration": {"retracted": 0, "extended": 3686,
                                                                                 "travel_mm": 56.5}}
    sc = units.scales(path, [1, 2])
    assert sc[1].mm(3686) == 27.0 and sc[2].mm(3686) == 56.5
    with pytest.raises(UsageError, match="ID 3 has no motion entry"):
        units.scales(path, [3])
    doc["actuators"]["1"]["motion"]["stroke"] = 3
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(UsageError, match=r"actuators\.1\.motion\.stroke: unknown key"):
        units.scales(str(tmp_path / "bad.json"), [1])


def test_a_path_in_millimetres_plays_in_counts(tmp_path):
    sc = {1: units.Scale(27.0, ident=1), 2: units.Scale(56.0, ident=2)}
    rows = rows_of('t,id,position\n0,"1,2",13.5\n', unit="mm", scales=sc)
    assert sorted((r.ids, r.position) for r in rows) == [((1,), 1843), ((2,), 889)]
    with pytest.raises(UsageError, match="path.csv:2: position: 40 mm is outside"):
        rows_of("t,id,position\n0,1,40\n", unit="mm", scales=sc)


# -- endurance cycles --------------------------------------------------------------------------

@PROTOCOLS
def test_cycles_measure_reach_time_and_current_on_the_moving_model(protocol):
    from zkzap.api.cycle import Cycler
    from zkzap.sim.zap_actuators import FULL_SPEED

    sim, bus = on(protocol, [1], virtual=True)      # model time: the polls' timing is the model's, not the load's
    with sim, bus:
        sim.device.actuator(1).set("goal-position", 500)
        sim.device.actuator(1).set("present-position", 500)
        c = Cycler(bus, 1, 500, 3500, dwell=0.05, cycles=2)
        recs = list(c.run())
        assert c.reason == "done" and [r["cycle"] for r in recs] == [1, 2]
        travel = (3000 - MARGIN[protocol]) / FULL_SPEED     # to within the end-compliance-margin
        for r in recs:
            for key in ("reach_b_s", "reach_a_s"):      # resolution: one poll (~7 ms, more on a loaded machine)
                assert travel <= r[key] <= travel + 0.1, r
            assert r["peak_current_ma"] == 420 and 15 < r["mean_current_ma"] <= 420
            assert r["errors"] == [] and r["status"] == "ok"
            if protocol == "ir":
                assert r["min_voltage_v"] == 12.0
            else:                                       # no unit in the 17Lf's map: the raw value only
                assert r["min_voltage_v"] is None and r["min_voltage_raw"] == 120


@pytest.mark.parametrize("fault,kw,reason", [
    ("stuck", {"stall": 0.2}, "stall"),
    (None, {"limit": 300}, "current-limit"),
    ("overload", {}, "device-error"),
])
@PROTOCOLS
def test_a_cycle_run_stops_the_rod_where_it_is(fault, kw, reason, protocol):
    from zkzap.api.cycle import Cycler

    sim, bus = on(protocol, [1], speed=1 if kw.get("limit") else 4)
    with sim, bus:
        sim.device.actuator(1).set("present-position", 1000)
        sim.device.actuator(1).set("goal-position", 1000)
        if fault:
            sim.inject(1, fault)
        c = Cycler(bus, 1, 1000, 3000, cycles=5, dwell=0.05, **kw)
        recs = list(c.run())
        assert c.reason == reason and recs[-1]["status"] == reason and c.done == 0
        a = sim.device.actuator(1)
        if reason != "device-error":
            assert c.held is not None and a.get("goal-position") == c.held < 3000


def test_the_cycle_state_round_trips(tmp_path):
    from zkzap.api.cycle import CycleState

    path = str(tmp_path / "state.json")
    s = CycleState(path, {k: None for k in CycleState.KEYS}, done=7, output="run.csv")
    s.save()
    back = CycleState.load(path)
    assert back.done == 7 and back.output == "run.csv"
    (tmp_path / "bad.json").write_text('{"format": "zkzap-cycle/1", "params": {}, "done": 1}')
    with pytest.raises(UsageError, match="params: missing"):
        CycleState.load(str(tmp_path / "bad.json"))
    several = CycleState(path, {k: None for k in CycleState.KEYS}, done=2, buses={"left": 3, "right": 2})
    several.save()
    assert CycleState.load(path).buses == {"left": 3, "right": 2} and back.buses is None
    doc = json.load(open(path))
    doc["buses"]["right"] = -1
    (tmp_path / "bad2.json").write_text(json.dumps(doc))
    with pytest.raises(UsageError, match=r"buses\.right: -1 is not a cycle count"):
        CycleState.load(str(tmp_path / "bad2.json"))


@PROTOCOLS
def test_a_cancelled_cycle_run_holds_the_rod_and_says_why(protocol):
    import threading

    from zkzap.api.cycle import Cycler

    sim, bus = on(protocol, [1], speed=4)
    with sim, bus:
        cancel = threading.Event()
        c = Cycler(bus, 1, 500, 3500, cycles=1000, dwell=0.05, cancel=cancel, cancel_why="cancelled from the page")
        recs = []
        for rec in c.run():
            recs.append(rec)
            if len(recs) == 2:
                cancel.set()            # mid-leg of cycle 3: the rod stops where it is
        assert c.reason == "cancelled" and c.why == "cancelled from the page" and c.done == 2
        assert [r["status"] for r in recs] == ["ok", "ok", "cancelled"]
        assert c.held is not None and sim.device.actuator(1).get("goal-position") == c.held


@PROTOCOLS
def test_a_cancelled_play_stops_every_actuator_with_the_words_it_was_given(protocol):
    import threading
    import time

    sim, bus = on(protocol, [1, 2], speed=2)
    with sim, bus:
        cancel = threading.Event()
        rows = motion.read_path(io.StringIO('t,id,position\n0,"1,2",500\n0.5,"1,2",3500\n60,"1,2",500\n'))
        p = motion.plan(rows, baud=bus.baud, protocol=protocol)
        player = motion.Player(bus, p, cancel=cancel, cancel_why="cancelled from the page")
        started = time.monotonic()
        for row in player.rows():
            if row["goal"] == 3500:
                cancel.set()            # between the steps: the stop is now, not at the step due at t=60
        assert time.monotonic() - started < 20
        assert player.stopped.reason == "cancelled" and player.stopped.message == "cancelled from the page"
        assert player.sent == 2 and set(player.stopped.positions) == {1, 2}
        for i in (1, 2):
            assert sim.device.actuator(i).get("goal-position") == player.stopped.positions[i]



def test_a_silent_actuator_never_makes_a_step_late():
    # ID 3 is named by the path but not on the bus: a read of it waits only as long as the next step allows
    with start_zap(ids=[1, 2]) as sim, Bus(sim) as bus:
        rows = motion.read_path(io.StringIO('t,id,position\n0,"1,2,3",500\n0.2,"1,2,3",1500\n0.4,"1,2,3",2500\n'
                                            '0.6,"1,2,3",800\n0.8,"1,2,3",900\n'))
        player = motion.Player(bus, motion.plan(rows, baud=bus.baud), settle=0.3)
        logged = list(player.rows())
        assert any(r["id"] == 3 and r["status"] == "no-reply" for r in logged)
        assert sum(r["status"] == "ok" for r in logged if r["id"] in (1, 2)) >= 10     # the others read all along
        assert player.summary()["lateness_max_ms"] < 50      # unbounded, a read of ID 3 made steps 150-500 ms late


def test_a_play_on_the_simulators_virtual_clock_keeps_its_times_in_no_time():
    # the player's waits are the clock's: on a virtual clock a wait is a jump (it spun forever)
    import time as _time

    from zkzap.link.port import open_port
    from zkzap.link.zap_bus import ZapBus

    bus = ZapBus(open_port("sim://zap?ids=1&clock=virtual", 57600, timeout=0.1))
    plan = motion.plan(motion.read_path(io.StringIO("t,id,position\n0,1,100\n30,1,200\n"), name="path.csv"))
    began = _time.monotonic()
    player = motion.Player(bus, plan, log=False).run()
    assert player.sent == 2 and player.stopped is None
    assert bus.now() >= 30.0 and _time.monotonic() - began < 10
    bus.close()
