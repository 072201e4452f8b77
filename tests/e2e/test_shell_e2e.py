"""``zkzap shell``: scripted through a pipe, and interactive in a real terminal (tmux) with
completion and history."""

from __future__ import annotations

import shlex
import shutil
import subprocess
import time
import uuid

import pytest

from .conftest import clean_env, executable


def test_piped_lines_run_over_one_port(start_sim, sh):
    url, _ = start_sim(["zap", "--ids", "1", "--pty", "--speed", "10"])
    text = "store goal-speed 700 --id 1\nload goal-speed --id 1\nmove 800 --id 1 --wait\nhelp\nscan --ids 0-2 -f csv\n"
    r = sh("zkzap", "shell", "zap", "-p", url, input=text)
    assert r.exit_code == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[:2] == ["700", "800"]
    assert any(line.startswith("  set-baud") for line in lines)
    assert "id,baud,model,firmware,return_mode,status,errors" in lines
    r = sh("zkzap", "shell", "zap", "-p", url, input="echo --id 5 --retries 0\nload id -p /dev/null\nbatch x\n")
    assert r.exit_code == 2
    assert "zap: error: no reply from ID 5" in r.stderr
    assert "zap: error: -p: the port is the shell's" in r.stderr and "zap: error: batch: not in a shell" in r.stderr


def test_zk_shell_piped(start_sim, sh):
    url, _ = start_sim(["zk", "--pty", "--speed", "20"])
    r = sh("zkzap", "shell", "zk", "-p", url, input="send keepalive\nmonitor --count 3 --ids 1 -f csv\nexit\n")
    assert r.exit_code == 0, r.stderr
    assert len(r.stdout.splitlines()) == 4 and r.stdout.startswith("time,t,id,")


def test_zk_shell_latches_a_trip_until_acknowledged_and_the_engine_is_cool(start_sim, sh):
    url, _ = start_sim(["zk", "--pty", "--speed", "20"])
    run = "send control --state run --throttle {} --for 20 --ids 1 -f jsonl --yes"
    text = "\n".join([run.format(40) + " --limit 'egt_c<=500'",     # trips; the rundown is recorded
                       run.format(10),                                 # refused: the alarm is latched
                       "alarms", "ack",
                       run.format(10),                                 # refused: setpoint 0 after a trip
                       "send control --state run --throttle 0 --for 0.5 --ids 1 -f jsonl --yes",   # allowed
                       "alarms", "ack", "exit"]) + "\n"
    r = sh("zkzap", "shell", "zk", "-p", url, input=text)
    err = r.stderr
    assert "error: limit violated: egt_c=" in err and "rundown recorded:" in err
    assert "zk: error: start refused: alarm latched: limit egt_c<=500 violated: egt_c=" in err
    assert "LATCHED" in r.stdout and "acknowledged 1 alarm" in err
    assert "zk: error: start refused: after a trip the engine starts at setpoint 0 (asked 10)" in err
    assert err.count("zk: error: start refused") == 2 and "interrupted" not in err
    assert r.stdout.count('"kind":"trip"') == 1 and r.stdout.count('"kind":"rundown"') == 1


class Terminal:
    def __init__(self, argv, env, width=100, height=30):
        self.socket = f"zkzap-shell-{uuid.uuid4().hex[:8]}"
        shell = " ".join(f"{k}={shlex.quote(v)}" for k, v in env.items()
                         if k in ("PATH", "HOME", "LANG", "NO_COLOR", "ZKZAP_HISTORY", "PYTHONPATH"))
        line = f"env {shell} {shlex.join(argv)}; echo EXIT=$?; sleep 600"
        self.tmux("-f", "/dev/null", "-u", "new-session", "-d", "-x", str(width), "-y", str(height), "-s", "t", line)

    def tmux(self, *args):
        return subprocess.run(["tmux", "-L", self.socket, *args], capture_output=True, text=True, timeout=10,
                              check=True).stdout

    def screen(self):
        return self.tmux("capture-pane", "-p", "-t", "t")

    def wait_for(self, needle, timeout=15.0):
        deadline = time.monotonic() + timeout
        text = ""
        while time.monotonic() < deadline:
            text = self.screen()
            if needle in text.rstrip():
                return text
            time.sleep(0.05)
        raise AssertionError(f"timed out waiting for {needle!r}; the screen shows:\n{text}")

    def keys(self, *keys):
        self.tmux("send-keys", "-t", "t", "--", *keys)

    def close(self):
        subprocess.run(["tmux", "-L", self.socket, "kill-server"], capture_output=True, timeout=10)


@pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed (apt-get install tmux)")
def test_interactive_completion_and_history(start_sim, tmp_path):
    url, _ = start_sim(["zap", "--ids", "1", "--pty"])
    history = tmp_path / "history"
    env = clean_env(ZKZAP_HISTORY=str(history), HOME=str(tmp_path))
    term = Terminal([executable("zkzap"), "shell", "zap", "-p", url], env)
    try:
        term.wait_for("zap>")
        term.keys("lo", "Tab")                                    # a command
        term.wait_for("zap> load")
        term.keys("present-vo", "Tab")                            # a register name
        term.wait_for("zap> load present-voltage")
        term.keys("--ph", "Tab")                                  # an option
        term.wait_for("zap> load present-voltage --physical")
        term.keys("--id 1", "Enter")
        term.wait_for("12.0")
        term.keys("Up")                                           # history
        term.wait_for("zap> load present-voltage --physical --id 1")
        term.keys("C-u", "exit", "Enter")
        term.wait_for("EXIT=0")
    finally:
        term.close()
    assert "load present-voltage --physical --id 1" in history.read_text()


@pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed (apt-get install tmux)")
def test_interactive_ctrl_c_stops_the_command_and_keeps_the_shell(start_sim, tmp_path):
    """Ctrl-C during a command stops it after its current transaction and returns to the
    prompt, every time (not only the first); Ctrl-C at the prompt drops the half-typed line."""
    url, _ = start_sim(["zap", "--ids", "1", "--pty"])
    env = clean_env(ZKZAP_HISTORY=str(tmp_path / "history"), HOME=str(tmp_path))
    term = Terminal([executable("zkzap"), "shell", "zap", "-p", url], env)
    try:
        term.wait_for("zap>")
        for _ in range(2):
            term.keys("C-l")                                      # a clear screen for each round
            term.wait_for("zap>")
            term.keys("echo --id 1 --count 0 --interval 0.2", "Enter")
            term.wait_for("reply from ID 1: seq=3")               # it runs
            term.keys("C-c")
            term.wait_for("answered", timeout=30)                  # echo's own summary on Ctrl-C
            term.wait_for("garbled; round trip", timeout=30)
            wait = time.monotonic() + 30
            while not term.screen().rstrip().endswith("zap>") and time.monotonic() < wait:
                time.sleep(0.05)
            assert term.screen().rstrip().endswith("zap>")          # back at the prompt
        term.keys("load present-pos", "C-c")                       # at the prompt: a fresh line
        term.keys("load present-voltage --physical --id 1", "Enter")
        screen = term.wait_for("12.0")
        assert "present-pos" not in screen.split("12.0")[-1]
        term.keys("C-l")
        term.wait_for("zap>")
        term.keys("echo --id 1 --count 0 --interval 0.2", "Enter")
        term.wait_for("reply from ID 1: seq=2")
        term.keys("C-c")                                           # the last command: interrupted
        term.wait_for("garbled; round trip", timeout=30)
        term.keys("exit", "Enter")
        term.wait_for("EXIT=")
        assert "EXIT=0" in term.screen()       # what was asked: exit; the Ctrl-C was asked for too
    finally:
        term.close()
