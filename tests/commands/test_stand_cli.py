"""Test-stand commands in-process against sim://zk: limits on monitor / send --for / profile, zk check,
RPM schedules, per-step averages, the logbook, and every new option's bad input."""

from __future__ import annotations

import csv
import io
import json

import pytest

SIM = "sim://zk?speed=20"


@pytest.fixture
def stand_port():
    """The simulator served over TCP: a real port to the logbook (an engine's hours are counted)."""
    from zkzap.sim import start_zk

    with start_zk(speed=50, transport="tcp") as sim:
        yield sim.url


def jsonl(text):
    return [json.loads(line) for line in text.splitlines() if line.strip()]


# --- limits ------------------------------------------------------------------------------------

def test_send_for_violated_by_the_simulators_egt_aborts_and_exits_5(cli):
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "40", "--for", "20", "-p", SIM, "-f", "jsonl",
            "--limit", "egt_c<=500,warn=400")
    assert r.exit_code == 5, r
    assert "limit violated: sent standby, throttle 0" in r.stderr
    assert "error: limit violated: egt_c=" in r.stderr and "limit warning: egt_c=" in r.stderr
    recs = jsonl(r.stdout)
    trip = next(i for i, rec in enumerate(recs) if rec["kind"] == "trip")
    assert recs[trip - 1]["limit"] == ["egt_c<=500,warn=400"] and recs[trip - 1]["egt_c"] > 500
    assert any(rec.get("warnings") == ["egt_c<=500,warn=400"] for rec in recs)
    assert all("limit" not in rec for rec in recs[:trip - 1])
    assert "limit egt_c<=500,warn=400: VIOLATED first at" in r.stderr
    # the trip is marked, and the rundown after it recorded until the engine is at rest
    assert recs[trip]["limit"] == "egt_c<=500,warn=400" and recs[trip]["field"] == "egt_c"
    assert recs[trip]["t"] == recs[trip - 1]["t"] and "sent standby, throttle 0" in recs[trip]["trip"]
    rundown = [rec for rec in recs[trip + 1:] if rec["kind"] == "status"]
    states = [rec["engine_state_name"] for rec in rundown if rec["id"] == 1]
    assert "cooling" in states and states[-1] == "standby" and rundown[-1]["rpm"] <= 500
    assert recs[-1]["kind"] == "rundown" and recs[-1]["ended"] == "rest"
    assert "rundown recorded:" in r.stderr


def test_monitor_limit_on_an_injected_error_exits_5_without_abort(cli, tmp_path):
    log, summary = tmp_path / "m.csv", tmp_path / "s.json"
    r = cli("zk", "monitor", "-p", SIM + "&error=egt-high&error_after=0.5", "--duration", "5", "-o", str(log),
            "--limit", "error_code==0", "--summary-json", str(summary))
    assert r.exit_code == 5 and "sent" not in r.stderr
    s = json.loads(summary.read_text())
    assert s["command"] == "zk monitor" and s["outcome"] == "limit" and s["exit_status"] == 5
    assert s["limits"][0]["verdict"] == "violated" and s["limits"][0]["extreme"] == 8 and s["aborted"] is None
    rows = list(csv.DictReader(io.StringIO(log.read_text())))
    assert rows[-1]["limit"] == "error_code==0" and rows[-1]["error_code"] == "8"
    assert "warnings" in rows[0] and all(len(row) == len(rows[0]) for row in rows)


def test_on_limit_warn_keeps_going_and_the_summary_names_it(cli, tmp_path):
    summary = tmp_path / "s.json"
    sched = tmp_path / "p.csv"
    sched.write_text("0,0,run\n16,60\n20,0,standby\n24,0,standby\n")       # model seconds
    r = cli("zk", "profile", str(sched), "-p", SIM, "-f", "jsonl", "--ids", "1", "--limit", "egt_c<=550",
            "--limit", "prop_rpm<=10", "--on-limit", "warn", "--summary-json", str(summary))
    # the run went on to its end, and its exit status says a limit was violated: no clean run to a script
    assert r.exit_code == 5, r
    assert "error: limit violated (--on-limit warn: the run went on): egt_c<=550" in r.stderr
    s = json.loads(summary.read_text())
    lim = {x["limit"]: x for x in s["limits"]}
    assert lim["egt_c<=550"]["verdict"] == "violated" and lim["egt_c<=550"]["extreme"] > 550
    assert lim["egt_c<=550"]["first_violation_t"] > 0 and lim["prop_rpm<=10"]["verdict"] == "ok"
    assert s["outcome"] == "duration" and s["exit_status"] == 5 and "limit violated: egt_c=" in r.stderr
    assert "trip" not in r.stdout                                # nothing tripped: the run went on


