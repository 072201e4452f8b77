"""zk send on the wire, zk monitor and zk profile in-process (CliRunner) against sim:// and ptys."""

import csv
import io
import json

import pytest

from zkzap.codec import zk

SIM = "sim://zk?speed=20"


def jsonl(text):
    return [json.loads(line) for line in text.splitlines()]


# --- zk monitor ----------------------------------------------------------------------------------

def test_monitor_jsonl_records(cli):
    r = cli("zk", "monitor", "-p", SIM, "--count", "30")
    assert r.exit_code == 0, r
    recs = jsonl(r.stdout)
    assert len(recs) == 30 and r.stderr == ""
    assert set(recs[0]) >= {"time", "t", "kind", "id", "rpm", "frame", "stale", "stale_ids"}
    assert [x["id"] for x in recs[:10]] == list(range(1, 11))
    assert recs[5]["protocol_version"] == 6


def test_monitor_csv_snapshot_rows_with_ids_and_append(cli, tmp_path):
    out = tmp_path / "log.csv"
    r = cli("zk", "monitor", "-p", SIM, "--count", "6", "--ids", "1,6", "-o", str(out))
    assert r.exit_code == 0, r
    r = cli("zk", "monitor", "-p", SIM, "--count", "4", "--ids", "1,6", "-o", str(out), "--append")
    assert r.exit_code == 0 and r.stdout == ""
    rows = list(csv.reader(io.StringIO(out.read_text())))
    assert rows[0][:4] == ["time", "t", "id", "rpm"] and rows[0][-2:] == ["stale", "stale_ids"]
    assert "pump_voltage_v" not in rows[0] and "max_rpm" in rows[0]
    assert len(rows) == 11 and all(len(row) == len(rows[0]) for row in rows)   # one header only
    assert [row[2] for row in rows[1:]] == ["1", "6"] * 5
    last = dict(zip(rows[0], rows[-1]))
    assert last["engine_state_name"] == "stop" and last["max_rpm"] == "160000"   # every field, latest value


def test_monitor_frames_csv_and_json_array(cli):
    r = cli("zk", "monitor", "-p", SIM, "--count", "3", "-f", "csv", "--frames")
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert len(rows) == 3 and rows[0]["frame"].startswith("F1") and rows[0]["kind"] == "status"
    r = cli("zk", "monitor", "-p", SIM, "--count", "3", "-f", "json")
    assert [x["id"] for x in json.loads(r.stdout)] == [1, 2, 3]


def test_monitor_raw_log_and_replay(cli, tmp_path):
    raw = tmp_path / "run.bin"
    r = cli("zk", "monitor", "-p", SIM + "&corrupt_every=9", "--count", "40", "--raw-log", str(raw))
    assert r.exit_code == 0, r
    live = jsonl(r.stdout)
    r2 = cli("zk", "monitor", "--replay", str(raw), "--fast", "--count", "40")
    assert r2.exit_code == 0, r2
    replay = jsonl(r2.stdout)

    def strip(recs):
        return [{k: v for k, v in x.items() if k not in ("time", "t", "stale", "stale_ids")} for x in recs]

    assert strip(replay) == strip(live)
    assert "with a bad CRC skipped" in r2.stderr


def test_monitor_fail_on_error(cli):
    r = cli("zk", "monitor", "-p", SIM + "&error=pump-failure&error_after=0.5", "--count", "15",
            "--fail-on-error", "--ids", "1")
    assert r.exit_code == 5
    recs = jsonl(r.stdout)
    assert len(recs) == 15 and recs[-1]["error_name"] == "pump-failure"
    assert "ECU error 4 (pump-failure: " in r.stderr
    r = cli("zk", "monitor", "-p", SIM, "--count", "12", "--fail-on-error")
    assert r.exit_code == 0


def test_monitor_silent_ecu_exits_3(cli, pty_port):
    path, _ = pty_port
    r = cli("zk", "monitor", "-p", path, "--timeout", "0.1")              # nobody answers: no frame to miss
    assert r.exit_code == 3 and r.stdout == ""
    assert f"no status frame from the ECU on {path} within 0.1 s" in r.stderr
    r = cli("zk", "monitor", "-p", SIM + "&silent_after=1", "--timeout", "0.3", "-f", "csv")
    assert r.exit_code == 3 and "fell silent" in r.stderr
    assert len(r.stdout.splitlines()) == 21                      # header + the frames that came


