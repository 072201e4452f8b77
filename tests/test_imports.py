"""Fast start: a dry-run compose, --help, --version and tab completion import neither rich nor
pyserial nor anything else they do not use. Each case runs in a fresh interpreter and reports
its sys.modules at exit."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

CLI = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cli")

RUNNER = r"""
import atexit, sys
OUT = sys.argv[1]
def dump():
    with open(OUT, "w") as f:
        f.write("\n".join(sorted(sys.modules)))
atexit.register(dump)
prog, args = sys.argv[2], sys.argv[3:]
if prog == "baseline":
    import click
    sys.exit(0)
from zkzap import commands
sys.argv = [prog] + args
{"zkzap": commands.main, "zk": commands.zk_main, "zap": commands.zap_main}[prog]()
"""

#: Never on these paths: the terminal UI, the serial stack, ports, simulators, generators.
HEAVY = ("rich", "serial", "zkzap.link", "zkzap.sim", "zkzap.io.dashboard", "zkzap.docs", "asyncio",
         "importlib.metadata", "shutil", "json", "csv", "zkzap.io.writers")
#: What click itself imports lazily on these paths (gettext's locale lookup, option-name
#: suggestions for short options, help text wrapping, the completion protocol).
CLICK_LAZY = {"locale", "_locale", "difflib", "heapq", "_heapq", "textwrap", "click._textwrap",
              "click.shell_completion", "shlex", "encodings.latin_1"}
#: Built into the interpreter (nothing loaded from disk): the entry points freeze the objects
#: imported before the command runs.
#: ``signal``: the programs handle SIGINT and SIGTERM from their first instant.
BUILTIN = {"gc", "signal"}


def modules(tmp_path, prog, *args, env=None):
    out = tmp_path / f"modules-{len(list(tmp_path.iterdir()))}.txt"
    e = dict(os.environ, PYTHONPATH=CLI + os.pathsep + os.environ.get("PYTHONPATH", ""))
    for var in ("ZKZAP_ZK_PORT", "ZKZAP_ZAP_PORT", "ZKZAP_DEBUG", "PYTHONPROFILEIMPORTTIME"):
        e.pop(var, None)
    e.update(env or {})
    p = subprocess.run([sys.executable, "-c", RUNNER, str(out), prog, *args], capture_output=True, text=True,
                       env=e, timeout=30)
    assert out.exists(), f"exit {p.returncode}: {p.stderr}"
    return p, set(out.read_text().split("\n"))


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    _, mods = modules(tmp_path_factory.mktemp("base"), "baseline")
    assert "click" in mods
    return mods


def check(mods, baseline, *, also_forbidden=()):
    heavy = sorted(m for m in mods if m.split(".")[0] in {h.split(".")[0] for h in HEAVY if "." not in h}
                   or any(m == h or m.startswith(h + ".") for h in HEAVY + tuple(also_forbidden)))
    assert not heavy, f"imported: {heavy}"
    extra = sorted(m for m in mods - baseline if not m.startswith("zkzap") and m not in CLICK_LAZY | BUILTIN)
    assert not extra, f"imported beyond click: {extra}"


CASES = {
    "zk send -n": (("zkzap", "zk", "send", "control", "--state", "run", "--throttle", "50", "-n"), "FF 1D F4 70\n"),
    "zk entry send -n": (("zk", "send", "action", "rate-50hz", "-n"), "FF 20 08 "),
    "zap compose -n": (("zap", "load", "present-position", "-n"), "FF FF FF 00 04 F2 8C 02 7B\n"),
    "zkzap --help": (("zkzap", "--help"), "Usage: zkzap"),
    "zk --help": (("zk", "--help"), "Usage: zk"),
    "zap store --help": (("zap", "store", "--help"), "Usage: zap store"),
    "zk send control --help": (("zkzap", "zk", "send", "control", "--help"), "Usage: zkzap zk send control"),
    "--version": (("zkzap", "--version"), "zkzap "),
}


@pytest.mark.parametrize("case", list(CASES))
def test_commands_import_only_what_they_use(tmp_path, baseline, case):
    argv, expected = CASES[case]
    p, mods = modules(tmp_path, *argv)
    assert p.returncode == 0, p.stderr
    assert p.stdout.startswith(expected)
    also = ("zkzap.codec.zap",) if argv[0] == "zk" or argv[1:2] == ("zk",) else ("zkzap.codec.zk",)
    if case in ("zkzap --help", "zk --help", "--version"):
        also += ("zkzap.codec",)      # a group's help lists its commands without importing them
    if argv[-1] == "-n":
        also += ("locale",)   # no message-catalogue look-up for the help option either
    check(mods, baseline, also_forbidden=also)


@pytest.mark.parametrize("words,cword,expected", [
    ("zkzap zk send co", 3, "plain,control"),
    ("zkzap zk send control --state r", 5, "plain,run"),
    ("zkzap zap load goal-", 3, "plain,goal-position"),
    ("zkzap zk decode -f j", 4, "plain,json"),
    ("zkzap z", 1, "plain,zap"),
])
def test_tab_completion_imports_only_what_it_uses(tmp_path, baseline, words, cword, expected):
    p, mods = modules(tmp_path, "zkzap", env={"_ZKZAP_COMPLETE": "bash_complete", "COMP_WORDS": words,
                                              "COMP_CWORD": str(cword)})
    assert p.returncode == 0, p.stderr
    assert expected in p.stdout.splitlines()
    check(mods, baseline)


def test_port_completion_lists_ports_with_pyserial(tmp_path, baseline):
    # the one completion that needs pyserial: the serial ports present (and URL schemes)
    p, mods = modules(tmp_path, "zk", env={"_ZK_COMPLETE": "bash_complete", "COMP_WORDS": "zk send keepalive -p soc",
                                           "COMP_CWORD": "4"})
    assert p.returncode == 0, p.stderr
    assert "plain,socket://" in p.stdout.splitlines()
    assert "rich" not in mods
