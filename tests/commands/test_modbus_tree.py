"""Every zap command on a Modbus RTU bus: walked over the whole command tree (a command added
later is covered), each either runs against the simulated 17Lf or refuses with exit 2 and its
reason named — never talks IR to a Modbus bus, never fails some other way.

The protocol is chosen by the environment (ZKZAP_ZAP_PROTOCOL=modbus), as a user's shell would:
a command with --protocol takes it, one without must refuse (open_link's check) rather than
open the port as IR. Servers (--listen) and the sniffer, which runs until stopped, have tests of
their own (tests/web, tests/e2e/test_sniff.py)."""

from __future__ import annotations

import itertools

import pytest

from cmdargs import has, invocation, protocol
from cmdtree import commands

BUS = "sim://zap?protocol=modbus&ids=1,2&clock=virtual"   # a census and silences in no time
ZAP_COMMANDS = [(path, cmd) for path, cmd in commands()
                if (path[0] == "zap" or path == ("shell", "zap")) and not has(cmd, "listen")]


@pytest.fixture(scope="module")
def values(tmp_path_factory):
    from click.testing import CliRunner

    from zkzap.commands import root, run

    d = tmp_path_factory.mktemp("modbus-inputs")
    batch = d / "batch.txt"
    batch.write_text("echo --id 1\nload present-position --id 1\n")
    path = d / "path.csv"
    path.write_text("t,id,position\n0,1,100\n1,1,200\n")
    fleet = d / "fleet.json"
    with CliRunner().isolation():
        code = run(root, "zkzap", ["zap", "backup", "--protocol", "modbus", "--ids", "1", "-p", BUS, "-o", str(fleet)])
    taught = itertools.count()
    return {"reg": "goal-position", "regs": "present-position", "value": "100", "position": "100", "new": "5",
            "new_baud": "115200", "ids": "1", "targets": "1:100", "registers": "present-position",
            "instruction": "read", "code": "read", "ident": "1", "params": ["00", "D2", "00", "01"],
            "file": lambda cmd: str(batch if cmd.name == "batch" else fleet),
            "a": str(fleet), "b": "bus", "fleet_file": str(fleet), "path": str(path),
            "output": lambda cmd: str(d / f"{cmd.name}-{next(taught)}.csv"),
            "_backup_ok": code == 0}


BOUNDS = {"timeout": "0.3", "retries": "1",   # a loaded machine: a command that runs must not time out
          "duration": lambda cmd: None if cmd.name == "teach" else "0.3",
          "count": lambda cmd: "1" if cmd.name in ("echo", "teach") else None, "ident": "1",
          "ids": "1", "find_ids": "1", "find_baud": "57600"}


def test_the_walk_finds_the_zap_commands():
    names = {" ".join(p) for p, _ in ZAP_COMMANDS}
    assert {"zap store", "zap sync-move", "zap raw", "zap batch", "shell zap", "zap play"} <= names


@pytest.mark.parametrize("path,cmd", ZAP_COMMANDS, ids=[" ".join(p) for p, _ in ZAP_COMMANDS])
def test_every_zap_command_runs_on_modbus_or_refuses_naming_why(cli, values, tmp_path, monkeypatch, path, cmd):
    monkeypatch.setenv("ZKZAP_ZAP_PROTOCOL", "modbus")
    args = invocation(cmd, values, dict(BOUNDS, state_path=tmp_path / "setup.json"))
    port = ["-p", BUS] if protocol(cmd) == "zap" else []
    r = cli(*path, *args, *port, input="echo --id 1\n" if path[0] == "shell" else "\n")
    assert "Traceback" not in r.stderr, r
    if r.exit_code == 2:
        assert "IR protocol only" in r.stderr or "Modbus" in r.stderr, r        # a named refusal
        assert r.stdout == "", r
    else:
        assert r.exit_code == 0, r


def _readme_row(start, name="README.md"):
    import os
    import re

    path = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), name)
    with open(path, encoding="utf-8") as f:
        row = next(line for line in f if line.startswith(start))
    return set(re.findall(r"`((?:zap|zkzap shell|zkzap sniff|zkzap web) [a-z-]+)`", row.split("|")[1]))


def test_the_readme_says_what_works_on_each_protocol():
    """The README's feature table (and the Modbus page's) names every zap command once, in the row of what it does on
    Modbus RTU: it speaks it (a --protocol that takes modbus) or it is IR only (its --protocol
    refuses modbus with a reason, or it has none and open_link refuses the environment)."""
    both, ir_only = set(), set()
    for path, cmd in commands():
        if not (path[0] == "zap" or path in (("shell", "zap"), ("sniff", "zap"), ("web", "zap"))):
            continue
        name = " ".join(path) if path[0] == "zap" else "zkzap " + " ".join(path)
        opt = next((p for p in cmd.params if p.name == "protocol"), None)
        speaks = opt is not None and "modbus" in opt.type.choices and not getattr(opt, "ir_only", None)
        if name == "zap detect":          # no --protocol: it probes both (test_zap_modbus_wire's detect tests)
            speaks = True
        (both if speaks else ir_only).add(name)
    for page in ("README.md", "docs/how-to/modbus.md"):
        assert _readme_row("| commands:", page) == both, page
        assert _readme_row("| IR only", page) == ir_only, page
