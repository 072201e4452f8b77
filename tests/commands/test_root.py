"""The lazy command maps: every name resolves to a real command, and help lists them all."""

import importlib

import click
import pytest

from zkzap import commands

MAPS = [("", commands.ROOT_COMMANDS), ("zk", commands.ZK_COMMANDS), ("zap", commands.ZAP_COMMANDS)]


@pytest.mark.parametrize("group,name,spec", [(g, n, s) for g, m in MAPS for n, s in m.items()])
def test_every_lazy_entry_is_a_command(group, name, spec, cli):
    module = importlib.import_module(spec[0], "zkzap.commands")
    cmd = getattr(module, spec[1])
    assert isinstance(cmd, click.Command)
    assert spec[2] and spec[2].endswith(".")
    r = cli(*([group] if group else []), name, "--help")
    assert r.exit_code == 0 and "Usage:" in r.stdout


def test_help_lists_every_command_without_importing_them(cli):
    for group, mapping in MAPS:
        out = cli(*([group] if group else []), "--help").stdout
        listed = {line.split()[0] for line in out.split("Commands:")[1].splitlines() if line.startswith("  ")}
        assert set(mapping) <= listed


def test_version(cli):
    from zkzap import __version__

    for group in ([], ["zk"], ["zap"]):
        r = cli(*group, "--version")
        assert r.exit_code == 0 and __version__ in r.stdout