def test_monitor_keepalive(cli, pty_port):
    path, written = pty_port
    r = cli("zk", "monitor", "-p", path, "--keepalive", "--rate", "50", "--timeout", "0.3")
    assert r.exit_code == 3
    data = written()
    assert 5 <= len(data) // 4 <= 20 and data[:4] == bytes.fromhex("FF000000")


def test_monitor_duration_and_version_note(cli):
    # an in-process simulator's speed applies to the session: 6 s of model time at 20 Hz
    r = cli("zk", "monitor", "-p", SIM, "--duration", "6", "-f", "jsonl")
    recs = jsonl(r.stdout)
    # (one read can bring a burst: at speed 20 a 50 ms stall of a loaded machine is 1 s of frames)
    assert r.exit_code == 0 and 110 <= len(recs) <= 200
    assert 5.0 <= recs[-1]["t"] <= 9.0            # model seconds (6 s of it), not 6 real seconds (120)


@pytest.mark.parametrize("args,msg", [
    ([], "no port: give -p PORT"),
    (["-p", SIM, "--sim"], "not both"),
    (["--replay", "x.bin", "-p", SIM], "not both"),
    (["--replay", "missing.bin"], "replay: cannot read missing.bin"),
    (["-p", SIM, "--fast"], "fast: only with --replay"),
    (["-p", SIM, "--ids", "0"], "ids: 0 is out of range; allowed status IDs 1..14"),
    (["-p", SIM, "--rate", "50"], "rate: applies only with --keepalive"),
    (["-p", SIM, "--count", "0"], "0 is out of range; allowed 1 or more"),
])
def test_monitor_usage_errors(cli, args, msg):
    r = cli("zk", "monitor", *args)
    assert r.exit_code == 2 and msg in r.stderr and r.stdout == ""


def test_monitor_bad_port_is_exit_4(cli):
    r = cli("zk", "monitor", "-p", "/dev/does-not-exist-zk")
    assert r.exit_code == 4 and "cannot open" in r.stderr


# --- zk send -----------------------------------------------------------------------------------

def test_send_once_waits_for_a_status_frame(cli):
    r = cli("zk", "send", "control", "--state", "stop", "-p", SIM)
    assert r.exit_code == 0 and r.stdout == "" and r.stderr == ""


def test_send_needs_consent_on_a_real_port_and_writes_nothing(cli, pty_port):
    path, written = pty_port
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "-p", path)
    assert r.exit_code == 2 and "state run can start the engine; pass --yes to confirm" in r.stderr
    assert written() == b""
    r = cli("zk", "send", "action", "drain-oil", "-p", path, "--for", "1")
    assert r.exit_code == 2 and "drain-oil" in r.stderr and written() == b""
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "-p", path, "--yes", "--no-wait")
    assert r.exit_code == 0 and written() == bytes.fromhex("FF1D2CE5")
    r = cli("zk", "send", "control", "--state", "stop", "-p", path, "--timeout", "0.1")
    assert r.exit_code == 3 and "no status frame came back" in r.stderr
    assert written() == zk.encode_control("control", sw="stop")[0]   # harmless: no consent needed


def test_send_for_drives_and_logs(cli):
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "-p", SIM, "--for", "24",
            "--ids", "1", "-f", "jsonl")
    assert r.exit_code == 0, r
    names = []
    for rec in jsonl(r.stdout):
        if not names or names[-1] != rec["engine_state_name"]:
            names.append(rec["engine_state_name"])
    assert names == ["stop", "ignition", "preheat", "fuel-ramp", "running"]


def test_send_for_ecu_error_aborts_with_exit_5(cli):
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "-p",
            SIM + "&error=egt-high&error_after=14", "--for", "20", "--ids", "1", "-f", "csv", "--abort", "stop")
    assert r.exit_code == 5
    assert "ECU error 8 (egt-high: Exhaust temperature is high)" in r.stderr
    assert "ECU error: sent stop, throttle 0" in r.stderr
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    # the frame of the error, then the trip record marking it, then the rundown to the end
    tripped = next(i for i, row in enumerate(rows) if row["trip"])
    assert rows[tripped - 1]["error_code"] == "8"
    assert rows[tripped]["trip"].startswith("ECU error 8 (egt-high") and "sent stop" in rows[tripped]["trip"]
    assert rows[-1]["trip"].startswith("rundown ")


