"""The installed fleet commands against ``zkzap sim zap`` processes over real ptys: a backup
of bus A applied to a factory-fresh bus B, then no differences; a watch ended by a condition;
a guided setup resumed by a second process."""

import json

from .conftest import stop_sim

FAST = ["--speed", "10"]


def jsonl(text):
    return [json.loads(line) for line in text.splitlines()]


def test_clone_bus_a_onto_fresh_bus_b_over_ptys(start_sim, sh, tmp_path):
    a_url, _ = start_sim(["zap", "--ids", "1,2", "--pty", *FAST])
    b_url, _ = start_sim(["zap", "--ids", "1,2", "--pty", *FAST])
    assert sh("zap", "store", "speed-limit", "400", "--id", "1", "-p", a_url, "--yes").exit_code == 0
    assert sh("zap", "store", "current-limit", "700", "--id", "2", "-p", a_url, "--yes").exit_code == 0
    fleet = str(tmp_path / "fleet.toml")
    r = sh("zap", "backup", "--ids", "1,2", "-p", a_url, "-o", fleet)
    assert r.exit_code == 0, r
    r = sh("zap", "apply", fleet, "-p", b_url, "--yes")
    assert r.exit_code == 0, r
    assert [(x["id"], x["register"], x["status"]) for x in jsonl(r.stdout)] == [
        (1, "speed-limit", "verified"), (2, "current-limit", "verified")]
    r = sh("zap", "diff", fleet, "bus", "-p", b_url)
    assert (r.exit_code, r.stdout) == (0, ""), r


def test_watch_until_moving_stops_over_a_pty(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "1,2", "--pty", *FAST])
    assert sh("zap", "sync-move", "1:3000", "2:1500", "-p", url).exit_code == 0
    r = sh("zap", "watch", "present-position", "--ids", "1,2", "--until", "moving==0", "-p", url)
    assert r.exit_code == 0, r
    rows = jsonl(r.stdout)
    assert {x["id"]: x["present-position"] for x in rows[-2:]} == {1: 3000, 2: 1500}
    assert "condition met" in r.stderr


def test_setup_resumes_in_a_second_process(start_sim, sh, tmp_path):
    state = str(tmp_path / "setup.json")
    args = ["setup", "--ids", "1-2", "--state", state, "--find-ids", "0-3", "--find-baud", "57600,115200", "--yes"]
    url, proc = start_sim(["zap", "--ids", "0", "--pty"])
    r = sh("zap", *args, "-p", url, input="\n")
    assert r.exit_code == 8 and "ID 1 done: found at ID 0, 57600 baud" in r.stderr
    stop_sim(proc)
    url, _ = start_sim(["zap", "--ids", "0@115200", "--pty"])    # the next one talks at 115200
    r = sh("zap", *args, "-p", url, input="\n")
    assert r.exit_code == 0, r
    assert "ID 2 done: found at ID 0, 115200 baud" in r.stderr and "setup: 2 of 2 done (1-2)" in r.stderr