def test_limits_file_on_profile_aborts(cli, tmp_path):
    lim = tmp_path / "engine.limits"
    lim.write_text("# stand limits\nrpm<=60000\n")
    sched = tmp_path / "p.csv"
    sched.write_text("0,0,run\n20,100\n60,0,standby\n")
    r = cli("zk", "profile", str(sched), "-p", SIM, "-f", "jsonl", "--ids", "2", "--limits", str(lim))
    assert r.exit_code == 5 and "limit violated: sent standby" in r.stderr
    assert "rpm<=60000" in r.stderr


# --- zk check ----------------------------------------------------------------------------------

def test_check_pass_fail_and_silent(cli, pty_port):
    r = cli("zk", "check", "-p", SIM, "--count", "30", "--limit", "power_voltage_v>=7.4", "--limit", "egt_c<=100")
    assert r.exit_code == 0, r
    doc = json.loads(r.stdout)
    assert doc["verdict"] == "pass" and [c["check"] for c in doc["checks"]] == \
        ["power_voltage_v>=7.4", "egt_c<=100", "ECU error code"]
    r = cli("zk", "check", "-p", SIM + "&battery=7.0", "--count", "30", "--limit", "power_voltage_v>=7.4",
            "-f", "csv")
    assert r.exit_code == 5 and "check failed: power_voltage_v>=7.4" in r.stderr
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert rows[0]["verdict"] == "violated" and float(rows[0]["extreme"]) < 7.4
    r = cli("zk", "check", "-p", SIM + "&error=13&error_after=0", "--count", "20")
    assert r.exit_code == 5 and json.loads(r.stdout)["checks"][-1]["verdict"] == "violated"
    r = cli("zk", "check", "-p", SIM + "&protocol_version=4", "--count", "12", "--limit", "prop_rpm<=5")
    assert r.exit_code == 1 and json.loads(r.stdout)["verdict"] == "unchecked"
    path, _ = pty_port
    r = cli("zk", "check", "-p", path, "--timeout", "0.1")
    assert r.exit_code == 3 and r.stdout == ""


# --- RPM schedules, steps, logbook -------------------------------------------------------------

def test_rpm_schedule_reaches_its_target_and_leaves_rpm_mode(cli, tmp_path):
    sched = tmp_path / "rpm.csv"
    sched.write_text("time_s,throttle_pct,rpm,state\n0,0,,run\n18,,100000,\n32,0,,standby\n36,0,,standby\n")
    steps, summary, book = tmp_path / "steps.csv", tmp_path / "s.json", tmp_path / "engine.db"
    r = cli("zk", "profile", str(sched), "-p", SIM, "-f", "jsonl", "--settle", "6", "--steps-csv", str(steps),
            "--summary-json", str(summary), "--logbook", str(book), "--fuel-density", "0.84")
    assert r.exit_code == 0, r
    recs = jsonl(r.stdout)
    scl = [(rec["t"], rec["scl"]) for rec in recs if rec["id"] == 8]
    assert any(v == 1 for _, v in scl) and scl[-1][1] == 0          # RPM mode on, then off again
    rows = list(csv.DictReader(io.StringIO(steps.read_text())))
    assert [row["target"] for row in rows] == ["100000 rpm"]          # the start-up and standby rows are no steps
    assert abs(float(rows[0]["rpm_mean"]) - 100000) < 3000 and float(rows[0]["tsfc_kg_kgf_h"]) > 0
    s = json.loads(summary.read_text())
    assert s["fuel_density_kg_l"] == 0.84 and s["steps"][0]["mode"] == "rpm" and s["starts"] == 1
    assert [(r["line"], r["why"]) for r in s["rows_not_steps"]] == [(2, "start-up")]
    r = cli("zk", "logbook", str(book), "-f", "json")
    doc = json.loads(r.stdout)
    run = doc["runs"][0]
    assert run["command"] == "zk profile" and run["schedule"] == str(sched) and str(steps) in run["files"]
    assert run["max_rpm"] >= 95000 and run["starts"] == 1 and run["running_s"] > 0
    assert doc["totals"]["simulated_runs"] == 1 and doc["totals"]["starts"] == 0     # sim://: no engine's hours


