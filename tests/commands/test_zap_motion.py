"""zap play, teach and calibrate end to end on the simulator (its moving model: real reach
times and currents), in-process and as real subprocesses."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import pytest

SIX = '"1,2,3,4,5,6"'


def jsonl(text):
    return [json.loads(line) for line in text.splitlines() if line.strip()]


class Proto:
    """One mightyZAP protocol's command line: ``args`` (its --protocol), ``sim(query)`` (a
    simulator URL speaking it), ``margin`` (its simulated actuator's end-compliance-margin)."""

    def __init__(self, name):
        self.name = name
        self.args = ["--protocol", "modbus"] if name == "modbus" else []
        self.margin = 8 if name == "modbus" else 7

    def sim(self, query):
        return "sim://zap?" + ("protocol=modbus&" if self.name == "modbus" else "") + query


@pytest.fixture(params=["ir", "modbus"])
def proto(request):
    """The motion commands' tests run over both protocols (parametrised, not copied)."""
    return Proto(request.param)


@pytest.fixture
def path(tmp_path):
    def make(text, name="path.csv"):
        p = tmp_path / name
        p.write_text(text)
        return str(p)
    return make


def test_dry_run_prints_the_plan_and_its_frames(cli, path):
    r = cli("zap", "play", path(f"t,id,position,speed\n0,{SIX},0,1023\n1,{SIX},3000\n"), "-n")
    assert r.exit_code == 0, r.stderr
    lines = r.stdout.splitlines()
    assert len(lines) == 3 and "goal-speed" in lines[0] and lines[2].lstrip().startswith("1.000")
    assert lines[2].endswith("FF FF FF FE 16 73 86 02 01 B8 0B 02 B8 0B 03 B8 0B 04 B8 0B 05 B8 0B 06 B8 0B 49")
    assert "2 steps, 3 frames" in r.stderr
    r = cli("zap", "play", path(f"t,id,position\n0,{SIX},0\n1,{SIX},3000\n"), "-n", "--interpolate", "linear",
            "-f", "jsonl")
    steps = jsonl(r.stdout)
    assert len(steps) == 51 and steps[25]["goals"]["1"] == 1500 and "interpolating at 50 Hz" in r.stderr


def test_a_rate_the_line_cannot_carry_is_refused_before_anything_is_sent(cli, path, pty_port):
    port, written = pty_port
    r = cli("zap", "play", path(f"t,id,position\n0,{SIX},0\n1,{SIX},3000\n"), "--interpolate", "linear",
            "--rate", "200", "-p", port)
    assert r.exit_code == 2 and r.stdout == "" and written() == b""
    assert "more than the line carries" in r.stderr and "170 Hz" in r.stderr
    r = cli("zap", "play", path("t,id,position\n0,1,0\n0,1,5\n"), "-p", port)
    assert r.exit_code == 2 and "path.csv:3" in r.stderr and written() == b""


def test_play_logs_tracking_to_csv_and_reaches_the_goals(cli, path, tmp_path, proto):
    out = tmp_path / "run.csv"
    # the simulator's actuators at their own speed (not twice it): a loaded machine's late log
    # reads still find them moving, drawing current
    r = cli("zap", "play", path('t,id,position\n0,"1,2",1500\n0.4,2,3000\n'), "-p", proto.sim("ids=1,2&speed=1"),
            "-o", str(out), "--interpolate", "linear", "--rate", "10", *proto.args)
    assert r.exit_code == 0, r.stderr
    import csv

    rows = list(csv.DictReader(open(out)))
    assert rows[0].keys() >= {"t", "id", "goal", "present", "tracking_error", "current_ma", "voltage_v"}
    last = {row["id"]: row for row in rows}
    m = proto.margin
    assert abs(int(last["1"]["present"]) - 1500) <= m and abs(int(last["2"]["present"]) - 3000) <= m
    assert any(int(row["current_ma"]) > 100 for row in rows)
    assert "lateness p50" in r.stderr and "5 of 5 steps" in r.stderr
    if proto.name == "modbus":                 # the raw voltage beside an empty voltage_v (no unit in the map)
        assert rows[0]["voltage_v"] == "" and rows[0]["voltage_raw"] == "120"


def test_play_in_millimetres_shows_counts_beside_mm(cli, path, tmp_path):
    fleet = tmp_path / "fleet.json"
    fleet.write_text(json.dumps({"format": "zkzap-fleet/1", "actuators": {"1": {"motion": {"part": "12Lf-20PT-27"}}}}))
    r = cli("zap", "play", path("t,id,position\n0,1,13.5\n"), "--unit", "mm", "--fleet", str(fleet),
            "-p", "sim://zap?ids=1&speed=4", "-f", "jsonl")
    assert r.exit_code == 0, r.stderr
    last = jsonl(r.stdout)[-1]
    assert last["goal"] == 1843 and last["goal_mm"] == 13.5
    assert abs(last["present"] - 1843) <= 7 and last["present_mm"] == round(last["present"] * 27 / 3686, 3)
    r = cli("zap", "play", path("t,id,position\n0,1,13.5\n"), "--unit", "mm", "-p", "sim://zap?ids=1")
    assert r.exit_code == 2 and "needs --fleet" in r.stderr


def test_a_current_over_the_limit_stops_every_actuator_and_says_so(cli, path, proto):
    r = cli("zap", "play", path('t,id,position\n0,"1,2",4000\n'), "--limit", "200", "-p", proto.sim("ids=1,2"),
            "-f", "jsonl", *proto.args)
    assert r.exit_code == 1, r.stderr
    assert "stopped every actuator" in r.stderr and "over the limit of 200 mA" in r.stderr
    assert "ID 1 held at" in r.stderr and "ID 2 held at" in r.stderr


def test_a_hardware_error_stops_every_actuator(cli, path, proto):
    r = cli("zap", "play", path('t,id,position\n0,"1,2",4000\n'), "-p", proto.sim("ids=1,2&faults=1:overload"),
            "--stop", "off", "-f", "jsonl", *proto.args)
    assert r.exit_code == 5, r.stderr
    assert "overload" in r.stderr and "force off: ID 1, ID 2" in r.stderr


def test_ctrl_c_stops_every_actuator_where_it_is(path, tmp_path, proto):
    from e2e.conftest import clean_env, executable

    p = path('t,id,position\n0,"1,2",0\n0.1,"1,2",4000\n60,"1,2",0\n')
    proc = subprocess.Popen([executable("zap"), "play", p, "-p", proto.sim("ids=1,2"), "-f", "jsonl", *proto.args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=clean_env())
    first = proc.stdout.readline()            # it is playing
    assert first
    time.sleep(0.3)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=20)
    assert proc.returncode == 130, err
    err = err.decode()
    assert "stopped every actuator (interrupted)" in err and "ID 1 held at" in err and "ID 2 held at" in err


def test_teach_records_waypoints_that_play_back(cli, tmp_path, proto):
    out = tmp_path / "taught.csv"
    r = cli("zap", "teach", "--ids", "1,2", "-o", str(out), "-p", proto.sim("ids=1,2"), input="\n\nq\n",
            *proto.args)
    assert r.exit_code == 0, r.stderr
    assert out.read_text() == "t,id,position\n0,1,0\n0,2,0\n1,1,0\n1,2,0\n"
    assert "2 waypoints of 2 actuators written" in r.stderr
    r = cli("zap", "play", str(out), "-n", *proto.args)
    # a sync move of both: one Symmetric Store a step on IR, one write per actuator on Modbus RTU
    assert r.exit_code == 0 and len(r.stdout.splitlines()) == (2 if proto.name == "ir" else 4)
    r = cli("zap", "play", str(out), "-p", proto.sim("ids=1,2&speed=4"), *proto.args, "-f", "jsonl")
    assert r.exit_code == 0 and all(x["present"] == 0 for x in jsonl(r.stdout)), r.stderr
    out2 = tmp_path / "timed.json"
    r = cli("zap", "teach", "--ids", "1", "-o", str(out2), "--rate", "20", "--count", "3", "-p", "sim://zap?ids=1")
    assert r.exit_code == 0, r.stderr
    rows = json.load(open(out2))
    assert [x["id"] for x in rows] == [1, 1, 1] and rows[2]["t"] > rows[1]["t"] > 0


def test_calibrate_records_the_two_ends_and_mm_follow_them(cli, tmp_path, path):
    fleet = tmp_path / "fleet.json"
    r = cli("zap", "calibrate", "--id", "1", "--fleet", str(fleet), "--part", "12Lf-20PT-27", "--retracted", "100",
            "--extended", "3700", "--travel", "27", "--measure-speed", "-p", "sim://zap?ids=1")
    assert r.exit_code == 0, r.stderr
    motion = json.load(open(fleet))["actuators"]["1"]["motion"]
    assert motion["calibration"] == {"retracted": 100, "extended": 3700, "travel_mm": 27}
    assert motion["part"] == "12Lf-20PT-27"
    # the simulator's rod: 10000 counts/s at goal-speed 1023, 3600 counts = 27 mm -> 75 mm/s
    assert motion["max_speed_mm_s"] == pytest.approx(75, rel=0.15)
    r = cli("zap", "play", path("t,id,position,speed\n0,1,0,30\n"), "--unit", "mm", "--fleet", str(fleet), "-n",
            "-f", "jsonl")
    assert r.exit_code == 0, r.stderr
    step = jsonl(r.stdout)[0]
    assert step["goals"] == {"1": 100} and 350 < step["speeds"]["1"] < 480
    r = cli("zap", "calibrate", "--id", "1", "--fleet", str(fleet), "--manual", "-p", "sim://zap?ids=1",
            input="\n\n")
    assert r.exit_code == 1 and "both ends read" in r.stderr
    r = cli("zap", "calibrate", "--id", "2", "--fleet", str(fleet), "--stroke", "27", "-p", "sim://zap?ids=2&speed=8")
    assert r.exit_code == 0, r.stderr
    doc = json.load(open(fleet))["actuators"]
    assert doc["2"]["motion"]["calibration"] == {"retracted": 0, "extended": 3686, "travel_mm": 27.0}
    assert "max_speed_mm_s" in doc["1"]["motion"]                   # the other entry is kept


def test_calibrate_a_17lf_drives_it_to_its_stroke_limits_and_mm_follow(cli, tmp_path, path):
    fleet = tmp_path / "fleet.json"
    sim = "sim://zap?protocol=modbus&ids=1&speed=8"
    r = cli("zap", "calibrate", "--protocol", "modbus", "--id", "1", "--fleet", str(fleet), "--stroke", "30",
            "-p", sim)
    assert r.exit_code == 0, r.stderr
    motion = json.load(open(fleet))["actuators"]["1"]["motion"]
    # the simulated 17Lf's stroke limits are 0 and 10000 (its map's range: no 4095 ceiling)
    assert motion["calibration"] == {"retracted": 0, "extended": 10000, "travel_mm": 30.0}
    r = cli("zap", "play", path("t,id,position\n0,1,15\n"), "--protocol", "modbus", "--unit", "mm", "--fleet",
            str(fleet), "-n", "-f", "jsonl")
    assert r.exit_code == 0 and jsonl(r.stdout)[0]["goals"] == {"1": 5000}, r.stderr
    for args, needle in ((["--id", "1", "--part", "12Lf-20PT-27"], "no 17Lf part's stroke"),
                         (["--id", "248"], "1..247")):
        r = cli("zap", "calibrate", "--protocol", "modbus", "--fleet", str(fleet), "-p", sim, *args)
        assert r.exit_code == 2 and needle in r.stderr, r.stderr
    r = cli("zap", "calibrate", "--id", "1", "--fleet", str(fleet), "--retracted", "5000", "-p", "sim://zap?ids=1")
    assert r.exit_code == 2 and "--retracted" in r.stderr and "4095" in r.stderr     # the 12Lf's range


def test_play_dry_run_on_modbus_names_each_actuator_s_write(cli, path):
    r = cli("zap", "play", path('t,id,position\n0,"1,2",9000\n'), "-n", "--protocol", "modbus")
    assert r.exit_code == 0, r.stderr
    assert r.stdout.splitlines() == ["    0.000  write goal-position=9000 to actuator 1  01 10 00 CD 00 01 02 23 28 AF 63",
                                     "    0.000  write goal-position=9000 to actuator 2  02 10 00 CD 00 01 02 23 28 BB 93"]
    r = cli("zap", "play", path('t,id,position\n0,"1,2",9000\n'), "-n")
    assert r.exit_code == 2 and "out of range; allowed 0..4095" in r.stderr


# -- zap cycle ---------------------------------------------------------------------------------

def test_cycle_resumes_where_it_stopped_and_reports_the_whole_run(cli, tmp_path, proto):
    out, state, report = tmp_path / "wear.csv", tmp_path / "wear.json", tmp_path / "wear.png"
    sim = proto.sim("ids=3&speed=2")    # a poll every ~7 ms (more when loaded): several during each move
    r = cli("zap", "cycle", "--id", "3", "--between", "500", "3500", "--dwell", "0.05", "--cycles", "3",
            "-p", sim, "-o", str(out), "--resume", str(state), *proto.args)
    assert r.exit_code == 0, r.stderr
    assert "3 cycles (1..3)" in r.stderr and "x the wire limit" in r.stderr
    assert json.load(open(state))["done"] == 3
    r = cli("zap", "cycle", "--resume", str(state), "--cycles", "5", "-p", sim, "--report", str(report), *proto.args)
    assert r.exit_code == 0, r.stderr
    assert "resuming the run" in r.stderr and "at cycle 4 of 5" in r.stderr
    assert "resuming the run" in r.stderr and "at cycle 4 of 5" in r.stderr
    import csv

    rows = list(csv.DictReader(open(out)))
    assert [int(x["cycle"]) for x in rows] == [1, 2, 3, 4, 5]
    assert all(float(x["reach_b_s"]) > 0 and int(x["peak_current_ma"]) > 100 for x in rows)
    assert report.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "report written" in r.stderr
    r = cli("zap", "cycle", "--resume", str(state), "-p", sim, *proto.args)
    assert r.exit_code == 2 and "has done its 5 cycles" in r.stderr
    r = cli("zap", "cycle", "--resume", str(state), "--id", "4", "--cycles", "9", "-p", sim, *proto.args)
    assert r.exit_code == 2 and "differs from the run" in r.stderr


def test_cycle_stops_on_a_stall_and_says_where(cli, tmp_path, proto):
    r = cli("zap", "cycle", "--id", "1", "--between", "500", "3500", "--stall", "0.2", "-p",
            proto.sim("ids=1&speed=4&faults=1:stuck"), "-f", "jsonl", *proto.args)
    assert r.exit_code == 1, r.stderr
    rec = jsonl(r.stdout)[-1]
    assert rec["status"] == "stall" and "stalled at 0" in r.stderr and "held at 0" in r.stderr


def test_cycle_in_millimetres_and_the_html_report(cli, tmp_path):
    fleet = tmp_path / "fleet.json"
    fleet.write_text(json.dumps({"format": "zkzap-fleet/1", "actuators": {"1": {"motion": {"stroke_mm": 27}}}}))
    report = tmp_path / "r.html"
    r = cli("zap", "cycle", "--id", "1", "--between", "2", "25", "--unit", "mm", "--fleet", str(fleet), "--dwell",
            "0", "--cycles", "2", "-p", "sim://zap?ids=1&speed=2", "-f", "jsonl", "--report", str(report))
    assert r.exit_code == 0, r.stderr
    recs = jsonl(r.stdout)
    assert len(recs) == 2 and recs[0]["overshoot_b_mm"] == 0.0
    html = report.read_text()
    assert "ID 1 between 2 and 25 mm" in html and "<svg" in html and "reach time to B" in html
    r = cli("zap", "cycle", "--id", "1", "--between", "2.5", "25", "-p", "sim://zap?ids=1")
    assert r.exit_code == 2 and "millimetres need --unit mm" in r.stderr


def test_cycle_of_a_path(cli, path, proto):
    r = cli("zap", "cycle", "--path", path('t,id,position\n0,"1,2",500\n0.2,"1,2",2500\n'), "--cycles", "2",
            "-p", proto.sim("ids=1,2&speed=4"), "-f", "jsonl", *proto.args)
    assert r.exit_code == 0, r.stderr
    recs = jsonl(r.stdout)
    assert [x["cycle"] for x in recs] == [1, 2] and all(x["max_tracking_error"] > 0 for x in recs)


def test_ctrl_c_stops_a_cycle_run_and_it_resumes(tmp_path):
    from e2e.conftest import clean_env, executable

    state, out = tmp_path / "s.json", tmp_path / "c.jsonl"
    proc = subprocess.Popen([executable("zap"), "cycle", "--id", "1", "--between", "500", "3500", "--dwell", "0",
                             "--cycles", "1000", "-p", "sim://zap?ids=1", "--resume", str(state), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=clean_env())
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and not state.exists():      # a cycle done and recorded
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 130, err
    assert b"interrupted; held at" in err and b"resume with --resume" in err
    done = json.load(open(state))["done"]
    assert done >= 1 and [json.loads(x)["cycle"] for x in out.read_text().splitlines()][:done] == \
        list(range(1, done + 1))


def test_move_and_watch_in_millimetres(cli, tmp_path):
    fleet = tmp_path / "fleet.json"
    fleet.write_text(json.dumps({"format": "zkzap-fleet/1", "actuators": {
        "1": {"motion": {"part": "12Lf-20PT-27"}}, "2": {"motion": {"stroke_mm": 56}}}}))
    sim = "sim://zap?ids=1,2&speed=4"
    r = cli("zap", "move", "13.5", "--unit", "mm", "--fleet", str(fleet), "--id", "1", "--wait", "-p", sim)
    assert r.exit_code == 0, r.stderr
    assert abs(float(r.stdout) - 13.5) <= 7 * 27 / 3686          # within the end-compliance-margin
    r = cli("zap", "watch", "present-position", "moving", "--ids", "1,2", "-c", "1", "--unit", "mm", "--fleet",
            str(fleet), "-p", sim)
    assert r.exit_code == 0, r.stderr
    rows = jsonl(r.stdout)
    assert [x["present-position_mm"] for x in rows] == [round(x["present-position"] * s / 3686, 3)
                                                         for x, s in zip(rows, (27, 56))]
    assert "moving_mm" not in rows[0]
    r = cli("zap", "move", "13.5", "--id", "1", "-p", sim)
    assert r.exit_code == 2 and "millimetres need --unit mm" in r.stderr
    r = cli("zap", "move", "40", "--unit", "mm", "--fleet", str(fleet), "--id", "1", "-p", sim)
    assert r.exit_code == 2 and "outside the rod's travel" in r.stderr


def test_a_backup_onto_the_fleet_file_keeps_the_calibration(cli, tmp_path):
    fleet = tmp_path / "fleet.json"
    sim = "sim://zap?ids=1&speed=8"
    r = cli("zap", "calibrate", "--id", "1", "--fleet", str(fleet), "--stroke", "27", "-p", sim)
    assert r.exit_code == 0, r.stderr
    r = cli("zap", "backup", "--ids", "1", "-o", str(fleet), "-p", sim)
    assert r.exit_code == 0, r.stderr
    doc = json.load(open(fleet))["actuators"]["1"]
    assert doc["motion"]["calibration"]["extended"] == 3686 and "stored" in doc
    assert "motion entries of 1 kept" in r.stderr


# -- several buses -----------------------------------------------------------------------------

def _fleet_with_buses(tmp_path, right="sim://zap?ids=1,3&speed=2"):
    fleet = tmp_path / "buses.json"
    fleet.write_text(json.dumps({"format": "zkzap-fleet/1", "actuators": {"1": {}}, "buses": {
        "left": {"port": "sim://zap?ids=1,2&speed=2", "ids": [1, 2]}, "right": {"port": right, "ids": [1, 3]}}}))
    return str(fleet)


def test_play_on_two_buses_each_on_its_thread(cli, tmp_path, path):
    fleet = _fleet_with_buses(tmp_path)
    p = path('t,id,position,bus\n0,"1,2",1000,left\n0,"1,3",2000,right\n0.3,3,500,\n')
    r = cli("zap", "play", p, "--buses", "all", "--fleet", fleet, "-f", "jsonl")
    assert r.exit_code == 0, r.stderr
    rows = jsonl(r.stdout)
    last = {(x["bus"], x["id"]): x for x in rows}
    assert set(last) == {("left", 1), ("left", 2), ("right", 1), ("right", 3)}
    assert abs(last[("right", 3)]["present"] - 500) <= 7 and abs(last[("left", 2)]["present"] - 1000) <= 7
    assert "bus left: 1 of 1 steps" in r.stderr and "bus right: 2 of 2 steps" in r.stderr
    r = cli("zap", "play", path("t,id,position\n0,1,100\n", "amb.csv"), "--buses", "all", "--fleet", fleet)
    assert r.exit_code == 2 and "ID 1 is on buses left, right: give the row's bus" in r.stderr
    r = cli("zap", "play", p, "--buses", "middle", "--fleet", fleet)
    assert r.exit_code == 2 and "no bus 'middle'" in r.stderr


def test_an_error_on_one_bus_stops_every_bus(cli, tmp_path, path):
    fleet = _fleet_with_buses(tmp_path, right="sim://zap?ids=1,3&faults=3:overload")
    p = path('t,id,position,bus\n0,"1,2",3000,left\n0,"1,3",3000,right\n5,"1,2",0,left\n')
    r = cli("zap", "play", p, "--buses", "all", "--fleet", fleet, "-f", "jsonl")
    assert r.exit_code == 5, r.stderr
    assert "bus right: stopped every actuator (ID 3 reports overload)" in r.stderr
    assert "bus left: stopped every actuator (another bus stopped)" in r.stderr


def test_watch_two_buses(cli, tmp_path):
    fleet = _fleet_with_buses(tmp_path)
    r = cli("zap", "watch", "present-position", "--buses", "left,right", "--fleet", fleet, "-c", "2", "-f", "csv")
    assert r.exit_code == 0, r.stderr
    import csv
    import io

    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert sorted({(x["bus"], x["id"]) for x in rows}) == [("left", "1"), ("left", "2"), ("right", "1"),
                                                          ("right", "3")]
    assert len(rows) == 8


def test_scan_every_bus_at_its_baud_rate(cli, tmp_path):
    fleet = tmp_path / "buses.json"
    fleet.write_text(json.dumps({"format": "zkzap-fleet/1", "actuators": {"1": {}}, "buses": {
        "left": {"port": "sim://zap?ids=1,2", "ids": [1, 2]},
        "right": {"port": "sim://zap?ids=1,3&baud=115200", "baud": 115200, "ids": [1, 3, 4]}}}))
    r = cli("zap", "scan", "--buses", "all", "--fleet", str(fleet), "--ids", "0-10", "-f", "jsonl")
    assert r.exit_code == 0, r.stderr
    assert sorted((x["bus"], x["id"], x["baud"]) for x in jsonl(r.stdout)) == [
        ("left", 1, 57600), ("left", 2, 57600), ("right", 1, 115200), ("right", 3, 115200)]
    assert "bus right (sim://zap?ids=1,3&baud=115200): ID 4 of the fleet file did not answer" in r.stderr
    r = cli("zap", "scan", "--buses", "all", "-p", "sim://zap", "--fleet", str(fleet))
    assert r.exit_code == 2 and "not with -p" in r.stderr


# -- several buses by -p given again ----------------------------------------------------------

LEFT, RIGHT = "sim://zap?ids=1,2&speed=4", "sim://zap?ids=1&speed=4"


def test_cycle_on_two_buses_by_their_ports(cli, proto):
    LEFT, RIGHT = proto.sim("ids=1,2&speed=4"), proto.sim("ids=1&speed=4")
    r = cli("zap", "cycle", "--id", "1", "--between", "500", "3000", "--dwell", "0.05", "--cycles", "2",
            "-p", LEFT, "-p", RIGHT, "-f", "jsonl", *proto.args)
    assert r.exit_code == 0, r.stderr
    recs = jsonl(r.stdout)
    assert sorted((x["bus"], x["cycle"]) for x in recs) == sorted([(LEFT, 1), (LEFT, 2), (RIGHT, 1), (RIGHT, 2)])
    assert all(x["status"] == "ok" and x["reach_b_s"] > 0 for x in recs)
    for port in (LEFT, RIGHT):
        assert f"bus {port}: 2 cycles (1..2)" in r.stderr and "x the wire limit" in r.stderr


def test_a_stall_on_one_bus_stops_the_cycle_on_every_bus(cli):
    stuck = "sim://zap?ids=1&speed=4&faults=1:stuck"
    r = cli("zap", "cycle", "--id", "1", "--between", "500", "3000", "--dwell", "0.05", "--cycles", "50",
            "--stall", "0.2", "-p", LEFT, "-p", stuck, "-f", "jsonl")
    assert r.exit_code == 1, r.stderr
    recs = jsonl(r.stdout)
    assert {x["bus"]: x["status"] for x in recs if x["status"] != "ok"} == {stuck: "stall", LEFT: "cancelled"}
    assert f"bus {stuck}: stopped: ID 1 stalled" in r.stderr and f"bus {LEFT}: stopped: another bus stopped" in r.stderr


def test_scan_of_several_buses_takes_one_protocol(cli):
    r = cli("zap", "scan", "--protocol", "auto", "-p", LEFT, "-p", RIGHT)
    assert (r.exit_code, r.stdout) == (2, "") and "--protocol auto: one bus at a time" in r.stderr


def test_a_cycle_run_on_several_buses_resumes_each_bus_and_reports_them_all(cli, tmp_path):
    state, out, report = tmp_path / "s.json", tmp_path / "c.jsonl", tmp_path / "r.html"
    args = ["zap", "cycle", "--id", "1", "--between", "500", "3000", "--dwell", "0", "-p", LEFT, "-p", RIGHT]
    r = cli(*args, "--cycles", "2", "--resume", str(state), "-o", str(out))
    assert r.exit_code == 0, r.stderr
    doc = json.loads(state.read_text())
    assert doc["buses"] == {LEFT: 2, RIGHT: 2} and doc["done"] == 2
    doc["buses"][RIGHT] = 1                  # as if the right bus had been interrupted a cycle earlier
    state.write_text(json.dumps(doc))
    r = cli(*args, "--cycles", "3", "--resume", str(state), "--report", str(report))
    assert r.exit_code == 0, r.stderr
    assert f"bus {LEFT} at cycle 3, bus {RIGHT} at cycle 2 of 3" in r.stderr
    got = sorted((x["bus"], x["cycle"]) for x in jsonl(out.read_text()))
    assert got == sorted([(LEFT, 1), (LEFT, 2), (LEFT, 3), (RIGHT, 1), (RIGHT, 2), (RIGHT, 2), (RIGHT, 3)])
    assert json.loads(state.read_text())["buses"] == {LEFT: 3, RIGHT: 3}
    from html import unescape

    text = unescape(report.read_text())
    assert "on 2 buses" in text and f"{LEFT}: 3 cycles" in text and f"{RIGHT}: 4 cycles" in text
    r = cli("zap", "cycle", "--resume", str(state), "--cycles", "4", "-p", LEFT)       # the run was on two buses
    assert r.exit_code == 2 and "was on 2 buses" in r.stderr
    r = cli("zap", "cycle", "--resume", str(state), "--cycles", "4", "-p", LEFT, "-p", "sim://zap?ids=1&speed=8")
    assert r.exit_code == 2 and "was on buses" in r.stderr
    r = cli("zap", "cycle", "--resume", str(state), "-p", LEFT, "-p", RIGHT)
    assert r.exit_code == 2 and "has done its 3 cycles" in r.stderr


def test_several_ports_refuse_what_is_one_bus_s(cli, tmp_path):
    r = cli("zap", "cycle", "--id", "1", "-p", LEFT, "-p", LEFT)
    assert r.exit_code == 2 and "is given twice" in r.stderr
    r = cli("zap", "watch", "present-position", "--ids", "1", "-p", LEFT, "-p", RIGHT, "--unit", "mm")
    assert r.exit_code == 2 and "--unit mm is for one bus" in r.stderr


def test_play_scan_and_watch_on_two_buses_by_their_ports(cli, path, proto):
    LEFT, RIGHT = proto.sim("ids=1,2&speed=4"), proto.sim("ids=1&speed=4")
    p = path('t,id,position\n0,1,1000\n0.3,1,2000\n')
    r = cli("zap", "play", p, "-p", LEFT, "-p", RIGHT, "-f", "jsonl", *proto.args)
    assert r.exit_code == 0, r.stderr
    last = {x["bus"]: x for x in jsonl(r.stdout)}
    assert set(last) == {LEFT, RIGHT} and all(abs(x["present"] - 2000) <= proto.margin for x in last.values())
    r = cli("zap", "scan", "--ids", "1-3", "-p", LEFT, "-p", RIGHT, "-f", "jsonl", *proto.args)
    assert r.exit_code == 0, r.stderr
    assert sorted((x["bus"], x["id"]) for x in jsonl(r.stdout)) == sorted([(LEFT, 1), (LEFT, 2), (RIGHT, 1)])
    assert "did not answer" not in r.stderr
    r = cli("zap", "watch", "present-position", "--ids", "1", "-c", "2", "-p", LEFT, "-p", RIGHT, "-f", "jsonl",
            *proto.args)
    assert r.exit_code == 0, r.stderr
    assert sorted(x["bus"] for x in jsonl(r.stdout)) == sorted([LEFT, LEFT, RIGHT, RIGHT])


def test_cycle_a_path_on_the_fleet_file_s_buses(cli, tmp_path, path):
    fleet = _fleet_with_buses(tmp_path)
    p = path('t,id,position\n0,1,1000\n0.3,1,2000\n')
    r = cli("zap", "cycle", "--path", p, "--cycles", "2", "--buses", "all", "--fleet", fleet, "-f", "jsonl")
    assert r.exit_code == 0, r.stderr
    recs = jsonl(r.stdout)
    assert sorted((x["bus"], x["cycle"]) for x in recs) == [("left", 1), ("left", 2), ("right", 1), ("right", 2)]
    assert all(x["status"] == "ok" and x["reads"] > 0 for x in recs)
    r = cli("zap", "cycle", "--path", p, "--cycles", "1", "--buses", "all", "--fleet", fleet, "--report",
            str(tmp_path / "r.png"))
    assert r.exit_code == 0 and (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG", r.stderr


def test_a_scan_of_several_buses_says_each_buses_late_actuators_as_a_note(cli):
    slow = "sim://zap?ids=1&faults=1:delay=40&clock=virtual"
    r = cli("zap", "scan", "--ids", "0-2", "-p", slow, "-p", "sim://zap?ids=2&clock=virtual", "-f", "jsonl")
    assert r.exit_code == 0, r.stderr
    assert f"note: bus {slow}: ID 1 at 57600 baud answered after the scan's quick wait" in r.stderr, r.stderr
    assert "warning" not in r.stderr and r.stderr.count("quick wait") == 1
