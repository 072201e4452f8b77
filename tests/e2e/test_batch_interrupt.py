"""Ctrl-C and SIGTERM in ``zap batch`` / ``zk batch``: the running line stops after its current
transaction, ends as the command ends on Ctrl-C alone, and no later line starts.

The batch talks to ``zkzap sim`` through a relay pty that keeps every byte the host wrote, so
the tests wait for evidence that the long line runs (its requests on the wire), and check that
what went out is whole packets/frames, that next to nothing went out after the signal, and
for the ZK that the abort frames were the last ones sent.
"""

from __future__ import annotations

import json
import signal
import subprocess
import time

import pytest

from zkzap.codec import zk
from zkzap.codec.framing import ZapFramer
from zkzap.api.session import abort_frames

from .conftest import clean_env, executable
from .relay import Relay


@pytest.fixture
def relay(start_sim):
    made = []

    def make(args, baud):
        url, _ = start_sim(args)
        r = Relay(url, baud, taps=0)
        r.start()
        made.append(r)
        return r

    yield make
    for r in made:
        r.stop()


def zap_packets(data: bytes):
    framer = ZapFramer()
    packets = [bytes(p) for p in framer.feed(data)]
    return packets, framer


def wait_until(what, predicate, timeout=60.0):
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


def interrupt_batch(program, relay, text, *args, evidence, sig=signal.SIGINT):
    """Run ``program batch -`` over ``relay`` with ``text``; once ``evidence(bytes written)``
    holds, send ``sig``. Returns (exit status, records, stderr, bytes written when signalled,
    seconds from the signal to the end)."""
    proc = subprocess.Popen([executable(program), "batch", "-", "-p", relay.host_path, *args],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=clean_env())
    proc.stdin.write(text.encode())
    proc.stdin.close()
    proc.stdin = None
    try:
        wait_until("the long line's traffic", lambda: evidence(relay.sent()) or proc.poll() is not None)
        if proc.poll() is not None:
            out, err = proc.communicate()
            raise AssertionError(f"the batch ended (exit {proc.returncode}) before the signal: "
                                 f"{out.decode()[-500:]} {err.decode()}")
        at = relay.sent()
        t0 = time.monotonic()
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    records = [json.loads(line) for line in out.decode().splitlines()]
    return proc.returncode, records, err.decode(), at, took


# each: the batch text (line 1 quick, line 2 long, line 3 never reached), extra batch options,
# the simulator's options, the fewest requests of line 2 to wait for, and what the stopped
# line leaves on stderr
ZAP_LINES = {
    "scan": ("scan -b all --retries 0", [], [], 30, "found so far"),
    "dump": ("dump --id 1", ["--timeout", "10"], ["--gap", "60"], 1, None),
    "echo": ("echo --id 1 --count 0", [], [], 30, "answered"),
    "watch": ("watch present-position --ids 1 --rate 50 --count 100000 -f jsonl", [], [], 10, None),
    "move": ("move 3000 --id 1 --wait --timeout 600", [], [], 10, "interrupted: ID 1 stopped at"),
}


@pytest.mark.parametrize("name", sorted(ZAP_LINES))
def test_zap_batch_stops_after_the_current_transaction(relay, name):
    line, opts, sim_opts, wait_for, says = ZAP_LINES[name]
    r = relay(["zap", "--ids", "1", "--pty", *sim_opts], 57600)
    prelude = "store goal-speed 20 --id 1\n" if name == "move" else "load present-position --id 1\n"
    text = prelude + line + "\nload present-voltage --id 1\n"
    before = []

    def evidence(data):
        packets, _ = zap_packets(data)
        if not before and packets:
            before.append(1)
        # line 1 is one request; line 2's requests are the rest
        return len(packets) - 1 >= wait_for

    code, recs, err, at, took = interrupt_batch("zap", r, text, *opts, evidence=evidence)
    assert code == 130, err
    assert [x["line"] for x in recs] == [1, 2], recs          # line 3 never started
    assert recs[0]["exit"] == 0
    assert recs[1]["exit"] == 130 and recs[1]["command"] == line
    assert "interrupted: the batch stopped after the current transaction of stdin:2" in err
    if says:
        assert says in err, err
    assert took < 15                                           # the line itself runs far longer
    packets, framer = zap_packets(r.sent())
    assert not framer.pending and not framer.bad and not framer.skipped   # only whole requests
    after = len(packets) - len(zap_packets(at)[0])
    # the request in flight and a move's clean-up (read where the rod is, stop it there) — plus
    # whatever went out while a loaded machine delayed the signal or this relay: a bound far
    # below what the line sends in full (1,270 probes, endless echoes, 100,000 polls, a long move)
    assert after <= 50, after
    if name == "move":
        assert packets[-1][5] == 0xF3 and packets[-1][6] == 134   # Send Data goal-position: stopped
        stopped = int.from_bytes(packets[-1][7:9], "little")
        assert recs[1]["result"] == stopped and f"stopped at {stopped}" in err   # where, in the record too
    if name == "scan" and "1 actuator found so far" in err:
        assert recs[1]["result"]["id"] == 1                   # what it found so far