def test_logbook_from_send_and_monitor_and_totals(cli, tmp_path, stand_port):
    book = str(tmp_path / "engine.db")
    cli("zk", "monitor", "-p", stand_port, "--count", "5", "-f", "jsonl", "--logbook", book)
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "6", "-p", stand_port,
            "--yes", "-f", "jsonl", "--logbook", book)
    assert r.exit_code == 0 and "run 2 recorded" in r.stderr
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "20", "-p", SIM, "-f", "jsonl",
            "--logbook", book)
    assert r.exit_code == 0 and "run 3 recorded" in r.stderr
    r = cli("zk", "logbook", book, "-f", "csv")
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert [row["command"] for row in rows] == ["zk monitor", "zk send control", "zk send control"]
    r = cli("zk", "logbook", book, "--totals", "-f", "jsonl")
    tot = jsonl(r.stdout)[0]
    # the run on sim:// is listed, and counted toward no engine's hours, starts or fuel
    assert tot["runs"] == 2 and tot["simulated_runs"] == 1 and tot["starts"] == 1
    sim_run = float(rows[2]["running_s"])
    assert sim_run > 0 and tot["running_s"] == round(float(rows[1]["running_s"]), 1)


@pytest.mark.parametrize("damage,msg", [
    ("UPDATE runs SET errors = '{' WHERE id = 1", "run 1: errors: not a JSON list"),
    ("UPDATE runs SET files = '7' WHERE id = 1", "run 1: files: not a JSON list"),
    ("UPDATE runs SET running_s = 'abc' WHERE id = 1", "run 1: running_s: 'abc' is not a number"),
    ("UPDATE runs SET max_rpm = x'00ff' WHERE id = 1", "run 1: max_rpm: b'\\x00\\xff' is not a number"),
    (None, "database disk image is malformed"),
])
def test_a_damaged_logbook_is_one_line_naming_the_run(cli, tmp_path, damage, msg):
    import sqlite3

    book = tmp_path / "engine.db"
    for _ in range(2):
        assert cli("zk", "monitor", "-p", SIM, "--count", "3", "-f", "jsonl", "--logbook", str(book)).exit_code == 0
    if damage:
        with sqlite3.connect(book) as db:
            db.execute(damage)
        db.close()
    else:
        with sqlite3.connect(book) as db:
            db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        db.close()
        data = book.read_bytes()
        book.write_bytes(data[:len(data) // 2 + 100])
    r = cli("zk", "logbook", str(book))
    assert (r.exit_code, r.stdout) == (2, ""), r
    assert f"logbook: {book}: {msg}" in r.stderr and "Traceback" not in r.stderr


# --- bad input: exit 2, nothing sent, nothing on stdout, no file touched ------------------------

@pytest.mark.parametrize("args,msg", [
    (["monitor", "--sim", "--limit", "egt<=3"], "unknown field 'egt'"),
    (["monitor", "--sim", "--limit", "egt_c<<3"], "'egt_c<<3': '<3' is not a number"),
    (["monitor", "--sim", "--limit", "egt_c~3"], "expected FIELD OP NUMBER"),
    (["monitor", "--sim", "--limit", "egt_c<=inf"], "not a finite number"),
    (["monitor", "--sim", "--limit", "egt_c<=800,warn=900"], "must be below the limit"),
    (["monitor", "--sim", "--limits", "missing.limits"], "limits: cannot read missing.limits"),
    (["monitor", "--sim", "--on-limit", "exit"], "on-limit: give --limit"),
    (["monitor", "--sim", "--limit", "rpm<=1", "--on-limit", "abort"], "does not control the engine"),
    (["monitor", "--sim", "--logbook", "-"], "logbook: a file is needed"),
    (["monitor", "--sim", "--summary-json", "-"], "'-' needs -o FILE"),
    (["monitor", "--sim", "--summary-json", "/nonexistent/s.json"], "no such directory"),
    (["send", "keepalive", "--sim", "--summary-json", "s.json"], "summary-json: applies only with --for"),
    (["send", "keepalive", "--sim", "--limit", "rpm<=1"], "limit: applies only with --for"),
    (["send", "keepalive", "--sim", "--for", "1", "--limit", "rpm<=1", "--on-limit", "abort"],
     "does not control the engine"),
    (["profile", "{s}", "--sim", "--settle", "nan"], "'nan' is not a finite number"),
    (["profile", "{s}", "--sim", "--average", "inf"], "is not a finite number"),
    (["profile", "{s}", "--sim", "--settle", "-inf"], "is not a finite number"),
    (["profile", "{s}", "--sim", "--steps-csv", "x.csv", "--fuel-density", "3"], "fuel-density"),
    (["profile", "{s}", "--sim", "--fuel-density", "0.8"], "applies with --settle"),
    (["profile", "{s}", "--sim", "--steps-csv", "/nonexistent/x.csv"], "no such directory"),
    (["profile", "{s}", "-n", "--limit", "rpm<=1"], "limit: not with -n"),
    (["profile", "{bad}", "--sim"], ":2: throttle_pct: 'nan' is not a finite number"),
    (["check", "--sim", "--duration", "nan"], "'nan' is not a finite number"),
    (["check", "--sim", "--on-limit", "warn", "--limit", "rpm<=1"], "on-limit"),
    (["logbook", "{nodb}"], "not a zkzap logbook"),
    (["logbook", "missing.db"], "no such file"),
    (["report", "{s}"], "give -o REPORT"),
    (["report", "{s}", "-o", "r.txt"], "the suffix '.txt' is not a format this command writes"),
    (["report", "{s}", "--terminal", "-o", "r.png"], "not with --terminal"),
    (["report", "{s}", "-o", "r.png", "--meta", "novalue"], "meta: 'novalue' is not KEY=VALUE"),
    (["profile", "{dup}", "-n"], "dup.csv:3: time_s: 20 is also the time of dup.csv:2"),
    (["profile", "{big}", "-n"], "big.csv:1: time_s: '1e400' is out of range"),
    (["profile", "{s}", "--sim", "--steps-csv", "x.csv", "--fuel-density", "800"],
     "allowed 0.5..1.2 kg/L (800 kg/m³ would be 0.8 kg/L)"),
    (["monitor", "--sim", "--limits", "{empty}"], "limits: empty.limits has no limit"),
    (["monitor", "--sim", "--logbook", "/nonexistent/x.db"], "logbook: cannot open /nonexistent/x.db: no such "
                                                             "directory /nonexistent"),
    (["monitor", "--sim", "--mqtt", "mqtt://localhost/x/#"], "a topic prefix has no wildcards"),
    (["monitor", "--sim", "-o", "run.xyz"], "run.xyz: the suffix '.xyz' is not a format this command writes"),
    (["monitor", "--sim", "-o", "run.png"], "the suffix '.png' (png) is not a format this command writes"),
    (["monitor", "--sim", "-o", "run.xlsx", "--append"], "a workbook cannot be appended to"),
    (["monitor", "--sim", "-f", "xlsx"], "a workbook needs a file"),
    (["report", "{s}", "-o", "{s}.png", "--steps", "{nodb}"], "expected the CSV"),
    (["report", "{nodb}", "-o", "r.png"], "expected the CSV"),
])
def test_bad_input_exit_2(cli, tmp_path, monkeypatch, args, msg):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.csv").write_text("0,0,run\n1,0,standby\n")
    (tmp_path / "bad.csv").write_text("0,0,run\n1,nan\n")
    (tmp_path / "nodb").write_text("hello\n")
    (tmp_path / "dup.csv").write_text("0,0,run\n20,30\n20,60\n30,0,standby\n")
    (tmp_path / "big.csv").write_text("1e400,0,run\n")
    (tmp_path / "empty.limits").write_text("# nothing yet\n\n")
    before = sorted(p.name for p in tmp_path.iterdir())
    subst = {"{s}": "s.csv", "{bad}": "bad.csv", "{nodb}": "nodb", "{s}.png": "s.png", "{dup}": "dup.csv",
             "{big}": "big.csv", "{empty}": "empty.limits"}
    r = cli("zk", *[subst.get(a, a) for a in args])
    assert r.exit_code == 2 and msg in r.stderr and r.stdout == "", r
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_logbook_per_engine_with_hours_above_a_throttle_and_a_service(cli, tmp_path, stand_port):
    import sqlite3

    book = str(tmp_path / "engines.db")
    old = sqlite3.connect(book)                         # a logbook from before engines were named
    from zkzap.api.logbook import SCHEMA

    old.execute(SCHEMA.replace(",\n    engine TEXT,\n    throttle_s TEXT", ""))
    old.close()
    for throttle, engine in ((90, "K100-1"), (50, "K100-2")):
        r = cli("zk", "send", "control", "--state", "run", "--throttle", str(throttle), "--for", "2", "-p",
                stand_port, "--yes", "-f", "jsonl", "--logbook", book, "--engine", engine)
        assert r.exit_code == 0, r
    r = cli("zk", "logbook", book, "--service", "K100-1", "--note", "25 h inspection")
    assert r.exit_code == 0 and "service 1 of K100-1 recorded" in r.stderr
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "60", "--for", "2", "-p", stand_port,
            "--yes", "-f", "jsonl", "--logbook", book, "--engine", "K100-1")
    assert r.exit_code == 0, r
    doc = json.loads(cli("zk", "logbook", book, "--engine", "K100-1", "--above", "80", "--above", "55",
                         "-f", "json").stdout)
    tot, since = doc["totals"], doc["since_service"]
    assert [run["engine"] for run in doc["runs"]] == ["K100-1", "K100-1"] and tot["starts"] == 2
    first, second = doc["runs"]
    assert set(first["throttle_s"]) == {"90"} and set(second["throttle_s"]) == {"60"}
    assert tot["hours_above"]["80"] == round(first["throttle_s"]["90"] / 3600, 4) > 0
    assert tot["hours_above"]["55"] == round((first["throttle_s"]["90"] + second["throttle_s"]["60"]) / 3600, 4)
    assert since["runs"] == 1 and since["hours_above"]["80"] == 0 and doc["last_service"]["note"] == "25 h inspection"
    assert since["fuel_used_l"] == second["fuel_used_l"] and tot["run_hours"] > tot["running_hours"] > 0
    rows = list(csv.DictReader(io.StringIO(cli("zk", "logbook", book, "--engine", "K100-1", "-f", "csv").stdout)))
    assert [row["period"] for row in rows] == ["all runs", f"since the service of {doc['last_service']['at']}"]
    r = cli("zk", "logbook", book, "--engine", "K100-9")
    assert r.exit_code == 2 and "engines there: K100-1, K100-2" in r.stderr


def test_an_unanswered_air_pressure_request_is_said_once(cli):
    r = cli("zk", "monitor", "-p", SIM + "&esr=1", "--duration", "3", "-f", "jsonl")
    assert r.exit_code == 0, r
    assert r.stderr.count("the ECU asks for the air pressure (status ID 8's ESR bit") == 1
    assert "nothing answers it: --air-pressure HPA" in r.stderr
    r = cli("zk", "monitor", "-p", SIM + "&esr=1", "--duration", "3", "-f", "jsonl", "--air-pressure", "1013")
    assert r.exit_code == 0 and "nothing answers it" not in r.stderr and "answering 1013 hPa" in r.stderr


def test_a_limit_on_a_sensors_field_and_on_a_rate(cli, tmp_path):
    aux = tmp_path / "load.txt"
    aux.write_text("load_kg=1.0\nload_kg=2.0\nload_kg=25.0\n")
    r = cli("zk", "monitor", "-p", SIM, "--duration", "2", "-f", "jsonl", "--aux", str(aux), "--limit", "load_kg<=20")
    assert r.exit_code == 5 and "limit violated: load_kg=25" in r.stderr, r
    assert jsonl(r.stdout)[-1]["limit"] == ["load_kg<=20"]
    r = cli("zk", "monitor", "-p", SIM, "--duration", "2", "-f", "jsonl", "--aux", str(aux), "--limit", "thrust<=20")
    assert r.exit_code == 2 and "unknown field 'thrust'" in r.stderr and r.stdout == ""
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "60", "--for", "30", "-p", SIM, "-f", "jsonl",
            "--limit", "egt_c/s<=60", "--limit", "egt_c<=640,when=running")
    assert r.exit_code == 5 and "limit violated: egt_c/s=" in r.stderr and "(egt_c/s<=60)" in r.stderr, r


def test_a_hung_start_ends_the_session_with_the_abort(cli, tmp_path):
    summary = tmp_path / "summary.json"
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "30", "-p", SIM, "-f", "jsonl",
            "--hung-start", "2", "--summary-json", str(summary))
    assert r.exit_code == 5, r
    (alarm,) = json.loads(summary.read_text())["alarms"]          # the run's alarm list, in its summary
    assert alarm["kind"] == "hung-start" and alarm["latched"] and alarm["time"].endswith("Z")
    assert "ALARM: hung start: the ECU has been starting for 2 s" in r.stderr and "sent standby" in r.stderr
    recs = jsonl(r.stdout)
    assert [x["kind"] for x in recs].count("trip") == 1 and recs[-1]["kind"] == "rundown"
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "30", "-p", SIM, "-f", "jsonl",
            "--hung-start", "0", "--hot-start", "0", "--ids", "1")
    assert r.exit_code == 0, r                                   # 0: not watched
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "30", "-p", SIM, "-f", "jsonl",
            "--hung-start", "2", "--ids", "2,3")                  # the watch needs ID 1, the records leave it out
    assert r.exit_code == 5 and "ALARM: hung start" in r.stderr and "sent standby" in r.stderr, r
