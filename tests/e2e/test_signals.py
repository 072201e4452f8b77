"""Signals at any moment, as the installed programs get them: during start-up, twice, during a
wait, at a consent prompt. Every case waits for a readiness line (an import trace, a record, a
note), never a fixed sleep."""

from __future__ import annotations

import os
import pty
import select
import signal
import subprocess
import threading
import time

import pytest

from .conftest import clean_env, executable

EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143}
SIGS = [signal.SIGINT, signal.SIGTERM]
SIG_IDS = ["SIGINT", "SIGTERM"]


def spawn(argv, **env):
    """Start an installed program; a watchdog kills it after 60 s so a hang fails, not blocks."""
    proc = subprocess.Popen([executable(argv[0]), *argv[1:]], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=clean_env(**env))
    watchdog = threading.Timer(60, proc.kill)
    watchdog.daemon = True
    watchdog.start()
    return proc


def wait_line(stream, predicate, timeout=20.0):
    """Read lines of ``stream`` until one satisfies ``predicate``; returns the lines read."""
    lines = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = stream.readline()
        if not line:
            break
        lines.append(line)
        if predicate(line):
            return lines
    raise AssertionError(f"no readiness line; got {lines!r}")


def finish(proc, timeout=20):
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


# --- during start-up ---------------------------------------------------------------------------

STARTING = [
    ["zk", "monitor", "--sim", "--duration", "600", "-f", "jsonl"],
    ["zap", "echo", "--id", "1", "--count", "0", "--sim"],
    ["zkzap", "sim", "zk"],
]


@pytest.mark.parametrize("delay", [0.0, 0.003, 0.015], ids=["at-once", "3ms", "15ms"])
@pytest.mark.parametrize("sig", SIGS, ids=SIG_IDS)
@pytest.mark.parametrize("argv", STARTING, ids=[" ".join(a[:2]) for a in STARTING])
def test_a_signal_during_start_up_exits_quietly(argv, sig, delay):
    """Once the zkzap package is imported (the import trace says so), the handlers are in place:
    a signal while click and the command modules load ends the process at once, with 130/143 and
    nothing but the trace on stderr — no traceback, and the command never starts logging."""
    proc = spawn(argv, PYTHONPROFILEIMPORTTIME="1")
    wait_line(proc.stderr, lambda line: line.split("|")[-1].strip() == "zkzap")
    if delay:
        time.sleep(delay)      # a point later in the start-up, not a wait for readiness
    proc.send_signal(sig)
    code, out, err = finish(proc)
    if argv[0] == "zkzap" and out.strip():
        # the simulator had announced its port (this test read the trace late, on a loaded
        # machine): the signal came after start-up, and ends the simulator as it always does
        assert code == 0, err
    else:
        assert code == EXIT[sig], err
    rest = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("import time:")]
    assert not any("Traceback" in ln or "KeyboardInterrupt" in ln or "error" in ln for ln in rest), rest
    assert len(out.splitlines()) <= 1         # a simulator may have printed its port line


# --- twice, as timeout(1) does ---------------------------------------------------------------------

