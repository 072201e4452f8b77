"""A command in a real terminal (``from tmuxterm import run_in_terminal``): a detached tmux
pane of a given size runs it to its end; what the pane shows (its scrollback included) is what
a person at a terminal of that width would read."""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
import time
import uuid

CLI = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cli")
ENTRY = "from zkzap import commands; import sys; getattr(commands, sys.argv.pop(1))()"


def have_tmux() -> bool:
    return shutil.which("tmux") is not None


def zk(*args):
    """``zk ARGS`` as an argv of the source tree's package."""
    return [sys.executable, "-c", ENTRY, "zk_main", *args]


def run_in_terminal(argv, width=80, height=50, timeout=60.0, cwd=None):
    """Run ``argv`` in a ``width`` x ``height`` tmux pane (NO_COLOR unset, no COLUMNS) until it
    exits; ``(exit status, the lines it left, trailing blanks dropped)``."""
    socket = f"zkzap-term-{uuid.uuid4().hex[:8]}"
    env = dict(os.environ, PYTHONPATH=CLI + os.pathsep + os.environ.get("PYTHONPATH", ""))
    keep = " ".join(f"{k}={shlex.quote(v)}" for k, v in env.items() if k in ("PYTHONPATH", "PATH", "HOME", "LANG",
                                                                             "LC_ALL"))
    where = f"cd {shlex.quote(str(cwd))} && " if cwd else ""
    line = f"{where}env -u NO_COLOR -u COLUMNS -u LINES {keep} {shlex.join(argv)}; echo EXIT=$?; sleep 600"

    def tmux(*args):
        return subprocess.run(["tmux", "-L", socket, *args], capture_output=True, text=True, timeout=10,
                              check=True).stdout

    tmux("-f", "/dev/null", "-u", "new-session", "-d", "-x", str(width), "-y", str(height), "-s", "t", line)
    try:
        deadline = time.monotonic() + timeout
        while True:
            text = tmux("capture-pane", "-p", "-S", "-", "-t", "t")     # the scrollback too
            lines = text.rstrip("\n").splitlines()
            status = next((ln for ln in reversed(lines) if ln.startswith("EXIT=")), None)
            if status is not None:
                body = lines[:lines.index(status)]
                while body and not body[-1].strip():
                    body.pop()
                while body and not body[0].strip():
                    body.pop(0)
                return int(status[5:]), body
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out: {shlex.join(argv)}; the screen shows:\n{text}")
            time.sleep(0.1)
    finally:
        subprocess.run(["tmux", "-L", socket, "kill-server"], capture_output=True, timeout=10)
