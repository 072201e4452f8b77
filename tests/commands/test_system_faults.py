"""System faults end in one clear line and the documented exit status, never a traceback:
stdout on a full disk (exit 7) for every kind of output, a raw log or -o on a full disk,
unreadable inputs, a simulator state file in a missing directory, malformed port URLs."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

FULL = "/dev/full"
needs_full = pytest.mark.skipif(not os.path.exists(FULL), reason="no /dev/full")


def _exe(name):
    return os.path.join(os.path.dirname(sys.executable), name)


def _run(argv, stdout=None, timeout=60):
    env = dict(os.environ, NO_COLOR="1")
    for k in list(env):
        if k.startswith("ZKZAP_"):
            del env[k]
    p = subprocess.run([_exe(argv[0]), *argv[1:]], stdout=stdout or subprocess.PIPE, stderr=subprocess.PIPE,
                       stdin=subprocess.DEVNULL, timeout=timeout, env=env)
    return p.returncode, p.stderr.decode("utf-8", "replace")


def _one_line(err):
    assert "Traceback" not in err, err
    lines = [x for x in err.splitlines() if not x.startswith("note:")]
    assert len(lines) == 1, err
    return lines[0]


STDOUT_KINDS = [
    "zk send control --state run --throttle 50 -n",
    "zk send raw 1 sw=3 throttle_pct=500 -n",
    "zap echo -n",
    "zap store goal-position 2047 --id 1 -n",
    "zkzap crc zk 14 64",
    "zkzap crc check FF 14 64 D3",
    "zk states",
    "zk errors -f csv",
    "zk fields -f json",
    "zap registers",
    "zkzap --help",
    "zk --help",
    "zap store --help",
    "zkzap --version",
    "zkzap completion bash",
    "zkzap completion zsh --prog zk",
    "zk profile --example",
    "zk decode FF 1D F4 70",
    "zap decode FF FF FF 00 02 F1 0C -f json",
    "zk monitor -p sim://zk?speed=20 --count 3",
    "zkzap ports",
]


@needs_full
@pytest.mark.parametrize("args", STDOUT_KINDS)
def test_stdout_on_a_full_disk_is_exit_7_in_one_line(args):
    with open(FULL, "w") as full:
        code, err = _run(args.split(), stdout=full)
    if args == "zkzap crc check FF 14 64 D3":       # writes to stderr only
        assert code == 0
        return
    if args == "zkzap ports" and code == 0:          # no port on this machine: nothing written
        return
    assert code == 7, err
    line = _one_line(err)
    assert "cannot write stdout: No space left on device" in line


@needs_full
@pytest.mark.parametrize("args", [
    "zk monitor -p sim://zk?speed=20 --count 5 -f jsonl --raw-log /dev/full",
    "zk send control --state stop --for 2 -p sim://zk?speed=20 -f jsonl --raw-log /dev/full",
    "zk monitor -p sim://zk?speed=20 --count 5 -o /dev/full -f csv",
    "zk decode FF 1D F4 70 -o /dev/full",
])
def test_a_file_output_on_a_full_disk_is_exit_7(args):
    code, err = _run(args.split(), stdout=subprocess.DEVNULL)
    assert code == 7, err
    assert "cannot write /dev/full: No space left on device" in err
    assert "Traceback" not in err


UNREADABLE = [
    ("zk decode --binary /proc/self/mem", "input: cannot read /proc/self/mem: Input/output error"),
    ("zap decode --binary /proc/self/mem", "input: cannot read /proc/self/mem: Input/output error"),
    ("zk monitor --replay /proc/self/mem --fast", "replay: cannot read /proc/self/mem: Input/output error"),
    ("zk decode --binary /nonexistent.bin", "input: cannot read /nonexistent.bin"),
    ("zk decode --binary /", "input: cannot read /"),
    ("zkzap sim zap --state /nonexistent/dir/bus.json", "state /nonexistent/dir/bus.json: cannot write"),
    ("zap echo -p sim://zap?state=/nonexistent/dir/bus.json", "state /nonexistent/dir/bus.json: cannot write"),
    ("zk monitor -p socket://127.0.0.1", "port: socket://127.0.0.1: expected socket://HOST:PORT"),
    ("zap echo -p socket://127.0.0.1", "port: socket://127.0.0.1: expected socket://HOST:PORT"),
    ("zk monitor -p socket://:5000", "expected socket://HOST:PORT"),
    ("zk monitor -p socket://host:port", "expected socket://HOST:PORT"),
    ("zap scan -p rfc2217://localhost", "expected rfc2217://HOST:PORT"),
]


@pytest.mark.parametrize("args,needle", UNREADABLE, ids=[a for a, _ in UNREADABLE])
def test_unreadable_inputs_and_bad_urls_are_one_line_exit_2(args, needle):
    code, err = _run(args.split())
    assert code == 2, err
    assert needle in _one_line(err)


@pytest.mark.parametrize("args,needle", [
    ("zk monitor -p socket://127.0.0.1:1", "cannot open: Connection refused"),
    ("zap echo -p socket://127.0.0.1:1", "Connection refused"),
    ("zk monitor -p /dev/ttyNOPE", "cannot open: No such file or directory"),
    ("zk monitor -p /dev/null", "Inappropriate ioctl for device"),
])
def test_port_failures_are_one_line_exit_4_without_library_text(args, needle):
    code, err = _run(args.split())
    assert code == 4, err
    line = _one_line(err)
    assert needle in line and "[Errno" not in line and "(25," not in line


@needs_full
@pytest.mark.parametrize("where", ["--raw-log", "-o"])
def test_a_full_disk_while_controlling_the_engine_sends_the_abort(where):
    code, err = _run(["zk", "send", "control", "--state", "run", "--throttle", "20", "--for", "5", "-p",
                      "sim://zk?speed=20", "-f", "jsonl", where, FULL], stdout=subprocess.DEVNULL)
    assert code == 7, err
    assert "note: output failed: sent standby, throttle 0" in err
    assert "cannot write /dev/full: No space left on device" in err and "Traceback" not in err


@pytest.fixture
def locked_pty():
    """A pty whose device another open file holds with an exclusive lock (as a running zkzap does)."""
    import fcntl
    import os
    import pty

    master, slave = pty.openpty()
    path = os.ttyname(slave)
    held = os.open(path, os.O_RDWR | os.O_NOCTTY)
    fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
    yield path
    for fd in (held, slave, master):
        os.close(fd)


def test_a_port_in_use_says_so_and_by_whom(locked_pty):
    import os

    code, err = _run(["zk", "monitor", "-p", locked_pty, "--count", "1"])
    assert code == 4, err
    line = _one_line(err)
    assert f"port {locked_pty}: in use by another program: " in line and f"(PID {os.getpid()})" in line, line
    assert "Resource temporarily unavailable" not in line and "; stop it, or use another port" in line


def test_a_port_in_use_by_an_unseen_program_says_how_to_find_it(cli, locked_pty, monkeypatch):
    monkeypatch.setattr("zkzap.link.port.holders", lambda device: [])
    r = cli("zap", "echo", "-p", locked_pty)
    assert r.exit_code == 4, r
    assert r.stderr.strip() == (f"zkzap: error: port {locked_pty}: in use by another program; 'fuser -v {locked_pty}' "
                                "names it (as root for another user's programs)")
