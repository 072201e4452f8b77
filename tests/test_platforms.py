"""zkzap on a system without POSIX-only modules (Windows): every command that should work does,
the rest refuse with a clear message.

The CLI runs in a subprocess whose ``import`` refuses termios, pty, fcntl, tty, resource, grp and
pwd whenever the importer is a zkzap module (pyserial's own POSIX backend may still import them on
this Linux machine; on Windows pyserial uses its win32 backend instead).
"""

import os
import subprocess
import sys

import pytest

from e2e.conftest import read_first_line

CLI = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cli")
POSIX_ONLY = ("termios", "pty", "fcntl", "tty", "resource", "grp", "pwd")

BOOT = f"""
import builtins, sys
_real = builtins.__import__
BLOCKED = {POSIX_ONLY!r}
def _guard(name, globals=None, locals=None, fromlist=(), level=0):
    importer = (globals or {{}}).get("__name__") or ""
    if level == 0 and name.split(".")[0] in BLOCKED and importer.split(".")[0] == "zkzap":
        raise ImportError(f"No module named {{name!r}} (not on this platform)", name=name)
    return _real(name, globals, locals, fromlist, level)
builtins.__import__ = _guard
prog = sys.argv[1]
sys.argv = sys.argv[1:]
from zkzap import commands
{{"zkzap": commands.main, "zk": commands.zk_main, "zap": commands.zap_main}}[prog]()
"""


def env():
    e = dict(os.environ, NO_COLOR="1", PYTHONPATH=CLI + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return e


def run(*args, input=None, timeout=60):
    p = subprocess.run([sys.executable, "-c", BOOT, *args], capture_output=True, text=True, env=env(),
                       input=input, timeout=timeout)
    return p


def test_the_guard_refuses_zkzap_but_not_others():
    p = subprocess.run([sys.executable, "-c", BOOT.replace("from zkzap import commands", "import termios\n"
                        "import zkzap.sim.serve as s\ntry:\n    s._termios()\nexcept s.PtyUnsupported as e:\n"
                        "    print('refused:', e)\nraise SystemExit(0)"), "zkzap"],
                       capture_output=True, text=True, env=env(), timeout=60)
    assert p.returncode == 0, p.stderr
    assert "refused: a pseudo-terminal needs a POSIX system" in p.stdout


@pytest.mark.parametrize("args, out", [
    (["zk", "send", "control", "--state", "run", "--throttle", "50", "-n"], "FF 1D F4 70\n"),
    (["zap", "store", "goal-position", "2047", "--id", "1", "-n"], "FF FF FF 01 05 F3 86 FF 07 7A\n"),
    (["zkzap", "crc", "zk", "14", "64"], "D3\n"),
    (["zk", "decode", "FF", "1D", "F4", "70", "-f", "csv"], None),
    (["zap", "decode", "FF FF FF 00 02 F1 0C"], None),
    (["zk", "states", "-f", "csv"], None),
    (["zap", "registers", "-f", "jsonl"], None),
    (["zk", "fields", "--kind", "status", "--id", "6", "-f", "csv"], None),
    (["zkzap", "completion", "bash"], None),
    (["zkzap", "ports", "-f", "jsonl"], None),
    (["zk", "profile", "--example"], None),
    (["zk", "monitor", "-p", "sim://zk?speed=10", "--count", "3", "-f", "jsonl"], None),
    (["zap", "scan", "--sim", "--sim-ids", "1,2", "--ids", "0-3", "-f", "csv"], None),
    (["zk", "detect", "-p", "sim://zk?baud=9600&speed=10", "-f", "json"], None),
])
def test_commands_run_without_posix_modules(args, out):
    p = run(*args)
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr
    if out is not None:
        assert p.stdout == out


def test_a_pty_simulator_says_it_needs_posix():
    p = run("zkzap", "sim", "zk", "--pty")
    assert p.returncode == 2 and p.stdout == ""
    assert "--pty: a pseudo-terminal needs a POSIX system" in p.stderr and "--listen" in p.stderr


def _first_line(proc, timeout=20.0):
    return read_first_line(proc, timeout).decode().strip()


@pytest.mark.parametrize("kind, client", [
    ("zk", ["zk", "monitor", "--count", "4", "-f", "jsonl"]),
    ("zap", ["zap", "echo", "--id", "1", "--count", "3", "-f", "jsonl"]),
])
def test_tcp_simulators_and_socket_ports_without_posix_modules(kind, client):
    extra = ["--ids", "1"] if kind == "zap" else []
    sim = subprocess.Popen([sys.executable, "-c", BOOT, "zkzap", "sim", kind, "--listen", "127.0.0.1:0",
                            "--speed", "5", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           stdin=subprocess.DEVNULL, env=env())
    try:
        url = _first_line(sim)
        assert url.startswith("socket://127.0.0.1:"), sim.stderr.read1(4000) if url == "" else url
        p = run(*client, "-p", url)
        assert p.returncode == 0, p.stderr
        assert len(p.stdout.splitlines()) >= 3
    finally:
        sim.terminate()
        sim.wait(10)
        sim.stdout.close()
        sim.stderr.close()
    assert sim.returncode == 0


def test_windows_and_macos_line_endings_and_port_names():
    # CRLF text (Notepad) decodes like LF text
    p = run("zk", "decode", "-f", "csv", input="FF 1D F4 70\r\nF1 00 00 00 00 4C A0\r\n")
    assert p.returncode == 0, p.stderr
    assert len(p.stdout.splitlines()) == 3 and "\r" not in p.stdout
    p = run("zk", "profile", "-", "-n", "-f", "csv", input="time_s,throttle_pct,state\r\n0,0,run\r\n10,40\r\n")
    assert p.returncode == 0, p.stderr
    from zkzap.link.adapters import hints_for, outgoing_port_hint

    assert outgoing_port_hint("/dev/tty.usbserial-A1", "darwin").endswith(
        "use /dev/cu.usbserial-A1 for an outgoing connection")
    assert outgoing_port_hint("/dev/cu.usbserial-A1", "darwin") is None
    assert outgoing_port_hint("COM3", "win32") is None and outgoing_port_hint(r"\\.\COM10", "win32") is None
    rec = {"name": "COM3", "device": "COM3", "vid": 0x0403, "latency_timer_ms": None, "permission": None}
    assert "Advanced > Latency Timer" in hints_for(rec, platform="win32")[0]
    rec = {"name": "cu.wchusbserial1", "device": "/dev/cu.wchusbserial1", "vid": 0x1A86, "latency_timer_ms": None,
           "permission": True}
    assert "vendor driver" in hints_for(rec, platform="darwin")[0]


def test_windows_port_names_reach_pyserial_untouched(cli):
    # a COM name is a device name like any other: opening it here fails as a missing device would
    for name in ("COM3", r"\\.\COM10"):
        r = cli("zap", "echo", "--id", "1", "-p", name)
        assert r.exit_code == 4 and r.stdout == "" and name in r.stderr
