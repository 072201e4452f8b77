"""-o FILE names its format by its suffix, over the whole command tree: every --output is an
OutputPath, a suffix that names none of the command's formats is refused before the command
runs (exit 2, nothing written), and -f overrides the name."""

from __future__ import annotations

import click
import pytest

from cmdtree import commands
from zkzap.commands.options import OutputPath, check_output_suffixes
from zkzap.errors import UsageError

OUTPUTS = [(path, cmd) for path, cmd in commands() for p in cmd.params
           if isinstance(p, click.Option) and "--output" in p.opts]


def test_every_output_option_names_its_formats():
    assert len(OUTPUTS) >= 10
    for path, cmd in OUTPUTS:
        p = next(p for p in cmd.params if "--output" in getattr(p, "opts", ()))
        assert isinstance(p.type, OutputPath), " ".join(path)
        assert p.type.formats, " ".join(path)


@pytest.mark.parametrize("path,cmd", OUTPUTS, ids=[" ".join(p) for p, _ in OUTPUTS])
def test_an_unknown_suffix_is_refused_and_a_known_one_taken(path, cmd):
    with pytest.raises(UsageError, match=r"run\.qqq: the suffix '\.qqq' is not a format this command writes"):
        check_output_suffixes(cmd, {"output": "run.qqq", "fmt": None})
    check_output_suffixes(cmd, {"output": "run.qqq", "fmt": "json"})     # -f names it: no question
    p = next(p for p in cmd.params if "--output" in getattr(p, "opts", ()))
    from zkzap.io import SUFFIXES

    known = next(s for s, f in SUFFIXES.items() if f in p.type.formats)
    assert p.type.format_of(f"run{known}") == SUFFIXES[known]


def test_a_session_to_an_unknown_suffix_writes_nothing(cli, tmp_path):
    r = cli("zk", "send", "keepalive", "--sim", "--for", "1", "-o", str(tmp_path / "run.xls"))
    assert r.exit_code == 2 and "name the file .csv, .json, .jsonl" in r.stderr and ".xlsx" in r.stderr
    assert list(tmp_path.iterdir()) == []
    r = cli("zk", "decode", "FF 1D F4 70", "-o", str(tmp_path / "frames.csv"))
    assert r.exit_code == 0 and (tmp_path / "frames.csv").read_text().startswith("kind,id,")
