"""The manual's examples run as written: every Python block marked ``<!-- api-example -->`` runs
against the simulators, and every offline command of a ``console`` block (a dry run, a decode
of its arguments, a CRC, a table) prints what the page says it prints."""

from __future__ import annotations

import os
import re
import shlex

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def pages():
    """The README and every page of the manual, as ``(name, text)``."""
    out = [("README.md", open(os.path.join(REPO, "README.md"), encoding="utf-8").read())]
    for dirpath, _, files in sorted(os.walk(os.path.join(REPO, "docs"))):
        for name in sorted(files):
            if name.endswith(".md"):
                path = os.path.join(dirpath, name)
                out.append((os.path.relpath(path, REPO), open(path, encoding="utf-8").read()))
    return out


def api_examples():
    return [(name, code) for name, text in pages()
            for code in re.findall(r"<!-- api-example -->\n```python\n(.*?)```", text, re.S)]


def test_there_are_api_examples():
    assert len(api_examples()) >= 4


@pytest.mark.parametrize("index", range(len(api_examples())))
def test_api_example_runs(index):
    name, code = api_examples()[index]
    exec(compile(code, f"{name} example {index + 1}", "exec"), {"__name__": "docs_example"})


#: Commands that only read their arguments (no port, no file) when given no --binary or -o.
OFFLINE = {("zkzap", "crc"), ("zk", "decode"), ("zap", "decode"), ("zk", "states"), ("zk", "errors"),
           ("zk", "fields"), ("zap", "registers")}


def console_examples():
    """``(page, argv, expected lines)`` of every offline command in a console block."""
    out = []
    for name, text in pages():
        for block in re.findall(r"```console\n(.*?)```", text, re.S):
            lines = block.split("\n")
            i = 0
            while i < len(lines):
                if not lines[i].startswith("$ "):
                    i += 1
                    continue
                command, i = lines[i][2:], i + 1
                while command.endswith("\\") and i < len(lines):
                    command, i = command[:-1] + lines[i].strip(), i + 1
                expected = []
                while i < len(lines) and not lines[i].startswith("$ "):
                    if lines[i].strip():
                        expected.append(lines[i])
                    i += 1
                argv = _words(command)
                if not argv or argv[0] not in ("zk", "zap", "zkzap"):
                    continue
                dry = "-n" in argv or "--dry-run" in argv
                reads_only = tuple(argv[:2]) in OFFLINE and not {"--binary", "-o", "--output"} & set(argv)
                if not (dry or reads_only) or any(a.startswith(("-p", "--port", "--sim", "--capture")) for a in argv):
                    continue
                if any(a.endswith((".bin", ".csv", ".pcapng", ".hex", ".json")) for a in argv[1:]):
                    continue
                out.append((name, argv, expected))
    return out


def _words(command: str) -> list:
    """The words of a simple command; [] for a pipeline, a redirection, a substitution."""
    if "$(" in command or "`" in command:
        return []
    lexer = shlex.shlex(command, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    lexer.commenters = "#"
    try:
        words = list(lexer)
    except ValueError:
        return []
    return [] if any(w and set(w) <= set("|&;<>()") for w in words) else words


def _matches(expected: str, line: str) -> bool:
    """An expected line matches as written, or around its ellipses (``…`` or ``...``)."""
    pieces = re.split(r"…|\.\.\.", expected)
    if len(pieces) == 1:
        return expected == line
    pos = 0
    for k, piece in enumerate(pieces):
        at = line.find(piece, pos)
        if at < 0 or (k == 0 and at != 0):
            return False
        pos = at + len(piece)
    return pieces[-1] == "" or line.endswith(pieces[-1])


def test_there_are_console_examples():
    examples = console_examples()
    assert len(examples) >= 30 and sum(1 for _, _, e in examples if e) >= 20


@pytest.mark.parametrize("page,argv,expected", console_examples(),
                         ids=lambda v: " ".join(v) if isinstance(v, list) and v and isinstance(v[0], str)
                         and v[0] in ("zk", "zap", "zkzap") else None)
def test_console_example_prints_what_the_page_says(page, argv, expected, monkeypatch):
    from click.testing import CliRunner

    from zkzap.commands import root, run
    from zkzap.commands.zap import zap
    from zkzap.commands.zk import zk

    monkeypatch.setenv("NO_COLOR", "1")
    progs = {"zkzap": root, "zk": zk, "zap": zap}
    runner = CliRunner()
    with runner.isolation() as streams:
        code = run(progs[argv[0]], argv[0], argv[1:])
        out = streams[0].getvalue().decode().splitlines()
        err = streams[1].getvalue().decode().splitlines()
    printed = out + err
    shown = [e for e in expected if not e.startswith("# ")]
    if any(e.startswith("echo $?") for e in shown):                  # not in offline examples
        shown = []
    want_error = bool(shown) and shown[-1].startswith(f"{argv[0]}: error:")
    assert (code != 0) == want_error, f"{page}: {' '.join(argv)} -> exit {code}: {err}"
    assert len(printed) == len(shown) or any("…" in e or "..." in e for e in shown) or not shown, \
        f"{page}: {' '.join(argv)}\n{printed}"
    for want, got in zip(shown, printed):
        assert _matches(want, got), f"{page}: {' '.join(argv)}\nexpected {want!r}\nprinted  {got!r}"


def test_the_status_keys_table_is_the_codec_table():
    from zkzap.codec import zk

    text = open(os.path.join(REPO, "docs", "reference", "records.md"), encoding="utf-8").read()
    table = text.split("<!-- zk-status-keys -->", 1)[1].strip().split("\n\n", 1)[0].splitlines()[2:]
    rows = {}
    for row in table:
        ident, keys = [c.strip() for c in row.strip("|").split("|")]
        rows[ident] = re.findall(r"`(\w+)`", keys)
    assert rows.pop("all") == ["rpm"]
    for st in zk.STATUS:
        expected = [k for f in st.fields if f.key != "rpm" for k in (f.key, f.name_key) if k]
        assert rows.pop(str(st.id)) == expected, st.id
    assert rows == {}
