"""Tab completion of values, through the programs' completion protocol (the variables bash's
completion script sets): what a person gets after pressing Tab at each kind of value. The table
runs in-process; each installed program answers it once as a subprocess."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys

import pytest

BIN = os.path.dirname(sys.executable)


def complete(words):
    prog = words.split()[0]
    path = os.path.join(BIN, prog)
    if not os.path.exists(path):
        pytest.skip(f"{prog} is not installed beside {sys.executable}")
    parts = words.split(" ")
    env = dict(os.environ, **{f"_{prog.upper()}_COMPLETE": "bash_complete", "COMP_WORDS": words,
                              "COMP_CWORD": str(len(parts) - 1)})
    p = subprocess.run([path], capture_output=True, text=True, env=env, timeout=30)
    assert p.returncode == 0, p.stderr
    return [tuple(line.split(",", 1)) for line in p.stdout.splitlines() if line]


@pytest.mark.parametrize("words,expected", [
    # --port: the group's own simulator, besides the ports present and the URL schemes
    ("zk monitor -p sim", [("plain", "sim://zk")]),
    ("zk send control --state run -p sim", [("plain", "sim://zk")]),
    ("zk profile x.csv -p sim", [("plain", "sim://zk")]),
    ("zap echo -p sim", [("plain", "sim://zap")]),
    ("zap scan -p sim", [("plain", "sim://zap")]),
    # file paths: schedules, --binary inputs, outputs
    ("zk profile sched", [("file", "sched")]),
    ("zk decode --binary cap", [("file", "cap")]),
    ("zap decode --binary cap", [("file", "cap")]),
    ("zk monitor -o ru", [("file", "ru")]),
    # zk send raw: the command's field names, then an enumeration's names
    ("zk send raw 1 s", [("plain", "sw=")]),
    ("zk send raw 1 sw=r", [("plain", "sw=run")]),
    ("zk send raw 7 rpm", [("plain", "rpm_value=")]),
    ("zk send raw 0 reserved_b", [("plain", "reserved_b1="), ("plain", "reserved_b2=")]),
    ("zk send raw 1 reserved_b", []),                      # command 1 has no reserved bits
    # baud rates for zap scan -b, also after a comma
    ("zap scan -b 11", [("plain", "115200")]),
    ("zap scan -b 57600,9", [("plain", "57600,9600")]),
    ("zap scan -b a", [("plain", "all")]),
    # fault kinds, with or without an ID
    ("zkzap sim zap --fault ov", [("plain", "overload")]),
    ("zkzap sim zap --fault 2:tr", [("plain", "2:truncate")]),
])
def test_tab_completes_values(words, expected, monkeypatch):
    assert complete_in_process(words, monkeypatch) == expected


@pytest.mark.parametrize("words,expected", [
    ("zk monitor -p sim", [("plain", "sim://zk")]),
    ("zap scan -b 57600,9", [("plain", "57600,9600")]),
    ("zkzap sim zap --fault 2:tr", [("plain", "2:truncate")]),
])
def test_the_installed_programs_complete_values(words, expected):
    # the table above runs the same protocol in-process; here each program once as installed
    assert complete(words) == expected


def complete_in_process(words, monkeypatch):
    """:func:`complete` without the process: the program's command under the same variables."""
    from click.testing import CliRunner

    from zkzap import commands

    prog = words.split()[0]
    if prog == "zkzap":
        cmd = commands.root
    else:                                   # what zk_main / zap_main run
        cmd = getattr(importlib.import_module(f"zkzap.commands.{prog}"), prog)
    parts = words.split(" ")
    monkeypatch.setenv(f"_{prog.upper()}_COMPLETE", "bash_complete")
    monkeypatch.setenv("COMP_WORDS", words)
    monkeypatch.setenv("COMP_CWORD", str(len(parts) - 1))
    with CliRunner().isolation() as streams:
        with pytest.raises(SystemExit) as e:
            commands.run(cmd, prog, [])
        assert e.value.code == 0, streams[1].getvalue()
        text = streams[0].getvalue().decode()
    return [tuple(line.split(",", 1)) for line in text.splitlines() if line]