def test_zap_batch_sigterm_is_143(relay):
    r = relay(["zap", "--ids", "1", "--pty"], 57600)
    text = "load present-position --id 1\necho --id 1 --count 0\nload present-voltage --id 1\n"
    code, recs, err, _, _ = interrupt_batch("zap", r, text, sig=signal.SIGTERM,
                                            evidence=lambda data: len(zap_packets(data)[0]) > 10)
    assert code == 143, err
    assert [(x["line"], x["exit"]) for x in recs] == [(1, 0), (2, 143)]
    assert "terminated: the batch stopped after the current transaction of stdin:2" in err


def _zk_frames(data: bytes):
    assert len(data) % 4 == 0, len(data)                      # only whole control frames
    frames = [data[i:i + 4] for i in range(0, len(data), 4)]
    for f in frames:
        zk.ControlFrame(f)                                     # each one valid (CRC and all)
    return frames


@pytest.mark.parametrize("kind", ["send", "profile", "send-sigterm"])
def test_zk_batch_stops_the_session_and_aborts(relay, tmp_path, kind):
    r = relay(["zk", "--pty", "--speed", "10"], 115200)
    sig, status, why = ((signal.SIGTERM, 143, "terminated") if kind.endswith("sigterm")
                        else (signal.SIGINT, 130, "interrupted"))
    if kind.startswith("send"):
        line = "send control --state run --throttle 30 --for 300 --ids 1"
    else:
        schedule = tmp_path / "run.csv"
        schedule.write_text("0,20\n100,40\n300,60\n")
        line = f"profile {schedule} -f jsonl"
    text = f"send keepalive\n{line}\nsend keepalive\n"
    code, recs, err, at, took = interrupt_batch(
        "zk", r, text, "--yes", sig=sig, evidence=lambda data: len(data) >= 4 * 10)   # the session's frames
    assert code == status, err
    assert [x["line"] for x in recs] == [1, 2]
    assert recs[0]["exit"] == 0 and recs[1]["exit"] == status
    kinds = [x["kind"] for x in recs[1]["result"]]
    if sig == signal.SIGINT:                                   # the rundown recorded, after the trip
        assert kinds[-1] == "rundown" and "trip" in kinds
    else:                                                      # SIGTERM: the process is to go
        assert kinds[-1] in ("status", "snapshot") and "trip" not in kinds
    assert f"{why}: sent standby, throttle 0" in err
    assert f"{why}: the batch stopped after the current transaction of stdin:2" in err
    assert took < 15
    frames = _zk_frames(r.sent())
    standby = abort_frames("standby")
    assert frames[-1] == standby[-1]                           # the abort was the last word
    assert set(frames[len(at) // 4:]) <= set(standby) | {frames[len(at) // 4 - 1]}
    # and the ECU is in the abort's safe state
    p = subprocess.run([executable("zk"), "monitor", "-p", r.host_path, "--ids", "1", "--count", "3", "-f", "jsonl"],
                       capture_output=True, text=True, timeout=60, env=clean_env())
    assert p.returncode == 0, p.stderr
    assert all(json.loads(x)["sw_state_name"] == "standby" for x in p.stdout.splitlines())
