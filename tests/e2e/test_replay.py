"""The simulators play recordings: ``sim zk --replay`` serves a recorded ECU session to
``zk monitor`` record for record; ``sim zap --replay`` answers recorded requests as recorded."""

from __future__ import annotations

import json
import subprocess

from .conftest import clean_env, executable

FIELDS_ONLY = ("time", "t", "stale", "stale_ids")


def run(name, *args, timeout=60):
    return subprocess.run([executable(name), *args], stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=timeout, env=clean_env())


def records(text):
    return [{k: v for k, v in json.loads(line).items() if k not in FIELDS_ONLY} for line in text.splitlines()]


def test_sim_zk_replay_reproduces_a_recorded_session_record_for_record(start_sim, tmp_path):
    url, _ = start_sim(["zk", "--speed", "10", "--pty"])
    cap = tmp_path / "run.pcapng"
    host_log = tmp_path / "host.jsonl"
    rec = run("zk", "send", "control", "--state", "run", "--throttle", "40", "--for", "2.5", "--yes", "-p", url,
              "-f", "jsonl", "--capture", str(cap), "--abort", "none")
    assert rec.returncode == 0, rec.stderr
    recorded = records(rec.stdout)
    assert len({r.get("rpm") for r in recorded}) > 5          # a session that changes
    # the replay, on a pty; monitor it for as many records as were recorded, minus what may pass
    # before the monitor opens the port
    url2, sim = start_sim(["zk", "--replay", str(cap), "--pty", "-o", str(host_log)])
    n = len(recorded) // 2
    mon = run("zk", "monitor", "-p", url2, "--count", str(n), "-f", "jsonl", "--keepalive")
    assert mon.returncode == 0, mon.stderr
    replayed = records(mon.stdout)
    assert len(replayed) == n
    first = next(i for i in range(len(recorded)) if recorded[i:i + n] == replayed)
    assert recorded[first:first + n] == replayed
    # the host's keep-alives were decoded and logged
    from .conftest import stop_sim

    assert stop_sim(sim) == 0
    logged = [json.loads(x) for x in host_log.read_text().splitlines()]
    assert logged and all(x["kind"] == "control" and x["command"] == "keepalive" and x["dir"] == "h2d"
                          for x in logged)


def test_sim_zk_replay_loops(start_sim, tmp_path):
    cap = tmp_path / "short.pcapng"
    rec = run("zk", "monitor", "--sim", "--count", "12", "-f", "jsonl", "--capture", str(cap))
    assert rec.returncode == 0, rec.stderr
    url, _ = start_sim(["zk", "--replay", str(cap), "--loop", "--speed", "5", "--pty"])
    mon = run("zk", "monitor", "-p", url, "--count", "40", "-f", "jsonl")
    assert mon.returncode == 0, mon.stderr                   # more records than the capture holds
    assert len(mon.stdout.splitlines()) == 40


def test_sim_zap_replay_answers_recorded_requests_as_recorded(start_sim, tmp_path):
    cap = tmp_path / "field.pcapng"
    field = "sim://zap?ids=4&faults=4:voltage=6.5,4:delay=30"
    r = run("zap", "load", "present-voltage", "--id", "4", "-p", field, "--capture", str(cap), "--timeout", "0.5")
    assert r.returncode == 5 and r.stdout.strip() == "65", r.stderr      # the field problem
    url, _ = start_sim(["zap", "--replay", str(cap), "--pty"])
    again = tmp_path / "again.pcapng"
    r2 = run("zap", "load", "present-voltage", "--id", "4", "-p", url, "--capture", str(again),
             "--timeout", "0.5")
    assert (r2.returncode, r2.stdout, r2.stderr) == (r.returncode, r.stdout, r.stderr)
    fb = [json.loads(x) for x in run("zap", "decode", str(again)).stdout.splitlines() if '"feedback"' in x]
    assert fb and fb[0]["latency_ms"] >= 25                  # the recorded 30 ms, reproduced
    # a request that was not recorded goes to the model: a healthy actuator with ID 4
    r3 = run("zap", "load", "present-position", "--id", "4", "-p", url)
    assert r3.returncode == 0, r3.stderr


def test_sim_replay_refuses_what_is_not_a_capture(sh, tmp_path):
    raw = tmp_path / "run.bin"
    raw.write_bytes(b"\xf1\x00\x00\x00\x00\x4c\xa0")
    r = sh("zkzap", "sim", "zk", "--replay", str(raw))
    assert r.exit_code == 2 and r.stdout == ""
    assert f"{raw}: not a pcapng capture: data starting with F1 00 00 00" in r.stderr