def test_send_for_harmless_command_keeps_going_through_errors(cli):
    # not stopped by the error (a keep-alive controls nothing), but the error is the exit status
    r = cli("zk", "send", "keepalive", "-p", SIM + "&error=3&error_after=0.3", "--for", "10", "-f", "jsonl")
    assert r.exit_code == 5 and "ECU error 3 (glowplug-failure: Glowplug failure) at t=" in r.stderr
    # it went on long past the error at 0.3 s (the last frame's time, not the run's end: on a
    # loaded machine the sped-up simulator's last frames before 10 s may not be read in time)
    assert jsonl(r.stdout)[-1]["t"] > 5


@pytest.mark.parametrize("args,msg", [
    (["control", "--state", "run", "-n", "--for", "3"], "for: not with -n"),
    (["control", "--state", "stop", "-p", SIM, "--rate", "50"], "rate: applies only with --for"),
    (["control", "--state", "stop", "-p", SIM, "-o", "x.csv"], "output: applies only with --for"),
    (["control", "--state", "stop", "-p", SIM, "--for", "1", "--no-wait"], "no-wait: not with --for"),
    (["control", "--state", "stop", "--for", "1"], "no port"),
    (["control", "--state", "stop", "-p", SIM, "--for", "1", "--ids", "99"], "ids: 99 is out of range"),
    (["raw", "1", "sw=3", "-p", SIM, "--for", "-1"], "-1"),
])
def test_send_usage_errors(cli, args, msg):
    r = cli("zk", "send", *args)
    assert r.exit_code == 2 and msg in r.stderr and r.stdout == ""


# --- zk profile ----------------------------------------------------------------------------------

def test_profile_example_and_plan(cli, tmp_path):
    r = cli("zk", "profile", "--example")
    assert r.exit_code == 0 and "time_s,throttle_pct,state" in r.stdout
    path = tmp_path / "ex.csv"
    path.write_text(r.stdout)
    r = cli("zk", "profile", str(path), "-n", "-f", "csv")
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert rows[0] == {"t": "0.0", "state": "run", "throttle_pct": "0.0", "frame": "FF 1C 00 A1"}
    assert rows[-1]["state"] == "standby" and len(rows) == 7


def test_profile_runs_logs_and_summarises(cli, tmp_path):
    sched = tmp_path / "s.csv"
    sched.write_text("0,0,run\n14,40\n20,0,standby\n24,0,standby\n")
    log, summary = tmp_path / "tel.csv", tmp_path / "sum.json"
    r = cli("zk", "profile", str(sched), "-p", SIM, "-o", str(log), "--summary-json", str(summary))
    assert r.exit_code == 0, r
    s = json.loads(summary.read_text())
    assert s["outcome"] == "duration" and s["exit_status"] == 0 and s["aborted"] is None
    assert s["states"][:5] == ["stop", "ignition", "preheat", "fuel-ramp", "running"]
    assert "cooling" in s["states"] and s["max_rpm"] > 80000 and s["max_egt_c"] > 500
    assert s["errors"] == [] and s["frames"] > 400
    assert "max rpm" in r.stderr and "states: stop > ignition" in r.stderr
    rows = list(csv.reader(io.StringIO(log.read_text())))
    assert all(len(row) == len(rows[0]) for row in rows) and len(rows) == s["records"] + 1


def test_profile_ending_in_run_gets_the_abort(cli, tmp_path):
    sched = tmp_path / "s.csv"
    sched.write_text("time_s,throttle_pct\n0,10\n0.5,20\n")
    r = cli("zk", "profile", str(sched), "-p", SIM, "-f", "jsonl", "--ids", "1")
    assert r.exit_code == 0
    assert "end of schedule: sent standby, throttle 0" in r.stderr


def test_profile_ecu_error_exit_5(cli, tmp_path):
    sched = tmp_path / "s.csv"
    sched.write_text("0,30,run\n20,30\n")
    r = cli("zk", "profile", str(sched), "-p", SIM + "&error=egt-high&error_after=14", "-f", "csv",
            "--summary-json", "-")
    assert r.exit_code == 5
    assert "errors: ECU error 8 (egt-high: " in r.stderr and "ECU error, sent standby" in r.stderr


@pytest.mark.parametrize("args,msg", [
    ([], "schedule: give SCHEDULE.csv"),
    (["x.csv", "--example"], "give no SCHEDULE"),
    (["missing.csv", "--sim"], "schedule: cannot read missing.csv"),
])
def test_profile_usage_errors(cli, args, msg):
    r = cli("zk", "profile", *args)
    assert r.exit_code == 2 and msg in r.stderr


