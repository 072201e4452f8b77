"""Fault injection: the output runs out of space, signals arrive at random moments, replies come
late, garbled or from two actuators at once. Real subprocesses, the simulators on real ptys.

What the user must get each time: a clear one-line message, the documented exit status, and
every record written before the fault whole (a file is cut back to its last whole record).
"""

from __future__ import annotations

import csv
import io
import json
import random
import resource
import signal
import subprocess
import time

import pytest

from zkzap.codec import zap, zk

from .conftest import clean_env, executable

SPEED = "20"
LIMIT = 40_000          # bytes the output file may grow to (RLIMIT_FSIZE): the "disk"


def small_disk():
    resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT, LIMIT))
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)      # then a write past the limit fails (EFBIG)


def run(name, *args, timeout=30, preexec=None, stdout=subprocess.PIPE):
    return subprocess.run([executable(name), *args], stdin=subprocess.DEVNULL, stdout=stdout,
                          stderr=subprocess.PIPE, text=True, timeout=timeout, env=clean_env(),
                          preexec_fn=preexec)


def whole_records(path, fmt):
    text = path.read_text()
    assert text.endswith("\n"), "the file ends inside a record"
    if fmt == "csv":
        rows = list(csv.reader(io.StringIO(text)))
        assert all(len(r) == len(rows[0]) for r in rows[1:])
        return rows[1:]
    return [json.loads(line) for line in text.splitlines()]


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    d = tmp_path_factory.mktemp("cap")
    rng = random.Random(4)
    # 3000 zk frames decode to seven to ten times the "disk" (LIMIT) in every format: enough to
    # fill it mid-run, little enough that the decode after the failure stays short
    (d / "zk.bin").write_bytes(b"".join(zk.status_frame(i % 10 + 1, rng.randbytes(5)) for i in range(3000)))
    (d / "zap.bin").write_bytes(b"".join(zap.packet(i % 4 + 1, 0, rng.randbytes(2)) for i in range(5000)))
    return d


@pytest.mark.parametrize("cmd,fmt", [
    (("zk", "decode", "--binary", "{cap}/zk.bin"), "jsonl"),
    (("zk", "decode", "--binary", "{cap}/zk.bin", "-f", "csv"), "csv"),
    (("zk", "decode", "--binary", "{cap}/zk.bin", "-f", "json"), None),
    (("zap", "decode", "--binary", "{cap}/zap.bin"), "jsonl"),
])
def test_disk_full_during_decode(captures, tmp_path, cmd, fmt):
    out = tmp_path / f"out.{fmt or 'json'}"
    r = run(cmd[0], *(a.replace("{cap}", str(captures)) for a in cmd[1:]), "-o", str(out), preexec=small_disk)
    assert r.returncode == 7, r.stderr
    assert r.stderr == f"{cmd[0]}: error: output: cannot write {out}: File too large\n"
    assert r.stdout == ""
    assert 0 < out.stat().st_size <= LIMIT
    if fmt:
        assert len(whole_records(out, fmt)) > 10
    else:
        text = out.read_text()                  # whole objects; the array is left open
        assert text.startswith("[\n{") and text.endswith("},\n")
        assert len(json.loads(text[:-2] + "]")) > 10


def test_disk_full_during_monitor(start_sim, tmp_path):
    url, _ = start_sim(["zk", "--speed", SPEED, "--pty"])
    out = tmp_path / "log.csv"
    r = run("zk", "monitor", "-p", url, "--count", "2000", "-f", "csv", "-o", str(out), preexec=small_disk)
    assert r.returncode == 7, r.stderr
    assert r.stderr.endswith(f"zk: error: output: cannot write {out}: File too large\n")
    assert "Traceback" not in r.stderr
    assert len(whole_records(out, "csv")) > 10


def test_stdout_on_a_full_device(captures):
    with open("/dev/full", "w") as full:
        r = run("zk", "decode", "--binary", str(captures / "zk.bin"), stdout=full)
    assert r.returncode == 7 and r.stderr == "zk: error: output: cannot write stdout: No space left on device\n"


# --- signals at random moments ----------------------------------------------------------------

SCHEDULE = "time_s,throttle_pct,state\n0,0,run\n2,40\n4,80\n30,0,standby\n"
COMMANDS = {
    "monitor": (["monitor"], False),
    "send --for": (["send", "control", "--state", "run", "--throttle", "30", "--for", "30", "--yes"], True),
    "profile": (["profile", "{schedule}", "--yes"], True),
}


def _wait_for_rows(path, proc, timeout=30.0):
    """Until ``path`` holds a header and a first record (the readiness signal), or fail."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            with open(path, "rb") as f:
                if f.read().count(b"\n") >= 2:
                    return
        except FileNotFoundError:
            pass
        if proc.poll() is not None:
            pytest.fail(f"exited {proc.returncode} before its first record: {proc.stderr.read()}")
        time.sleep(0.01)
    pytest.fail(f"no record in {path} within {timeout} s")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("what", list(COMMANDS))
def test_signal_at_a_random_moment(start_sim, tmp_path, what, sig):
    url, _ = start_sim(["zk", "--speed", SPEED, "--pty"])
    schedule = tmp_path / "run.csv"
    schedule.write_text(SCHEDULE)
    args, controls = COMMANDS[what]
    out = tmp_path / "log.csv"
    p = subprocess.Popen([executable("zk"), *(a.replace("{schedule}", str(schedule)) for a in args),
                          "-p", url, "-o", str(out)], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=clean_env())
    _wait_for_rows(out, p)                   # ready: the session has written its first record
    moment = random.Random(f"{what}{sig}").uniform(0.0, 0.5)
    time.sleep(moment)                       # then a random moment of the run
    p.send_signal(sig)
    _, err = p.communicate(timeout=15)
    assert p.returncode == (130 if sig == signal.SIGINT else 143), (moment, err)
    assert "Traceback" not in err
    if controls:
        why = "interrupted" if sig == signal.SIGINT else "terminated"
        assert f"{why}: sent " in err, (moment, err)
    if out.exists() and out.stat().st_size:
        whole_records(out, "csv")


# --- replies late, garbled, colliding ---------------------------------------------------------

@pytest.mark.parametrize("sim_args,load_args,code,needle", [
    (["--ids", "1", "--fault", "1:delay=80"], ["--timeout", "0.02", "--retries", "0"], 3, "no reply"),
    (["--ids", "1", "--fault", "1:corrupt"], [], 6, "checksum"),
    (["--ids", "1@115200"], [], 3, "no reply"),
], ids=["late", "corrupt", "other-baud"])
def test_bad_replies(start_sim, sim_args, load_args, code, needle):
    url, _ = start_sim(["zap", *sim_args, "--pty"])
    r = run("zap", "load", "present-position", "--id", "1", "-p", url, *load_args)
    assert r.returncode == code, r.stderr
    assert r.stdout == ""
    assert needle in r.stderr.lower() and "Traceback" not in r.stderr
    assert len(r.stderr.splitlines()) == 1
