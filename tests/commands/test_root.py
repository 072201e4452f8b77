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


@pytest.mark.parametrize("entry,prog", [("main", "zkzap"), ("zk_main", "zk"), ("zap_main", "zap")])
def test_entry_points_freeze_what_is_imported_then_run(monkeypatch, entry, prog):
    import gc

    calls = []
    monkeypatch.setattr(gc, "freeze", lambda: calls.append("freeze"))
    monkeypatch.setattr(commands, "run", lambda cmd, name: calls.append(("run", cmd.name, name)) or 3)
    with pytest.raises(SystemExit) as e:
        getattr(commands, entry)()
    assert e.value.code == 3
    assert calls == ["freeze", ("run", "root" if prog == "zkzap" else prog, prog)]


def test_every_command_builds_its_help_option_without_gettext(monkeypatch, cli):
    import gettext

    looked_up = []
    monkeypatch.setattr(gettext, "dgettext", lambda domain, msg: looked_up.append(msg) or msg)
    for group, mapping in MAPS:
        for name, spec in mapping.items():
            cmd = getattr(importlib.import_module(spec[0], "zkzap.commands"), spec[1])
            # the context as click makes it for the command (its settings name -h): a bare one
            # passed only where another test had already built the option in this process
            ctx = click.Context(cmd, info_name=name, **cmd.context_settings)
            option = cmd.get_help_option(ctx)
            assert option.opts == ["-h", "--help"] and option.help == "Show this message and exit."
            assert option is cmd.get_help_option(ctx)
    assert looked_up == []