def test_profile_bad_row_and_consent(cli, tmp_path, pty_port):
    path, written = pty_port
    sched = tmp_path / "s.csv"
    sched.write_text("0,30,run\n5,130\n")
    r = cli("zk", "profile", str(sched), "-p", path, "--yes")
    assert r.exit_code == 2 and f"{sched}:2: throttle: 130 is out of range; allowed 0..100 %" in r.stderr
    sched.write_text("0,30,run\n5,0,standby\n")
    r = cli("zk", "profile", str(sched), "-p", path)
    assert r.exit_code == 2 and "state run can start the engine" in r.stderr
    assert written() == b""


# --- port from the environment, terminal view ----------------------------------------------------

def test_sim_and_replay_beat_the_environment_port(cli, monkeypatch, tmp_path):
    monkeypatch.setenv("ZKZAP_ZK_PORT", "/dev/does-not-exist-zk")
    r = cli("zk", "monitor", "--sim", "--count", "2", "--ids", "1")
    assert r.exit_code == 0 and len(jsonl(r.stdout)) == 2
    raw = tmp_path / "r.bin"
    from zkzap.sim.zk_ecu import ZkEcu

    raw.write_bytes(ZkEcu().poll(0.99))
    r = cli("zk", "monitor", "--replay", str(raw), "--fast")
    assert r.exit_code == 0 and len(jsonl(r.stdout)) == 20
    r = cli("zk", "monitor", "--count", "1")
    assert r.exit_code == 4 and "/dev/does-not-exist-zk" in r.stderr


class FakeDashboard:
    made = []

    def __init__(self, stream, title):
        self.title, self.updates, self.notes, self.entered = title, [], [], False
        FakeDashboard.made.append(self)

    def __enter__(self):
        self.entered = True
        return self

    def __exit__(self, *exc):
        self.entered = False
        return False

    def update(self, snapshot, health):
        self.updates.append((snapshot, health))

    def note(self, text):
        """What the session says while the view is up goes above it, through here."""
        self.notes.append(text)


@pytest.mark.parametrize("extra,file_records", [([], False), (["-o", "log.csv"], True)])
def test_terminal_gets_the_dashboard(cli, monkeypatch, tmp_path, extra, file_records):
    from zkzap.commands.zk import monitor as mon
    from zkzap.io import term

    FakeDashboard.made = []
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(mon, "_dashboard", lambda title: FakeDashboard(None, title))
    real = term.is_tty
    monkeypatch.setattr(term, "is_tty", lambda stream: stream is mon.sys.stdout or real(stream))
    r = cli("zk", "monitor", "-p", SIM, "--duration", "10", *extra)
    assert r.exit_code == 0, r
    assert r.stdout == ""                                            # the view replaces stdout records
    (dash,) = FakeDashboard.made
    assert dash.title == f"ZK ECU on {SIM}" and not dash.entered and len(dash.updates) >= 3
    snapshot, health = dash.updates[-1]
    assert set(zk.STATUS_KEYS) | {"time_s"} == set(snapshot)
    assert set(health) == {"frames", "frames_per_s", "crc_errors", "skipped", "stale", "protocol_version",
                           "version_source"}
    assert health["frames"] > 50 and health["protocol_version"] == 6 and health["version_source"] == "frame"
    assert snapshot["max_rpm"] == 160000
    assert all(text.startswith(("note: ", "warning: ")) for text in dash.notes), dash.notes
    if file_records:
        rows = list(csv.DictReader(open(tmp_path / "log.csv")))
        assert len(rows) == health["frames"]


def test_send_for_output_file_format_by_extension(cli, tmp_path):
    out = tmp_path / "drive.jsonl"
    # 2 s of model time (0.1 s of real time): 0.3 s were 15 ms, short enough for a busy machine to
    # pass without one frame read
    r = cli("zk", "send", "mode", "--state", "run", "--rpm-factor", "2", "-p", SIM, "--for", "2", "-o", str(out))
    assert r.exit_code == 0 and r.stdout == ""
    recs = jsonl(out.read_text())
    assert recs and all("frame" in x for x in recs)


def test_table_format_in_a_pipe_is_a_rich_table(cli):
    r = cli("zk", "monitor", "-p", SIM, "--count", "2", "-f", "table")
    assert r.exit_code == 0
    assert "fields" in r.stdout and "power_voltage_v=12.0" in r.stdout and "time=" not in r.stdout
