"""Unix manners, checked on real processes: NO_COLOR/FORCE_COLOR, no escape codes in a pipe,
one-line errors without tracebacks (unless --debug), Ctrl-C exits 130 quietly, a closed pipe
ends quietly, exit codes documented in --help."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from zkzap.codec import zk
from zkzap.errors import EXIT_CODES

CLI = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "cli")
ENTRY = "from zkzap import commands; import sys; getattr(commands, sys.argv.pop(1))()"
MAINS = {"zkzap": "main", "zk": "zk_main", "zap": "zap_main"}


def env_with(**extra):
    env = dict(os.environ, PYTHONPATH=CLI + os.pathsep + os.environ.get("PYTHONPATH", ""))
    for var in ("NO_COLOR", "FORCE_COLOR", "ZKZAP_DEBUG", "ZKZAP_ZK_PORT", "ZKZAP_ZAP_PORT", "COLUMNS"):
        env.pop(var, None)
    env.update(extra)
    return env


def argv(prog, *args):
    """The command line of ``prog`` from the source tree (stdout and stderr are pipes here)."""
    return [sys.executable, "-c", ENTRY, MAINS[prog], *args]


def run(prog, *args, input=None, **env):
    return subprocess.run(argv(prog, *args), input=input, capture_output=True, env=env_with(**env), timeout=30)


OUT_OF_RANGE = ("zk", "send", "control", "--state", "run", "--throttle", "150", "-n")
MESSAGE = b"zk: error: throttle: 150 is out of range; allowed 0..100 %\n"


def test_plain_errors_in_a_pipe():
    p = run(*OUT_OF_RANGE)
    assert (p.returncode, p.stdout, p.stderr) == (2, b"", MESSAGE)


def test_force_color_colours_the_error_prefix_and_no_color_wins():
    forced = run(*OUT_OF_RANGE, FORCE_COLOR="1")
    assert forced.returncode == 2
    assert forced.stderr.startswith(b"zk: \x1b[31m") and b"error:" in forced.stderr
    both = run(*OUT_OF_RANGE, FORCE_COLOR="1", NO_COLOR="1")
    assert both.stderr == MESSAGE
    empty = run(*OUT_OF_RANGE, NO_COLOR="")           # an empty NO_COLOR does not count
    assert empty.stderr == MESSAGE


@pytest.mark.parametrize("args", [
    ("zk", "states", "-f", "table"),
    ("zap", "registers", "goal-position", "-f", "table"),
    ("zk", "decode", "FF", "1D", "F4", "70", "-f", "table"),
    ("zkzap", "--help"),
    ("zk", "decode", *zk.encode_status(2, radio_voltage_v=5.0, power_voltage_v=12.0).hex(" ").upper().split()),
])
def test_no_escape_codes_when_not_a_terminal(args):
    p = run(*args)
    assert p.returncode == 0, p.stderr
    assert p.stdout and b"\x1b" not in p.stdout and b"\x1b" not in p.stderr
    if args[1] == "decode" and "F2" in args:
        assert b"note: voltages assume protocol version 4" in p.stderr     # a message, also plain


def test_force_color_reaches_tables_in_a_pipe():
    p = run("zk", "states", "running", "-f", "table", FORCE_COLOR="1")
    assert b"\x1b[" in p.stdout and b"running" in p.stdout


@pytest.mark.parametrize("args,code,message", [
    (("zk", "decode", "ZZ"), 2, b"zk: error: hex input: 'ZZ' is not hex"),
    (("zkzap", "crc", "check", "FF", "14", "64", "D4"), 1, b"zkzap: error: control frame: CRC mismatch: expected D3"),
    (("zap", "store", "goal-position", "5000", "--id", "1", "-n"), 2, b"zap: error: goal-position: 5000 is out of range"),
    (("zk", "send", "control", "--bogus"), 2, b"zk: error: No such option"),
    (("zk", "send", "control", "--state", "stop", "-p", "/nonexistent/tty"), 4, b"zk: error: port /nonexistent/tty"),
])
def test_errors_are_one_line_without_traceback(args, code, message):
    p = run(*args)
    assert p.returncode == code
    assert p.stdout == b""
    assert p.stderr.startswith(message), p.stderr
    assert p.stderr.count(b"\n") == 1 and b"Traceback" not in p.stderr


@pytest.mark.parametrize("how", ["--debug", "ZKZAP_DEBUG"])
def test_debug_shows_the_traceback(how):
    if how == "--debug":
        p = run("zk", "--debug", *OUT_OF_RANGE[1:])
    else:
        p = run(*OUT_OF_RANGE, ZKZAP_DEBUG="1")
    assert p.returncode != 0
    assert b"Traceback (most recent call last)" in p.stderr
    assert b"FieldValueError: throttle: 150 is out of range" in p.stderr


@pytest.mark.parametrize("args", [("zk", "decode"), ("zap", "decode", "--binary")])
def test_ctrl_c_in_a_blocking_read_exits_130_quietly(args):
    r, w = os.pipe()
    proc = subprocess.Popen(argv(*args), stdin=r, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env_with())
    os.close(r)
    try:
        frame = b"FF 1D F4 70\n" if args[0] == "zk" else bytes.fromhex("FFFFFF0002F10C")
        os.write(w, frame)
        first = proc.stdout.readline()          # decoded and flushed while the pipe stays open
        assert b'"kind":' in first
        time.sleep(0.1)                         # now blocked reading stdin
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=10)
    finally:
        os.close(w)
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130
    assert err.strip() == b"", err            # at most the newline that ends the ^C line
    assert out == b""


def test_closed_pipe_ends_quietly(tmp_path):
    capture = tmp_path / "big.bin"
    frame = zk.encode_status(1, rpm=120000, engine_state=11, egt_c=650, sw_state=2)
    capture.write_bytes(frame * 100_000)       # 15 MB of JSON Lines: far more than a pipe holds
    cmd = " ".join(f"'{a}'" for a in argv("zkzap", "zk", "decode", "--binary", str(capture)))
    p = subprocess.run(["bash", "-c", f'{cmd} | head -1; echo "status=${{PIPESTATUS[0]}}" >&2'],
                       capture_output=True, env=env_with(), timeout=60)
    assert p.stdout.count(b"\n") == 1 and p.stdout.startswith(b'{"kind":"status","id":1,"rpm":120000')
    assert p.stderr == b"status=0\n", p.stderr


def test_closed_pipe_from_a_table_and_csv():
    for args in (("zk", "fields", "-f", "csv"), ("zap", "registers", "-f", "table")):
        cmd = " ".join(f"'{a}'" for a in argv(*args))
        p = subprocess.run(["bash", "-c", f'{cmd} | head -c 10 >/dev/null; echo "status=${{PIPESTATUS[0]}}" >&2'],
                           capture_output=True, env=env_with(), timeout=30)
        assert p.stderr == b"status=0\n", (args, p.stderr)


@pytest.mark.parametrize("prog", ["zkzap", "zk", "zap"])
def test_help_documents_every_exit_code(prog):
    p = run(prog, "--help", COLUMNS="400")
    text = p.stdout.decode()
    epilog = text[text.index("Exit status:"):]
    for code, meaning in EXIT_CODES:
        assert f"{code} {meaning}" in " ".join(epilog.split())


def test_an_error_quoting_an_input_is_one_line_without_its_control_characters(cli, tmp_path):
    batch = tmp_path / "b.txt"
    batch.write_bytes(b"echo --id 1\n" + b"frob\x1b[2J\x07" + b"x" * 3000 + b"\n")
    r = cli("zap", "batch", str(batch), "-p", "/nonexistent/port")
    assert r.exit_code == 2 and r.stdout == ""
    line = r.stderr
    assert line.count("\n") == 1 and len(line.splitlines()) == 1, repr(line)
    assert "\x1b" not in line and "\x07" not in line and "frob\\x1b[2J\\x07xxx" in line
    assert f"{batch}:2:" in line and " [...] " in line and len(line) < 1100
