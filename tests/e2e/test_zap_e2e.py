"""The installed ``zap`` commands against ``zkzap sim zap`` over a real pty and a real TCP socket."""

import json
import signal
import subprocess
import time

import pytest

from .conftest import clean_env, executable

FAST = ["--speed", "10"]           # model time 10x: moves and turnarounds shrink, timeouts do not


def jsonl(text):
    return [json.loads(line) for line in text.splitlines()]


def test_port_on_the_first_line(start_sim, transport):
    url, proc = start_sim(["zap", "--ids", "1", *transport])
    if "--pty" in transport:
        assert url.startswith("/dev/")
    else:
        assert url.startswith("socket://127.0.0.1:") and not url.endswith(":0")
    assert proc.poll() is None


def test_no_device_exit_3(start_sim, transport, sh):
    url, _ = start_sim(["zap", "--ids", "1", *transport, *FAST])
    r = sh("zap", "load", "present-position", "--id", "9", "-p", url)
    assert r.exit_code == 3 and r.stdout == ""
    assert "no reply from ID 9 at 57600 baud" in r.stderr


def test_load_value_in_a_shell_capture(start_sim, transport, sh):
    url, _ = start_sim(["zap", "--ids", "1", *transport, *FAST])
    zap = executable("zap")
    assert sh("zap", "move", "1234", "--id", "1", "--wait", "-p", url).stdout == "1234\n"
    script = f'pos=$("{zap}" load present-position --id 1 -p "{url}") && echo "position is $pos"'
    p = subprocess.run(["sh", "-c", script], capture_output=True, text=True, env=clean_env(), timeout=30)
    assert (p.returncode, p.stdout, p.stderr) == (0, "position is 1234\n", "")


def test_scan(start_sim, transport, sh):
    url, _ = start_sim(["zap", "--ids", "1,2,7", *transport, *FAST])
    r = sh("zap", "scan", "--ids", "0-20", "-p", url)
    assert r.exit_code == 0, r
    assert [(x["id"], x["baud"], x["status"]) for x in jsonl(r.stdout)] == [(1, 57600, "ok"), (2, 57600, "ok"),
                                                                            (7, 57600, "ok")]


def test_sync_move_and_move_wait(start_sim, transport, sh):
    url, _ = start_sim(["zap", "--ids", "1,2,3", *transport, *FAST])
    assert sh("zap", "sync-move", "1:1000", "2:2000", "-p", url).exit_code == 0
    r = sh("zap", "move", "3000", "--id", "3", "--speed", "1023", "--wait", "-p", url)
    assert (r.exit_code, r.stdout) == (0, "3000\n")
    for ident, goal in ((1, 1000), (2, 2000)):
        r = sh("zap", "load", "present-position", "--id", str(ident), "-p", url)
        assert r.stdout == f"{goal}\n"


def test_overload_exit_5(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "1,2", "--pty", "--fault", "2:overload", *FAST])
    r = sh("zap", "load", "present-position", "--id", "2", "-p", url)
    assert r.exit_code == 5 and r.stdout == "0\n"
    assert "ID 2 reports error 0x20: overload" in r.stderr
    assert sh("zap", "echo", "--id", "1", "-p", url).exit_code == 0


def test_corrupted_reply_exit_6_after_retries(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "2", "--listen", "127.0.0.1:0", "--fault", "2:corrupt", *FAST])
    r = sh("zap", "echo", "--id", "2", "-p", url)
    assert r.exit_code == 6
    assert "garbled reply (checksum mismatch: a collision, two actuators answering at once, or a line fault) after 3 tries" in r.stderr


def test_echoing_adapter(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "1", "--pty", "--echo", *FAST])
    assert sh("zap", "load", "present-voltage", "--id", "1", "-p", url).stdout == "120\n"
    r = sh("zap", "scan", "--ids", "0-3", "-p", url)
    assert [x["id"] for x in jsonl(r.stdout)] == [1]
    r = sh("zap", "echo", "--id", "2", "-p", url)
    assert r.exit_code == 3 and "only our own bytes came back" in r.stderr


def test_move_wait_timeout_exit_3(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "1", "--pty", "--fault", "1:stuck", *FAST])
    r = sh("zap", "move", "2000", "--id", "1", "--wait", "--wait-timeout", "0.3", "-p", url)
    assert r.exit_code == 3 and "still moving after 0.3 s" in r.stderr


def test_set_id_verified(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "1", "--pty", *FAST])
    r = sh("zap", "set-id", "7", "--id", "1", "-p", url)
    assert r.exit_code == 2 and "pass --yes" in r.stderr                  # a real port asks first
    r = sh("zap", "set-id", "7", "--id", "1", "--yes", "-p", url)
    assert r.exit_code == 0 and "ID 1 is now ID 7 (verified)" in r.stderr
    assert sh("zap", "echo", "--id", "7", "-p", url).exit_code == 0
    assert sh("zap", "echo", "--id", "1", "-p", url, "--retries", "0").exit_code == 3


