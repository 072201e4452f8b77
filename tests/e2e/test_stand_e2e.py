"""End to end on a real pty: a stand run with an RPM schedule, the shipped limits file, step
averages and a logbook; then the report from its CSV and the pre-flight check, all as installed
commands; and a limit violated by the simulator's injected error."""

from __future__ import annotations

import csv
import io
import json
import subprocess

import pytest

from .conftest import clean_env, executable


def zk(*args, timeout=60):
    return subprocess.run([executable("zk"), *args], capture_output=True, text=True, timeout=timeout,
                          env=clean_env())


def test_stand_run_report_and_logbook(start_sim, tmp_path):
    url, _ = start_sim(["zk", "--pty", "--speed", "20"])
    sched, limits = tmp_path / "rpm.csv", tmp_path / "engine.limits"
    # as a European spreadsheet saves it; the start (12 s of the simulator's model time) takes 0.6 s
    sched.write_text("time_s;throttle_pct;rpm;state\n0;0;;run\n1,0;;80000;\n1,5;;120000;\n2,0;0;;standby\n"
                     "2,2;0;;standby\n")
    limits.write_text(zk("profile", "--example", "limits").stdout)
    tel, steps, summary, book = (tmp_path / n for n in ("tel.csv", "steps.csv", "s.json", "engine.db"))
    r = zk("profile", str(sched), "-p", url, "--yes", "-o", str(tel), "--limits", str(limits), "--settle", "0.2",
           "--steps-csv", str(steps), "--summary-json", str(summary), "--logbook", str(book))
    assert r.returncode == 0, r.stderr
    s = json.loads(summary.read_text())
    assert [x["verdict"] for x in s["limits"]] == ["ok"] * 4
    rows = list(csv.DictReader(io.StringIO(steps.read_text())))
    assert [row["target"] for row in rows] == ["80000 rpm", "120000 rpm"]      # no start-up, no standby
    assert abs(float(rows[1]["rpm_mean"]) - 120000) < 6000 and s["rows_not_steps"][0]["why"] == "start-up"
    out = tmp_path / "report.png"
    r = zk("report", str(tel), "--steps", str(steps), "--summary", str(summary), "-o", str(out))
    assert r.returncode == 0 and out.read_bytes()[:4] == b"\x89PNG", r.stderr
    r = zk("logbook", str(book), "-f", "json")
    assert json.loads(r.stdout)["totals"]["starts"] == 1
    r = zk("check", "-p", url, "--count", "20", "--limits", str(limits))
    assert r.returncode == 0 and json.loads(r.stdout)["verdict"] == "pass", r.stderr


def test_the_simulators_egt_violates_a_limit_and_the_engine_gets_the_abort(start_sim):
    url, _ = start_sim(["zk", "--pty", "--speed", "20"])
    r = zk("send", "control", "--state", "run", "--throttle", "40", "--for", "5", "-p", url, "--yes", "-f", "jsonl",
           "--ids", "1", "--limit", "egt_c<=500")
    assert r.returncode == 5, r.stderr
    assert "limit violated: sent standby, throttle 0" in r.stderr and "error: limit violated: egt_c=" in r.stderr
    recs = [json.loads(line) for line in r.stdout.splitlines()]
    trip = next(i for i, rec in enumerate(recs) if rec["kind"] == "trip")
    assert recs[trip - 1]["limit"] == ["egt_c<=500"] and recs[trip]["limit"] == "egt_c<=500"
    assert recs[-1]["kind"] == "rundown" and recs[-2]["engine_state_name"] == "standby"


@pytest.mark.parametrize("how,code", [("exit", 5), ("warn", 5)])
def test_an_injected_error_violates_a_limit(start_sim, how, code):
    url, _ = start_sim(["zk", "--pty", "--speed", "20", "--set", "error=egt-high", "--set", "error_after=0.5"])
    r = zk("monitor", "-p", url, "--duration", "1", "-f", "jsonl", "--limit", "error_code==0", "--on-limit", how)
    assert r.returncode == code, r.stderr
    assert "sent" not in r.stderr and "limit error_code==0: VIOLATED first at" in r.stderr
    recs = [json.loads(line) for line in r.stdout.splitlines()]
    assert any(rec.get("limit") == ["error_code==0"] for rec in recs)
    if how == "warn":
        assert recs[-1]["t"] > 0.9 and "note: limit violated: error_code=8" in r.stderr


def _interrupted_run(tmp_path, url, second):
    """``zk send --for`` with the engine running, then Ctrl-C (and, with ``second``, Ctrl-C
    again once the rundown is being recorded); its records, stderr and exit status."""
    import signal
    import threading
    import time

    out = tmp_path / "run.jsonl"
    proc = subprocess.Popen([executable("zk"), "send", "control", "--state", "run", "--throttle", "50", "--for", "120",
                             "-p", url, "--yes", "-o", str(out)], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=clean_env())
    err = []
    reader = threading.Thread(target=lambda: err.extend(iter(proc.stderr.readline, "")), daemon=True)
    reader.start()

    def until(what, timeout=30):
        end = time.monotonic() + timeout
        while not what():
            assert proc.poll() is None and time.monotonic() < end, "".join(err)
            time.sleep(0.05)

    def running():
        lines = out.read_text().splitlines() if out.exists() else []
        return any('"engine_state_name":"running"' in line for line in lines[-20:])

    try:
        until(running)
        proc.send_signal(signal.SIGINT)
        if second:
            until(lambda: any("recording the rundown" in line for line in err))
            proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    reader.join(5)
    return [json.loads(line) for line in out.read_text().splitlines()], "".join(err), proc.returncode


def test_ctrl_c_records_the_rundown_and_a_second_one_cuts_it(start_sim, tmp_path):
    url, _ = start_sim(["zk", "--pty", "--speed", "5"])
    recs, err, code = _interrupted_run(tmp_path, url, second=False)
    assert code == 130, err
    kinds = [r["kind"] for r in recs]
    trip = kinds.index("trip")
    assert recs[trip]["reason"] == "interrupted" and "sent standby, throttle 0" in recs[trip]["trip"]
    after = [r["engine_state_name"] for r in recs[trip + 1:] if r.get("id") == 1]
    assert after[0] in ("running", "cooling") and "cooling" in after and after[-1] == "standby"
    assert recs[-1]["kind"] == "rundown" and recs[-1]["ended"] == "rest" and "rundown recorded:" in err

    (tmp_path / "run.jsonl").unlink()
    url, _ = start_sim(["zk", "--pty", "--speed", "2"])          # a cool-down of seconds
    recs, err, code = _interrupted_run(tmp_path, url, second=True)
    assert code == 130, err
    assert recs[-1]["kind"] == "rundown" and recs[-1]["ended"] == "cut"
    assert "rundown recording cut after" in err and "not recorded from there" in err
    assert [r["engine_state_name"] for r in recs if r.get("id") == 1][-1] != "standby"
