"""The bridge options on the ZK logging commands: bad input is exit 2 before any port opens
(nothing on stdout, no file touched), a missing extra names itself, and no command imports a
bridge's library unless its option is given."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys

import pytest

NOPORT = "/dev/nonexistent-zkzap"


@pytest.mark.parametrize("args,message", [
    (("--mavlink", "udpout:127.0.0.1"), "expected udpout:HOST:PORT"),
    (("--mavlink", "udpout:127.0.0.1:70000"), "port 1..65535"),
    (("--mavlink", "bogus"), "expected udpout:HOST:PORT"),
    (("--mavlink", "/dev/ttyUSB1,fast"), "baud rate"),
    (("--sysid", "3"), "sysid: applies only with --mavlink"),
    (("--mavlink-rate", "5"), "mavlink-rate: applies only with --mavlink"),
    (("--mqtt-qos", "1"), "mqtt-qos: applies only with --mqtt"),
    (("--mqtt-optional",), "mqtt-optional: applies only with --mqtt"),
    (("--mqtt", "mqtt://h/p", "--mqtt-qos", "3"), "mqtt-qos"),
    (("--mavlink", "udpout:127.0.0.1:14550", "--mavlink-rate", "0"), "mavlink-rate"),
])
def test_bad_bridge_options_are_exit_2_before_the_port(cli, tmp_path, args, message):
    out = tmp_path / "keep.jsonl"
    out.write_text("old\n")
    r = cli("zk", "monitor", "-p", NOPORT, "-o", str(out), *args)
    assert r.exit_code == 2 and r.stdout == "" and message in r.stderr, r
    assert out.read_text() == "old\n"


@pytest.mark.parametrize("option,module,extra", [
    (("--mavlink", "udpout:127.0.0.1:14550"), "pymavlink", "mavlink"),
    (("--mqtt", "mqtt://127.0.0.1/p"), "paho", "mqtt"),
    (("-f", "mcap", "-o", "x.mcap"), "mcap", "mcap"),
])
def test_a_missing_extra_is_named(cli, monkeypatch, option, module, extra):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == module else real(name, *a))
    r = cli("zk", "monitor", "-p", NOPORT, *option)
    assert r.exit_code == 2 and r.stdout == "", r
    assert f"pip install 'zkzap[{extra}]'" in r.stderr


def test_send_takes_bridges_only_with_for(cli):
    r = cli("zk", "send", "keepalive", "-p", NOPORT, "--mqtt", "mqtt://h/p")
    assert r.exit_code == 2 and "mqtt: applies only with --for" in r.stderr, r


def test_profile_and_send_have_the_bridge_options(cli):
    for cmd in (("zk", "profile"), ("zk", "send", "control"), ("zk", "monitor")):
        r = cli(*cmd, "--help")
        assert all(o in r.stdout for o in ("--mavlink", "--mqtt", "--mqtt-qos", "--sysid", "--compid")), cmd


def test_unknown_format_is_exit_2(cli):
    r = cli("zk", "monitor", "-p", NOPORT, "-f", "parquet")
    assert r.exit_code == 2 and r.stdout == ""


def test_mcap_to_a_terminal_is_refused(cli, monkeypatch):
    import zkzap.io.term as term

    monkeypatch.setattr(term, "is_tty", lambda stream: True)
    r = cli("zk", "monitor", "-p", NOPORT, "-f", "mcap")
    assert r.exit_code == 2 and "binary output" in r.stderr, r


BRIDGE_LIBS = ("pymavlink", "paho", "mcap", "zkzap.io.bridges", "zkzap.io.mcap", "zstandard", "lz4")

RUNNER = r"""
import sys
from zkzap import commands
sys.argv = ["zk"] + sys.argv[1:]
try:
    commands.zk_main()
except SystemExit:
    pass
print(" ".join(sorted(m for m in sys.modules)), file=sys.stderr)
"""


@pytest.mark.parametrize("args", [
    ("monitor", "-p", "sim://zk?speed=10", "--count", "3", "-f", "jsonl"),
    ("monitor", "-p", "sim://zk?speed=10", "--count", "3", "-f", "influx"),
    ("decode", "FF 1D F4 70", "-f", "influx"),
    ("monitor", "--help"),
])
def test_no_bridge_library_is_imported_unless_asked_for(args):
    env = {k: v for k, v in os.environ.items() if not k.startswith("ZKZAP_")}
    p = subprocess.run([sys.executable, "-c", RUNNER, *args], capture_output=True, text=True, env=env, timeout=60)
    assert p.returncode == 0, p.stderr
    mods = p.stderr.strip().splitlines()[-1].split()
    bad = [m for m in mods if any(m == b or m.startswith(b + ".") for b in BRIDGE_LIBS)]
    assert not bad, bad


def test_dry_runs_refuse_the_bridges(cli, tmp_path):
    r = cli("zk", "send", "control", "--state", "stop", "-n", "--mavlink", "udpout:127.0.0.1:14550")
    assert r.exit_code == 2 and r.stdout == "" and "mavlink: applies only with --for" in r.stderr, r
    sched = tmp_path / "s.csv"
    sched.write_text("0,10\n5,0,stop\n")
    r = cli("zk", "profile", str(sched), "-n", "--mqtt", "mqtt://h/p")
    assert r.exit_code == 2 and r.stdout == "" and "mqtt: applies only with a run" in r.stderr, r
