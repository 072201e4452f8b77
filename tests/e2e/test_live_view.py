"""The live dashboard as a person sees it: ``zk monitor`` (and ``zk send ... --for``) in a real
terminal (a tmux pane, 100x32) against ``zkzap sim zk`` on a pseudo-terminal, read back from
tmux's screen. tmux is the terminal emulator: what it shows is what a pilot would see."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
import uuid

import pytest

pytest.importorskip("zkzap.commands.zk.monitor", reason="zk monitor is not in this build yet")
pytest.importorskip("zkzap.commands.sim", reason="zkzap sim is not in this build yet")
pytest.importorskip("zkzap.sim.zk_ecu", reason="the ECU simulator is not in this build yet")
if shutil.which("tmux") is None:
    pytest.skip("tmux is not installed (apt-get install tmux); it is the terminal these tests read",
                allow_module_level=True)

CLI = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "cli")
ENTRY = "from zkzap import commands; import sys; getattr(commands, sys.argv.pop(1))()"
COLOUR = re.compile(r"\x1b\[(?:[0-9;]*;)?(3[0-7]|9[0-7]|38;[0-9;]+)m")


def cmd(main, *args):
    return [sys.executable, "-c", ENTRY, main, *args]


def base_env(**extra):
    env = dict(os.environ, PYTHONPATH=CLI + os.pathsep + os.environ.get("PYTHONPATH", ""))
    for var in ("NO_COLOR", "FORCE_COLOR", "COLUMNS", "LINES", "ZKZAP_ZK_PORT", "ZKZAP_ZK_BAUD", "ZKZAP_DEBUG"):
        env.pop(var, None)
    env.update(extra)
    return env


@pytest.fixture
def sim():
    """Start ``zkzap sim zk ARGS`` on a pty; returns its path. Stopped (by PID) at the end."""
    procs = []

    def start(*args):
        p = subprocess.Popen(cmd("main", "sim", "zk", *args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             env=base_env())
        procs.append(p)
        line = p.stdout.readline().decode().strip()
        assert line.startswith("/dev/"), f"simulator did not start: {line!r} {p.stderr.read1(4096)!r}"
        return line, p

    yield start
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                p.kill()


class Terminal:
    """A detached tmux session running one command; ``screen()`` is what it shows."""

    def __init__(self, argv, env, width=100, height=32):
        self.socket = f"zkzap-test-{uuid.uuid4().hex[:8]}"
        shell = " ".join(f"{k}={shlex.quote(v)}" for k, v in env.items() if k in
                         ("PYTHONPATH", "NO_COLOR", "PATH", "HOME", "LANG", "LC_ALL"))
        line = f"env {shell} {shlex.join(argv)}; echo EXIT=$?; sleep 600"
        self.tmux("-f", "/dev/null", "-u", "new-session", "-d", "-x", str(width), "-y", str(height), "-s", "t", line)

    def tmux(self, *args):
        return subprocess.run(["tmux", "-L", self.socket, *args], capture_output=True, text=True, timeout=10,
                              check=True).stdout

    def screen(self, escapes=False) -> str:
        return self.tmux("capture-pane", "-p", *(["-e"] if escapes else []), "-t", "t")

    def wait_for(self, predicate, timeout=15.0, what="the screen"):
        deadline = time.monotonic() + timeout
        text = ""
        while time.monotonic() < deadline:
            text = self.screen()
            try:
                if predicate(text):
                    return text
            except AssertionError:      # caught mid-redraw: look again
                pass
            time.sleep(0.1)
        raise AssertionError(f"timed out waiting for {what}; the screen shows:\n{text}")

    def keys(self, *keys):
        self.tmux("send-keys", "-t", "t", *keys)

    def close(self):
        subprocess.run(["tmux", "-L", self.socket, "kill-server"], capture_output=True, timeout=10)


@pytest.fixture
def terminal():
    opened = []

    def open_(argv, **env):
        t = Terminal(argv, base_env(**env))
        opened.append(t)
        return t

    yield open_
    for t in opened:
        t.close()


def link_numbers(screen):
    m = re.search(r"Link\s+([\d.]+) frames/s\s+([\d,]+) frames\s+CRC errors (\d+)", screen)
    assert m, screen
    return float(m.group(1)), int(m.group(2).replace(",", "")), int(m.group(3))


def row(screen, label):
    m = re.search(rf"(?:│ |  ){label}\s+(.+?)(?:\s{{2,}}|\s*│)", screen)
    assert m, f"no {label!r} row in:\n{screen}"
    return m.group(1)


def test_monitor_dashboard_on_a_terminal(sim, terminal):
    port, proc = sim("--speed", "5")
    term = terminal(cmd("zk_main", "monitor", "-p", port))
    screen = term.wait_for(lambda s: "protocol v6 (from the ECU)" in s and re.search(r"[1-9][\d,]* frames ", s),
                           what="the dashboard with frames counted")
    assert f"ZK ECU on {port}" in screen
    assert row(screen, "State") == "STOP"
    assert row(screen, "Error") == "none"
    assert row(screen, "RPM").startswith("0 rpm")
    assert row(screen, "EGT") == "20 °C"                              # the simulator's ambient
    assert row(screen, "Battery") == "12.0 V"
    assert "160,000 rpm" in screen and "40,000 rpm" in screen        # max and idle from IDs 6 and 8
    assert re.search(r"RPM 20 s\s+▄+\s+0\.\.0 rpm", screen)           # a flat sparkline
    rate, frames, crc = link_numbers(screen)
    assert rate > 0 and frames > 0 and crc == 0
    assert "STALE" not in screen and "Traceback" not in screen
    # colour: the 'none' error in green, the frame in blue
    coloured = term.screen(escapes=True)
    assert re.search(r"\x1b\[32m\S*\s*none", coloured) or re.search(r"\x1b\[32mnone", coloured), coloured
    # the frame counter moves
    term.wait_for(lambda s: link_numbers(s)[1] > frames, timeout=5, what="more frames")

    # the simulator goes away: the last view stays, one line says why, exit status 4
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=5)
    screen = term.wait_for(lambda s: "EXIT=" in s, what="the monitor to exit")
    assert "EXIT=4" in screen
    assert "zk: error: port" in screen
    assert "╰" in screen and "Traceback" not in screen


def test_no_color_keeps_the_screen_but_drops_colour(sim, terminal):
    port, _ = sim("--speed", "5")
    term = terminal(cmd("zk_main", "monitor", "-p", port), NO_COLOR="1")
    term.wait_for(lambda s: "protocol v6" in s, what="the dashboard")
    coloured = term.screen(escapes=True)
    assert "STOP" in coloured and "Battery" in coloured
    assert not COLOUR.search(coloured), repr(COLOUR.search(coloured))


def test_silent_ecu_turns_the_view_stale_then_exits_3(sim, terminal):
    port, proc = sim("--speed", "5")
    term = terminal(cmd("zk_main", "monitor", "-p", port, "--timeout", "1.5"))
    term.wait_for(lambda s: "protocol v6" in s and link_numbers(s)[1] > 0, what="frames")
    proc.send_signal(signal.SIGSTOP)            # the ECU falls silent; its port stays open
    try:
        screen = term.wait_for(lambda s: "STALE: no status frames for" in s, what="the stale banner")
        assert re.search(r"last frame \d+\.\d s ago", screen)
        assert link_numbers(screen)[0] < 100      # the rate falls as the silence lasts
        screen = term.wait_for(lambda s: "EXIT=" in s, what="the monitor to give up")
    finally:
        proc.send_signal(signal.SIGCONT)
    assert "EXIT=3" in screen
    assert "fell silent" in screen or "no status frame" in screen
    assert "Traceback" not in screen


def test_running_engine_under_zk_send_for_and_ctrl_c(sim, terminal):
    port, _ = sim("--speed", "20")
    term = terminal(cmd("zk_main", "send", "control", "--state", "run", "--throttle", "60", "--for", "0",
                        "-p", port, "--yes"))
    screen = term.wait_for(lambda s: "RUNNING" in s and re.search(r"RPM\s+1\d\d,\d{3} rpm", s), timeout=20,
                           what="the engine running above 100,000 rpm")
    assert row(screen, "Host") == "run"
    assert re.search(r"█+░* \d+ %", screen)                          # the rpm gauge
    assert re.search(r"RPM 20 s\s+[▁▂▃▄▅▆▇█]*▁[▁▂▃▄▅▆▇█]*█", screen)    # the climb in the sparkline
    egt = int(re.search(r"EGT\s+(\d+) °C", screen).group(1))
    assert egt > 300
    coloured = term.screen(escapes=True)
    assert re.search(r"\x1b\[(?:1;)?32m\S*RUNNING|\x1b\[32mRUNNING", coloured), coloured
    term.keys("C-c")
    screen = term.wait_for(lambda s: "EXIT=" in s, what="Ctrl-C to end the run")
    assert "EXIT=130" in screen and "Traceback" not in screen


def test_after_ctrl_c_the_abort_notice_and_the_last_view_stay_on_screen(sim, terminal):
    port, _ = sim("--speed", "20")
    term = terminal(cmd("zk_main", "send", "control", "--state", "run", "--throttle", "40", "--for", "0",
                        "-p", port, "--yes"))
    term.wait_for(lambda s: "RUNNING" in s or "IGNITION" in s or "PREHEAT" in s, timeout=20,
                  what="the engine starting")
    term.keys("C-c")
    screen = term.wait_for(lambda s: "EXIT=" in s, what="Ctrl-C to end the run")
    assert "EXIT=130" in screen and "Traceback" not in screen
    assert "note: interrupted: sent standby, throttle 0" in screen, screen
    lines = [ln for ln in screen.splitlines() if ln.strip()]
    assert len(lines) == len(set(lines)) or screen.count("╭") == 1, screen    # one view, not copies
    assert screen.count("╭") == 1 and screen.count("╰") == 1, screen
    assert screen.index("note: interrupted") < screen.index("╭"), screen       # the notice above it
    assert "note: rundown recorded" in screen, screen                            # the rundown was recorded
    assert "elapsed" in screen, screen


def test_a_limit_warning_stays_on_screen_above_the_live_view(sim, terminal, tmp_path):
    port, _ = sim("--speed", "10")
    term = terminal(cmd("zk_main", "send", "control", "--state", "run", "--throttle", "40", "--for", "60",
                        "-p", port, "--yes", "--limit", "egt_c<=900,warn=300", "--on-limit", "warn",
                        "-o", str(tmp_path / "d.csv")))
    screen = term.wait_for(lambda s: "note: limit warning: egt_c=" in s, timeout=30, what="the warning")
    elapsed = re.compile(r"elapsed ([0-9.]+) s")
    then = float(elapsed.search(screen).group(1))
    screen = term.wait_for(lambda s: elapsed.search(s) and float(elapsed.search(s).group(1)) > then + 2,
                           what="the view redrawn since the warning")
    assert "note: limit warning: egt_c=" in screen, screen
    assert screen.index("note: limit warning") < screen.index("╭"), screen     # above the view, not under it
    assert screen.count("╭") == 1 and screen.count("╰") == 1, screen          # no fragments of old views
    term.keys("C-c")
    term.wait_for(lambda s: "EXIT=" in s, what="Ctrl-C to end the run")
