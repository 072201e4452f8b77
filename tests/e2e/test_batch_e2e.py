"""``zap batch`` and ``zk batch`` as installed commands over a real pty to ``zkzap sim``."""

from __future__ import annotations

import json
import os
import selectors
import signal
import subprocess
import time

from .conftest import clean_env, executable, read_first_line

FAST = ["--speed", "10"]


def jsonl(text):
    return [json.loads(line) for line in text.splitlines()]


def test_zap_batch_one_port_records(start_sim, sh, tmp_path):
    url, _ = start_sim(["zap", "--ids", "1,2", "--pty", *FAST])
    f = tmp_path / "moves.txt"
    f.write_text("# set up\nstore goal-speed 600 --id 2\n\nload goal-speed --id 2\n"
                 "move 1500 --id 1 --wait\nload present-voltage --id 1 --physical\necho --id 7 --retries 0\n"
                 "load present-position --id 1\n")
    r = sh("zap", "batch", str(f), "-p", url)
    recs = jsonl(r.stdout)
    assert r.exit_code == 3                                   # the echo to ID 7: stopped there
    assert [x["line"] for x in recs] == [2, 4, 5, 6, 7]
    assert [x["exit"] for x in recs] == [0, 0, 0, 0, 3]
    assert recs[1]["result"] == 600 and recs[2]["result"] == 1500 and recs[3]["result"] == 12.0
    assert recs[1]["command"] == "load goal-speed --id 2"
    assert "no reply from ID 7" in recs[4]["error"]
    assert f"{f}:7: zap: error: no reply from ID 7" in r.stderr

    r = sh("zap", "batch", str(f), "-p", url, "--keep-going")
    recs = jsonl(r.stdout)
    assert r.exit_code == 3 and [x["line"] for x in recs] == [2, 4, 5, 6, 7, 8] and recs[-1]["result"] == 1500


def test_zap_batch_bad_line_refused_before_anything_is_sent(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "1", "--pty"])
    r = sh("zap", "batch", "-", "-p", url, input="store goal-speed 100 --id 1\nstore goal-speed 5000 --id 1\n")
    assert r.exit_code == 2 and r.stdout == ""
    assert "stdin:2: store: goal-speed: 5000 is out of range" in r.stderr
    assert sh("zap", "load", "goal-speed", "--id", "1", "-p", url).stdout == "1023\n"     # untouched
    for bad, message in (("frobnicate --id 1", "stdin:1: unknown command 'frobnicate'"),
                         ("load present-position -p /dev/null", "stdin:1: -p: the port is the batch's"),
                         ("move 9000 --id 1", "stdin:1: move: goal-position: 9000 is out of range"),
                         ("load 'present-position", "stdin:1: No closing quotation")):
        r = sh("zap", "batch", "-p", url, input=bad + "\n")
        assert r.exit_code == 2 and message in r.stderr, (bad, r.stderr)


def test_zap_batch_one_consent_for_stored_writes(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "1", "--pty"])
    text = "store goal-position 100 --id 1\nstore short-stroke-limit 50 --id 1\nset-id 4 --id 1\n"
    r = sh("zap", "batch", "-p", url, input=text)
    assert r.exit_code == 2 and r.stdout == ""
    assert "stdin:2 store short-stroke-limit 50 --id 1 (short-stroke-limit)" in r.stderr
    assert "stdin:3 set-id 4 --id 1 (id)" in r.stderr and "stdin:1" not in r.stderr
    r = sh("zap", "batch", "-p", url, "--yes", input=text + "load id --id 4\n")
    assert r.exit_code == 0, r.stderr
    assert jsonl(r.stdout)[-1]["result"] == 4


def test_zap_batch_ctrl_c_stops_after_the_current_command(start_sim, tmp_path):
    url, _ = start_sim(["zap", "--ids", "1", "--pty"])
    f = tmp_path / "echoes.txt"
    f.write_text("echo --id 1\n" * 2000)
    proc = subprocess.Popen([executable("zap"), "batch", str(f), "-p", url], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=clean_env())
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    first = b""
    deadline = time.monotonic() + 30
    while not first.endswith(b"\n") and sel.select(max(0.0, deadline - time.monotonic())):
        first += os.read(proc.stdout.fileno(), 1)
    sel.close()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    recs = jsonl((first + out).decode())
    assert proc.returncode == 130
    assert 1 <= len(recs) < 2000 and all(r["exit"] == 0 for r in recs)
    assert b"the batch stopped after the current transaction of " in err


def test_zap_batch_records_reach_the_reader_while_the_next_line_waits(start_sim, tmp_path):
    # a line's record is written while the next line's request is on the wire: the reader has it
    # while the slow actuator (ID 2, 100 ms late) still owes the lines after it their replies
    url, _ = start_sim(["zap", "--ids", "1,2", "--pty", "--fault", "2:delay=100"])
    f = tmp_path / "poll.txt"
    f.write_text("load id --id 1\n" + "load id --id 2\n" * 8)
    proc = subprocess.Popen([executable("zap"), "batch", str(f), "-p", url], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=clean_env())
    first = read_first_line(proc, 30)                         # (nothing after it is consumed)
    still_running = proc.poll() is None                       # 8 slow lines to go: at least 0.8 s
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert json.loads(first) == {"line": 1, "command": "load id --id 1", "exit": 0, "result": 1}
    assert still_running
    recs = jsonl(out.decode())
    assert [r["line"] for r in recs] == list(range(2, 10)) and {r["result"] for r in recs} == {2}


def test_zap_batch_messages_follow_the_records_before_them(start_sim, tmp_path):
    # a line's messages come after every earlier line's record (one terminal, in order), also
    # when the line sent nothing it waited for (in return mode 1 a store is not answered)
    url, _ = start_sim(["zap", "--ids", "1", "--pty"])
    f = tmp_path / "mixed.txt"
    f.write_text("load id --id 1\nstore goal-position 100 --id 1 -v\nload id --id 1\necho --id 7 --retries 0\n")
    r = subprocess.run(f"{executable('zap')} batch {f} -p {url} 2>&1", shell=True,
                       capture_output=True, text=True, env=clean_env(), timeout=60)
    lines = r.stdout.splitlines()
    assert r.returncode == 3, r.stdout
    kinds = [json.loads(x)["line"] if x.startswith("{") else x.split(": ", 2)[0] for x in lines]
    assert kinds == [1, f"{f}:2", 2, 3, f"{f}:4", 4], lines


def test_zk_batch_over_a_pty(start_sim, sh):
    url, _ = start_sim(["zk", "--pty", "--speed", "20"])
    text = "send keepalive\nmonitor --count 4 --ids 1\nsend control --state run --throttle 20 --for 0.5 --ids 1\n"
    r = sh("zk", "batch", "-", "-p", url, input=text)
    assert r.exit_code == 2 and "stdin:3 send control --state run --throttle 20" in r.stderr   # consent
    r = sh("zk", "batch", "-", "-p", url, "--yes", input=text)
    assert r.exit_code == 0, r.stderr
    recs = jsonl(r.stdout)
    assert [x["exit"] for x in recs] == [0, 0, 0]
    assert len(recs[1]["result"]) == 4 and all(x["id"] == 1 for x in recs[1]["result"])
    assert recs[2]["result"] and recs[2]["result"][-1]["kind"] == "status"
    r = sh("zk", "batch", "-", "-p", url, input="send control --state run --throttle 300\n")
    assert r.exit_code == 2 and "stdin:1: send control: throttle: 300 is out of range" in r.stderr
