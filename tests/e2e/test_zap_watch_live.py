"""``zap watch`` in a real terminal (a tmux pane): the live table per actuator as a person sees it."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import time
import uuid

import pytest

if shutil.which("tmux") is None:
    pytest.skip("tmux is not installed (apt-get install tmux); it is the terminal these tests read",
                allow_module_level=True)

CLI = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "cli")
ENTRY = "from zkzap import commands; import sys; getattr(commands, sys.argv.pop(1))()"


class Terminal:
    def __init__(self, argv, width=110, height=40):
        self.socket = f"zkzap-watch-{uuid.uuid4().hex[:8]}"
        env = dict(os.environ, PYTHONPATH=CLI + os.pathsep + os.environ.get("PYTHONPATH", ""))
        shell = " ".join(f"{k}={shlex.quote(v)}" for k, v in env.items() if k in ("PYTHONPATH", "PATH", "HOME",
                                                                                  "LANG", "LC_ALL"))
        line = f"env -u NO_COLOR {shell} {shlex.join(argv)}; echo EXIT=$?; sleep 600"
        self.tmux("-f", "/dev/null", "-u", "new-session", "-d", "-x", str(width), "-y", str(height), "-s", "t", line)

    def tmux(self, *args):
        return subprocess.run(["tmux", "-L", self.socket, *args], capture_output=True, text=True, timeout=10,
                              check=True).stdout

    def screen(self, escapes=False):
        return self.tmux("capture-pane", "-p", *(["-e"] if escapes else []), "-t", "t")

    def wait_for(self, predicate, timeout=20.0, what="the screen"):
        deadline = time.monotonic() + timeout
        text = ""
        while time.monotonic() < deadline:
            text = self.screen()
            if predicate(text):
                return text
            time.sleep(0.1)
        raise AssertionError(f"timed out waiting for {what}; the screen shows:\n{text}")

    def close(self):
        subprocess.run(["tmux", "-L", self.socket, "kill-server"], capture_output=True, timeout=10)


def test_watch_live_table_with_health_units_and_error_colour():
    port = "sim://zap?ids=1,2&faults=2:overload"
    argv = [sys.executable, "-c", ENTRY, "zap_main", "watch", "present-position", "present-voltage", "--ids", "1,2",
            "--rate", "20", "--duration", "30", "-p", port]
    term = Terminal(argv)
    try:
        screen = term.wait_for(lambda s: re.search(r"[1-9]\d* polls in", s) and "ID 2" in s, what="the live table")
        assert "20 Hz asked; wire limit" in screen
        assert re.search(r"present-voltage\s+│\s+12 V", screen), screen
        assert screen.count("errors none") == 1 and "errors overload" in screen, screen
        assert re.search(r"ID 1 .*│ \d+/\d+ ok, 0\.0% lost", screen), screen
        coloured = term.screen(escapes=True)
        assert re.search(r"\x1b\[[0-9;]*31m[^\x1b]*overload", coloured), coloured
        term.tmux("send-keys", "-t", "t", "C-c")
        screen = term.wait_for(lambda s: "EXIT=" in s, what="the watch to end")
        assert "EXIT=130" in screen and "Traceback" not in screen
        assert re.search(r"\d+ polls in [\d.]+ s: [\d.]+ polls/s \(asked 20", screen)
    finally:
        term.close()
