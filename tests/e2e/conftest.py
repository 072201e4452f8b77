"""End-to-end fixtures: ``zkzap sim ...`` as a real subprocess on a pty or a TCP socket.

``start_sim(args)`` runs ``zkzap sim ARGS...`` (``["zap", "--ids", "1,2"]``, ``["zk", "--speed",
"20"]`` plus a transport: ``transport`` gives ``["--pty"]`` or ``["--listen", "127.0.0.1:0"]``),
reads the port from its first stdout line and returns ``(url, process)``; every simulator still
running at the end of the test is stopped with SIGTERM. ``stop_sim(process)`` stops one early
and returns its exit status. The installed commands themselves run through the top-level
``sh`` fixture (``sh("zap", "scan", "-p", url)``).
"""

from __future__ import annotations

import os
import selectors
import shutil
import signal
import subprocess
import sys
import time

import pytest

TRANSPORTS = {"pty": ["--pty"], "socket": ["--listen", "127.0.0.1:0"]}


def executable(name: str) -> str:
    """Path of an installed command (next to this interpreter first); skip the test without it."""
    here = os.path.join(os.path.dirname(sys.executable), name)
    path = here if os.path.exists(here) else shutil.which(name)
    if path is None:
        pytest.skip(f"{name} is not installed (pip install -e .)")
    return path


def clean_env(**extra) -> dict:
    env = dict(os.environ, NO_COLOR="1", **extra)
    for var in ("ZKZAP_ZK_PORT", "ZKZAP_ZAP_PORT", "ZKZAP_ZK_BAUD", "ZKZAP_ZAP_BAUD", "ZKZAP_ZAP_RETURN_MODE",
                "ZKZAP_ZAP_LATENCY"):
        env.pop(var, None)
    return env


def read_first_line(proc, timeout: float) -> bytes:
    """The first line ``proc`` writes on its stdout pipe, read byte by byte (nothing after it is
    consumed) within ``timeout`` seconds; what came, without a newline, when it did not."""
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    line = b""
    deadline = time.monotonic() + timeout
    try:
        while not line.endswith(b"\n"):
            left = deadline - time.monotonic()
            if left <= 0 or not sel.select(left):
                break
            ch = os.read(proc.stdout.fileno(), 1)
            if not ch:
                break
            line += ch
    finally:
        sel.close()
    return line


def _first_line(proc, timeout: float) -> str:
    line = read_first_line(proc, timeout)
    if not line.endswith(b"\n"):
        proc.kill()
        _, err = proc.communicate(timeout=5)
        pytest.fail(f"simulator printed no port within {timeout} s (exit {proc.returncode}): "
                    f"{err.decode(errors='replace').strip()}")
    return line.decode().strip()


def stop_sim(proc, sig=signal.SIGTERM, timeout: float = 5.0) -> int:
    """Stop a simulator with ``sig``; its exit status (killed after ``timeout`` s)."""
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    for stream in (proc.stdout, proc.stderr):
        if stream is not None and not stream.closed:
            stream.close()
    return proc.returncode


@pytest.fixture(params=sorted(TRANSPORTS))
def transport(request):
    """The simulator's transport arguments: a pty, then a TCP socket on a free port."""
    return list(TRANSPORTS[request.param])


@pytest.fixture
def start_sim():
    started = []

    def start(args, *, timeout: float = 10.0):
        cmd = [executable("zkzap"), "sim", *args]
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                env=clean_env())
        started.append(proc)
        return _first_line(proc, timeout), proc

    yield start
    for proc in started:
        stop_sim(proc)


@pytest.fixture
def stop():
    return stop_sim
