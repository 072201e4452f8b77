"""Shared fixtures: the CLI through CliRunner and as installed subprocesses."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys

import pytest

from click.testing import CliRunner

# A suite started in the background of a non-interactive shell inherits SIGINT ignored, and so
# would every program it starts (zkzap, like any program, leaves an ignored signal ignored):
# the tests that send Ctrl-C to a program need it to arrive.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# Run the source tree's package even when the tests are run without an install.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cli"))
# Helpers shared by the test modules (``from cmdtree import commands``).
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from zkzap.commands import root, run  # noqa: E402

#: ``pytester``: tests of zkzap's pytest plugin run pytest on a test file of their own.
pytest_plugins = ("pytester",)

#: Variables that change zkzap's behaviour or its output's look: none of the developer's (or
#: CI's) values may reach a test. A test that wants one sets it itself.
LEAKY = ("NO_COLOR", "FORCE_COLOR", "COLUMNS", "LINES", "TERM_PROGRAM", "CLICOLOR", "CLICOLOR_FORCE")


@pytest.fixture(autouse=True)
def hermetic(monkeypatch):
    """Every test runs without the caller's ZKZAP_* and colour/terminal-size variables, so
    ``ZKZAP_DEBUG=1`` or ``ZKZAP_ZAP_RETURN_MODE=0`` in a developer's shell changes nothing."""
    for var in list(os.environ):
        if var.startswith("ZKZAP_") or var in LEAKY:
            monkeypatch.delenv(var, raising=False)
    # what one test's buses learned of a port's latencies is not the next test's (pty paths repeat)
    from zkzap.link import zap_timing

    monkeypatch.setattr(zap_timing, "_POLICIES", {})


class Result:
    def __init__(self, code, out, err):
        self.exit_code, self.stdout, self.stderr = code, out, err

    def __repr__(self):
        return f"Result(exit={self.exit_code}, stdout={self.stdout!r}, stderr={self.stderr!r})"


@pytest.fixture
def cli(monkeypatch):
    """Invoke ``zkzap ARGS...`` in-process with zkzap's error handling; returns exit/stdout/stderr."""
    monkeypatch.setenv("NO_COLOR", "1")

    def invoke(*args, input=None):
        runner = CliRunner()
        with runner.isolation(input=input) as streams:
            code = run(root, "zkzap", list(args))
            out, err = streams[0].getvalue(), streams[1].getvalue()
        return Result(code, out.decode(), err.decode())

    return invoke


def _exe(name):
    here = os.path.dirname(sys.executable)
    path = os.path.join(here, name)
    return path if os.path.exists(path) else shutil.which(name)


@pytest.fixture
def sh():
    """Run an installed command (zkzap, zk, zap) as a real subprocess."""
    env = dict(os.environ, NO_COLOR="1")

    def call(name, *args, input=None, timeout=30):
        exe = _exe(name)
        if exe is None:
            pytest.skip(f"{name} is not installed (pip install -e .)")
        p = subprocess.run([exe, *args], input=input, capture_output=True, timeout=timeout, env=env,
                           text=isinstance(input, str) or input is None)
        return Result(p.returncode, p.stdout, p.stderr)

    return call