def test_set_baud_over_a_pty(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "1", "--pty", *FAST])
    r = sh("zap", "set-baud", "115200", "--id", "1", "--yes", "-p", url)
    assert r.exit_code == 0 and "now talks at 115200 baud (verified)" in r.stderr
    assert sh("zap", "echo", "--id", "1", "-b", "115200", "-p", url).exit_code == 0
    assert sh("zap", "echo", "--id", "1", "--retries", "0", "-p", url).exit_code == 3
    r = sh("zap", "scan", "--ids", "0-2", "-b", "all", "-p", url)
    assert [(x["id"], x["baud"]) for x in jsonl(r.stdout)] == [(1, 115200)]


def test_stored_settings_survive_a_simulator_restart(start_sim, stop, sh, tmp_path):
    state = str(tmp_path / "bus.json")
    url, proc = start_sim(["zap", "--ids", "1", "--pty", "--state", state, *FAST])
    assert sh("zap", "store", "long-stroke-limit", "3000", "--id", "1", "--yes", "-p", url).exit_code == 0
    assert sh("zap", "set-id", "5", "--id", "1", "--yes", "-p", url).exit_code == 0
    assert sh("zap", "move", "2500", "--id", "5", "--wait", "-p", url).exit_code == 0
    assert stop(proc) == 0
    url, _ = start_sim(["zap", "--ids", "1", "--listen", "127.0.0.1:0", "--state", state, *FAST])
    r = sh("zap", "load", "long-stroke-limit", "--id", "5", "-p", url)
    assert (r.exit_code, r.stdout) == (0, "3000\n")
    assert sh("zap", "load", "present-position", "--id", "5", "-p", url).stdout == "2500\n"
    assert sh("zap", "load", "goal-position", "--id", "5", "-p", url).stdout == "2500\n"


def test_simulator_killed_under_a_running_command_exit_4(start_sim, transport, stop):
    url, proc = start_sim(["zap", "--ids", "1", *transport, *FAST])
    echo = subprocess.Popen([executable("zap"), "echo", "--id", "1", "--count", "0", "--interval", "0.01",
                             "-p", url], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=clean_env())
    try:
        first = echo.stdout.readline()
        assert first.startswith("reply from ID 1: seq=1 ok")
        stop(proc, signal.SIGKILL)
        out, err = echo.communicate(timeout=10)
    finally:
        if echo.poll() is None:
            echo.kill()
    assert echo.returncode == 4, err
    assert "port" in err and "failed" in err
    assert "sent" in err and "answered" in err                           # the summary still came


def test_simulator_stops_cleanly_on_sigint(start_sim, stop):
    _, proc = start_sim(["zap", "--ids", "1", "--pty"])
    t = time.monotonic()
    assert stop(proc, signal.SIGINT) == 0
    assert time.monotonic() - t < 2


@pytest.mark.parametrize("args,needle", [
    (["--fault", "2:explode"], "unknown kind 'explode'"),
    (["--listen", "localhost:http"], "--listen"),
    (["--ids", "1,300"], "out of range"),
])
def test_simulator_refuses_bad_options(sh, args, needle):
    r = sh("zkzap", "sim", "zap", *args)
    assert r.exit_code == 2 and needle in r.stderr and r.stdout == ""


def test_full_scan_over_a_pty_finds_the_one_actuator(start_sim, sh):
    # how long it takes is measured by benchmarks/transactions.py, not here
    url, _ = start_sim(["zap", "--ids", "3", "--pty", *FAST])
    r = sh("zap", "scan", "-p", url)
    assert r.exit_code == 0, r.stderr
    assert [(x["id"], x["status"]) for x in jsonl(r.stdout)] == [(3, "ok")]


@pytest.mark.parametrize("sim_args", [
    ["--fault", "3:delay=18", "--fault", "9:delay=18"],               # some actuators answer 20 ms late
    ["--turnaround", "20", "--gap", "1"],                             # every one slow and trickling
    ["--turnaround", "20", "--gap", "1", "--echo"],                   # ... behind an echoing adapter
], ids=["some-late", "slow-trickling", "slow-trickling-echo"])
def test_scan_finds_every_slow_actuator_over_a_pty(start_sim, sh, sim_args):
    url, _ = start_sim(["zap", "--ids", "1,2,3,9,30", "--pty", *sim_args])
    r = sh("zap", "scan", "--ids", "0-40", "-p", url)
    assert r.exit_code == 0, r.stderr
    recs = jsonl(r.stdout)
    assert [(x["id"], x["status"], x["return_mode"]) for x in recs] == [(i, "ok", 1) for i in (1, 2, 3, 9, 30)]


def test_issue_examples_slow_actuators_over_a_pty(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "1,2", "--pty", "--fault", "all:delay=12"])
    r = sh("zap", "echo", "--id", "1", "-p", url)
    assert r.exit_code == 0 and "reply from ID 1" in r.stdout
    rtt = float(r.stdout.split()[-2])
    assert rtt >= 12 + 2 + 2.4 - 0.5                                   # delay + turnaround + both packets
    r = sh("zap", "set-id", "5", "--id", "2", "--yes", "-p", url)
    assert r.exit_code == 0 and "verified" in r.stderr, r.stderr
    r = sh("zap", "scan", "--ids", "0-8", "-p", url)
    assert [x["id"] for x in jsonl(r.stdout)] == [1, 5]