@pytest.mark.parametrize("argv", [
    ["zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "0", "--sim", "-f", "jsonl"],
    ["zk", "monitor", "--sim", "-f", "jsonl"],
], ids=["send-for", "monitor"])
@pytest.mark.parametrize("sig", SIGS, ids=SIG_IDS)
def test_a_repeated_signal_changes_nothing(argv, sig):
    proc = spawn(argv)
    wait_line(proc.stdout, lambda line: line.startswith("{"))
    proc.send_signal(sig)
    proc.send_signal(sig)
    code, _, err = finish(proc)
    assert code == EXIT[sig], err
    assert "zk: error" not in err and "note: error" not in err and "Traceback" not in err
    if argv[1] == "send":
        why = "interrupted" if sig == signal.SIGINT else "terminated"
        assert f"note: {why}: sent standby, throttle 0" in err


# --- zap: summaries and safe ends ----------------------------------------------------------------

@pytest.mark.parametrize("sig", SIGS, ids=SIG_IDS)
def test_zap_echo_until_interrupted_ends_with_its_summary_and_the_signal_status(sig):
    proc = spawn(["zap", "echo", "--id", "1", "--count", "0", "--interval", "0.01", "--sim"])
    wait_line(proc.stdout, lambda line: line.startswith("reply from ID 1: seq=1"))
    proc.send_signal(sig)
    code, _, err = finish(proc)
    assert code == EXIT[sig]
    assert " sent, " in err and " answered, 0 lost, 0 garbled; round trip min/avg/max " in err
    assert "Traceback" not in err


@pytest.mark.parametrize("sig", SIGS, ids=SIG_IDS)
def test_zap_scan_interrupted_says_what_it_found(sig):
    proc = spawn(["zap", "scan", "-p", "sim://zap?ids=0,200", "-b", "all", "--timeout", "0.05", "-f", "jsonl"])
    wait_line(proc.stdout, lambda line: '"id":0' in line)
    proc.send_signal(sig)
    code, _, err = finish(proc)
    assert code == EXIT[sig], err
    assert "interrupted after " in err and " found so far" in err and "Traceback" not in err


@pytest.mark.parametrize("no_stop", [False, True], ids=["stops", "no-stop"])
@pytest.mark.parametrize("sig", SIGS, ids=SIG_IDS)
def test_zap_move_wait_interrupted_stops_the_rod_where_it_is(tmp_path, sig, no_stop):
    state = tmp_path / "bus.json"
    argv = ["zap", "move", "3000", "--id", "1", "--speed", "20", "--wait", "--wait-timeout", "600", "-v",
            "-p", f"sim://zap?ids=1&state={state}"] + (["--no-stop"] if no_stop else [])
    proc = spawn(argv)
    wait_line(proc.stderr, lambda line: "moving from" in line)
    proc.send_signal(sig)
    code, out, err = finish(proc)
    assert code == EXIT[sig], err
    if no_stop:
        assert "keeps moving to its goal (--no-stop)" in err and out == ""
    else:
        assert "interrupted: ID 1 stopped at " in err and "(goal-position set to the present position)" in err
        # where the rod was left, on stdout as a finished move's position is; the simulator saves
        # the bus on close, and a stopped rod stays put
        stopped_at = int(err.split("stopped at ")[1].split()[0])
        assert out == f"{stopped_at}\n"
        r = subprocess.run([executable("zap"), "load", "present-position", "--id", "1", "-p",
                            f"sim://zap?ids=1&state={state}"], capture_output=True, text=True, env=clean_env())
        assert abs(int(r.stdout) - stopped_at) <= 2, (r.stdout, err)


# --- a consent prompt --------------------------------------------------------------------------

def _prompt(answer: bytes):
    """Run a hazardous command on a terminal (a pty for stdin and stderr), answer the prompt."""
    master, slave = pty.openpty()
    proc = subprocess.Popen([executable("zk"), "send", "control", "--state", "run", "-p", "/dev/zkzap-none"],
                            stdin=slave, stdout=subprocess.PIPE, stderr=slave, env=clean_env())
    os.close(slave)
    seen = b""
    deadline = time.monotonic() + 20
    while b"Continue? [y/N]" not in seen and time.monotonic() < deadline:
        if select.select([master], [], [], 0.5)[0]:
            try:
                seen += os.read(master, 4096)
            except OSError:
                break
    assert b"Continue? [y/N]" in seen, seen
    if answer == b"SIGINT":
        proc.send_signal(signal.SIGINT)
    else:
        os.write(master, answer)
    proc.wait(timeout=20)
    rest = b""
    while select.select([master], [], [], 0.2)[0]:
        try:
            chunk = os.read(master, 4096)
        except OSError:
            break
        if not chunk:
            break
        rest += chunk
    os.close(master)
    return proc.returncode, proc.stdout.read(), (seen + rest).decode(errors="replace")


@pytest.mark.parametrize("answer,code,needle", [
    (b"\x04", 2, "not sent: no answer (end of input)"),     # Ctrl-D
    (b"n\n", 2, "not sent: consent refused"),
    (b"\n", 2, "not sent: consent refused"),                 # the default is no
    (b"SIGINT", 130, ""),
    (b"y\n", 4, "port /dev/zkzap-none"),                     # consented: then the port is tried
], ids=["ctrl-d", "no", "enter", "ctrl-c", "yes"])
def test_consent_prompt_answers(answer, code, needle):
    rc, out, screen = _prompt(answer)
    assert rc == code, screen
    assert out == b""
    assert needle in screen and "Traceback" not in screen
