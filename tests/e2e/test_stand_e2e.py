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
    assert json.loads(r.stdout.splitlines()[-1])["limit"] == ["egt_c<=500"]


@pytest.mark.parametrize("how,code", [("exit", 5), ("warn", 0)])
def test_an_injected_error_violates_a_limit(start_sim, how, code):
    url, _ = start_sim(["zk", "--pty", "--speed", "20", "--set", "error=egt-high", "--set", "error_after=0.5"])
    r = zk("monitor", "-p", url, "--duration", "1", "-f", "jsonl", "--limit", "error_code==0", "--on-limit", how)
    assert r.returncode == code, r.stderr
    assert "sent" not in r.stderr and "limit error_code==0: VIOLATED first at" in r.stderr
    recs = [json.loads(line) for line in r.stdout.splitlines()]
    assert any(rec.get("limit") == ["error_code==0"] for rec in recs)
    if how == "warn":
        assert recs[-1]["t"] > 0.9 and "note: limit violated: error_code=8" in r.stderr
