"""A silent device never passes: every command that talks to a device, against one that says
nothing, exits with a failure status — never 0.

The commands are found by walking the whole command tree (every command whose port options are
a protocol's, :func:`cmdargs.protocol`), not listed by hand; their required parameters get
values by parameter name (:func:`cmdargs.invocation`). The one exception is the protocol's
own: outside feedback-return-mode 2 a mightyZAP write is never acknowledged, so a command that
sent nothing but packets that expect no reply (checked on its --capture with the codec's
``Command.expects_reply``) may succeed unconfirmed, as the README says.

The same walk checks that what is wrong with a port's name is said once by every command.
"""

from __future__ import annotations

import itertools
import json

import pytest

from zkzap.codec import zap

from cmdargs import has, invocation, protocol
from cmdtree import commands

#: A ZK ECU that never sends a status frame, in model time ten times faster than real time.
SILENT_ZK = "sim://zk?silent_after=0&speed=10"
#: A mightyZAP bus whose only actuator (ID 1) never answers.
SILENT_ZAP = "sim://zap?ids=1&faults=1:silent&clock=virtual"   # (on the virtual clock: silence in no time)

#: Commands that serve until they are stopped (they declare a --listen address) have no end to
#: judge; the console's own answer to a silent device is tested in tests/web/test_access.py.
DEVICE_COMMANDS = [(path, cmd) for path, cmd in commands() if protocol(cmd) and not has(cmd, "listen")]


@pytest.fixture(scope="module")
def values(tmp_path_factory):
    """Required parameters' values, by protocol and parameter name (files made once)."""
    from click.testing import CliRunner

    from zkzap.commands import root, run

    tmp_path = tmp_path_factory.mktemp("inputs")
    schedule = tmp_path / "stand.csv"
    schedule.write_text("0,0,stop\n1,0,stop\n")
    zk_batch, zap_batch = tmp_path / "zk.txt", tmp_path / "zap.txt"
    zk_batch.write_text("send keepalive\n")
    zap_batch.write_text("echo --id 1\n")
    zap_path = tmp_path / "path.csv"
    zap_path.write_text("t,id,position\n0,1,100\n1,1,200\n")
    taught = itertools.count()
    fleet = tmp_path / "fleet.json"
    with CliRunner().isolation():
        assert run(root, "zkzap", ["zap", "backup", "--sim", "--ids", "1", "-o", str(fleet)]) == 0
    return {
        "zk": {"sw": "stop", "param": "rate-20hz", "accel_curve": "40", "ignition_voltage_v": "3.2",
               "pressure_hpa": "1013", "target_rpm": "60000", "rpm_factor": "2", "cmd_id": "0",
               "schedule": str(schedule), "file": str(zk_batch)},
        "zap": {"reg": "goal-position", "regs": "present-position", "value": "100", "position": "100", "new": "5",
                "new_baud": "115200", "ids": "1", "targets": "1:100", "registers": "present-position",
                "instruction": "echo", "code": "echo",
                "file": lambda cmd: str(zap_batch if cmd.name == "batch" else fleet),
                "a": str(fleet), "b": "bus", "ident": "1", "fleet_file": str(fleet), "path": str(zap_path),
                # a new file each time: what one run left must not make the next one's a refusal
                "output": lambda cmd: str(tmp_path / f"{cmd.name}-{next(taught)}.csv")},
    }


BOUNDS = {
    # every wait short: a silent device costs a timeout, nothing more
    "zk": {"timeout": "0.3", "budget": "0.3", "window": "0.1", "duration": "0.3"},
    # (zap teach's --duration bounds its --rate mode only; its Enter mode ends with its input)
    "zap": {"timeout": "0.01", "retries": "0", "duration": lambda cmd: None if cmd.name == "teach" else "0.3",
            "ids": "1", "find_ids": "1", "find_baud": "57600",
            # zap cycle checks its --id in code (--path or --resume may give it instead)
            "ident": lambda cmd: "1" if cmd.name == "cycle" else None,
            # zap detect tries one rate, not five (each a whole scan of both protocols' IDs)
            "baud": lambda cmd: "57600" if cmd.name == "detect" else None},
}
#: What a shell reads, and a command that asks reads (zap setup's Enter): a line that talks.
STDIN = {"zk": "monitor --duration 0.3\n", "zap": "echo --id 1\n"}


def test_the_walk_finds_the_device_commands():
    names = {" ".join(path) for path, _ in DEVICE_COMMANDS}
    for expected in ("zk monitor", "zk send control", "zk detect", "zk check", "zap scan", "zap store",
                     "sniff zk", "sniff zap", "shell zk", "zk batch"):
        assert expected in names
    assert "zk decode" not in names and "sim zk" not in names and "zkzap crc" not in names
    assert "web zk" not in names                # a server: tests/web/test_access.py


@pytest.mark.parametrize("path,cmd", DEVICE_COMMANDS, ids=[" ".join(p) for p, _ in DEVICE_COMMANDS])
def test_a_silent_device_never_gives_exit_0(cli, values, tmp_path, path, cmd):
    proto = protocol(cmd)
    args = invocation(cmd, values[proto], dict(BOUNDS[proto], state_path=tmp_path / "setup.json"))
    capture = tmp_path / "wire.pcapng"
    r = cli(*path, *args, "-p", SILENT_ZK if proto == "zk" else SILENT_ZAP, "--capture", str(capture),
            input=STDIN[proto])
    assert "Traceback" not in r.stderr
    if r.exit_code == 0:
        # only a mightyZAP write nobody acknowledges may pass: everything sent expects no reply
        assert proto == "zap", r
        sent = [json.loads(line) for line in cli("zap", "decode", str(capture), "-f", "jsonl").stdout.splitlines()]
        sent = [bytes.fromhex(rec["frame"]) for rec in sent if rec.get("dir") == "h2d"]
        assert sent, r
        assert not any(zap.Command(pkt).expects_reply(1) for pkt in sent), r
    else:
        assert r.exit_code != 2, r          # refused input would be the test's failure, not the device's


@pytest.mark.parametrize("path,cmd", DEVICE_COMMANDS, ids=[" ".join(p) for p, _ in DEVICE_COMMANDS])
def test_a_port_hint_is_said_once(cli, values, tmp_path, path, cmd, monkeypatch):
    """The same walk: what is wrong with a port's name (macOS's /dev/tty.* dial-in device; here
    any name) is said once by every command that opens a port, however often it checks it."""
    from zkzap.link import adapters

    monkeypatch.setattr(adapters, "outgoing_port_hint", lambda device, platform=None: f"{device}: HINT")
    proto = protocol(cmd)
    args = invocation(cmd, values[proto], dict(BOUNDS[proto], state_path=tmp_path / "setup.json"))
    r = cli(*path, *args, "-p", SILENT_ZK if proto == "zk" else SILENT_ZAP, input=STDIN[proto])
    assert "Traceback" not in r.stderr and r.exit_code != 2, r
    assert r.stderr.count("HINT") == 1, r.stderr
