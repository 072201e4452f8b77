"""The committed man pages and completion scripts are exactly what the generators make from the
click application today; the pages lint clean; their examples are real."""

from __future__ import annotations

import filecmp
import os
import re
import shlex
import shutil
import subprocess
import sys

import pytest
from click.testing import CliRunner

from zkzap.docs import completions, man

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MAN = os.path.join(REPO, "man")
COMPLETIONS = os.path.join(REPO, "completions")
REGENERATE = "regenerate them with: python -m zkzap.docs all"


@pytest.fixture(scope="module")
def pages():
    return man.pages()


def _differences(expected_dir, actual_dir):
    exp = {os.path.relpath(os.path.join(d, f), expected_dir)
           for d, _, fs in os.walk(expected_dir) for f in fs}
    act = {os.path.relpath(os.path.join(d, f), actual_dir)
           for d, _, fs in os.walk(actual_dir) for f in fs}
    diff = sorted(exp ^ act)
    for rel in sorted(exp & act):
        if not filecmp.cmp(os.path.join(expected_dir, rel), os.path.join(actual_dir, rel), shallow=False):
            diff.append(rel)
    return diff


def test_committed_man_pages_are_current(tmp_path):
    out = tmp_path / "man"
    man.generate(str(out))
    diff = _differences(MAN, str(out))
    assert not diff, f"man pages differ from the application: {', '.join(diff)}; {REGENERATE}"


def test_committed_completions_are_current(tmp_path):
    out = tmp_path / "completions"
    completions.generate(str(out))
    diff = _differences(COMPLETIONS, str(out))
    if diff:
        with open(os.path.join(COMPLETIONS, "bash", "zkzap"), encoding="utf-8") as f:
            made_with = re.search(r"from click (\S+)'s", f.read())
        if made_with and made_with.group(1) != completions.click_version():
            pytest.skip(f"committed completions come from click {made_with.group(1)}, click "
                        f"{completions.click_version()} is installed; {REGENERATE}")
    assert not diff, f"completion scripts differ: {', '.join(diff)}; {REGENERATE}"


def test_a_page_per_command_and_the_entry_points(pages):
    from cmdtree import commands, groups

    expected = {"zkzap.1", "zk.1", "zap.1"}
    expected |= {"-".join(("zkzap", *path)) + ".1" for path, _ in groups(hidden=False)}
    expected |= {"-".join(("zkzap", *path)) + ".1" for path, _ in commands(hidden=False)}
    assert set(pages) == expected
    for name in ("zkzap-zk-send-control.1", "zkzap-zap-load.1", "zkzap-zk-decode.1", "zkzap-crc-zk.1",
                 "zkzap-ports.1", "zkzap-completion.1", "zkzap-zk-fields.1", "zkzap-zap-registers.1"):
        assert name in pages


def test_every_page_has_the_sections(pages):
    for name, text in pages.items():
        heads = re.findall(r"^\.SH (.+)$", text, re.M)
        for section in ("NAME", "SYNOPSIS", "DESCRIPTION", "OPTIONS", "ENVIRONMENT", "EXIT STATUS", "EXAMPLES"):
            assert section in heads, f"{name}: no {section}"
        assert text.startswith(f'.TH "{man.esc(name[:-2].upper())}" 1 ')


def test_exit_status_and_environment_come_from_the_application(pages):
    from zkzap.errors import EXIT_CODES

    text = pages["zkzap.1"]
    status = text.split(".SH EXIT STATUS", 1)[1].split(".SH", 1)[0]
    assert re.findall(r"\\fB(\d+)\\fR", status) == [str(c) for c, _ in EXIT_CODES]
    for var in ("ZKZAP_ZK_PORT", "ZKZAP_ZK_BAUD", "ZKZAP_ZAP_PORT", "ZKZAP_ZAP_BAUD", "NO_COLOR", "FORCE_COLOR",
                "ZKZAP_DEBUG"):
        assert f"\\fB{var}\\fR" in text
    control = pages["zkzap-zk-send-control.1"]
    assert "\\fBZKZAP_ZK_PORT\\fR" in control and "ZKZAP_ZAP_PORT" not in control
    assert "zk send control \\-\\-state run \\-\\-throttle 50 \\-n" in control     # its own example
    assert "\\fBzk send control\\fR" in control                                  # the direct entry point
    assert ".SH NAME\nzk \\- " in pages["zk.1"]


def test_options_are_listed_with_their_help(pages):
    text = pages["zkzap-zk-send-control.1"]
    assert "\\fB\\-p\\fR, \\fB\\-\\-port\\fR \\fIPORT\\fR" in text
    assert "\\fB\\-n\\fR, \\fB\\-\\-dry\\-run\\fR" in text
    action = pages["zkzap-zk-send-action.1"]
    assert ".SH ARGUMENTS" in action and "test\\-pump" in action


def test_pages_are_plain_ascii_roff(pages):
    for name, text in pages.items():
        text.encode("ascii")
        for ln in text.splitlines():
            assert ln == ln.rstrip(), f"{name}: trailing blank"
            assert ln, f"{name}: blank line"
            assert not ln.startswith("'"), f"{name}: line starts with a control character"


def _lint_targets():
    return sorted(os.path.join(MAN, f) for f in os.listdir(MAN) if f.endswith(".1"))


@pytest.mark.skipif(shutil.which("groff") is None, reason="groff is not installed (apt-get install groff-base)")
def test_groff_renders_without_warnings():
    # one run over every page (warnings name the file and line)
    p = subprocess.run(["groff", "-man", "-ww", "-z", *_lint_targets()], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0 and p.stderr == "", p.stderr


@pytest.mark.skipif(shutil.which("mandoc") is None, reason="mandoc is not installed (apt-get install mandoc)")
def test_mandoc_lint_is_clean():
    p = subprocess.run(["mandoc", "-Tlint", *_lint_targets()], capture_output=True, text=True, timeout=60)
    assert p.stdout + p.stderr == "", p.stdout + p.stderr


# --- the examples are real -----------------------------------------------------------------------

HEX_RESULT = re.compile(r"^((?:[0-9A-F]{2} )*[0-9A-F]{2})(?::|$)")
OFFLINE = {("zkzap", "crc"), ("zk", "decode"), ("zap", "decode"), ("zk", "states"), ("zk", "errors"),
           ("zk", "fields"), ("zap", "registers"), ("zkzap", "completion")}


def offline_examples(pages):
    """(page, argv, expected first output line or None) for every example that runs offline:
    a dry run (-n) or a command that only reads its arguments."""
    seen = set()
    for name, text in sorted(pages.items()):
        if ".SH EXAMPLES" not in text:
            continue
        block = text.split(".SH EXAMPLES", 1)[1].split(".SH", 1)[0]
        for raw in block.splitlines():
            if raw.startswith("."):
                continue
            ex = raw.replace("\\-", "-").replace("\\e", "\\").replace("\\&", "")
            code, _, comment = ex.partition("#")
            if any(c in code for c in "|<>&$`"):
                continue
            try:
                argv = shlex.split(code)
            except ValueError:
                continue
            if not argv or tuple(argv) in seen:
                continue
            offline = "-n" in argv or "--dry-run" in argv or (
                tuple(argv[:2]) in OFFLINE and not any(a in ("--binary", "-o", "--output") for a in argv))
            if not offline or any(a.startswith(("-p", "--port", "--sim")) for a in argv):
                continue
            if any("/" in a or a.endswith((".bin", ".csv")) for a in argv[1:]):
                continue
            seen.add(tuple(argv))
            m = HEX_RESULT.match(comment.strip())
            yield name, argv, m.group(1) if m else None


def test_offline_examples_run_and_print_what_they_say(pages, monkeypatch):
    from zkzap.commands import root, run
    from zkzap.commands.zap import zap
    from zkzap.commands.zk import zk

    monkeypatch.setenv("NO_COLOR", "1")
    progs = {"zkzap": root, "zk": zk, "zap": zap}
    checked = with_output = 0
    for page, argv, expected in offline_examples(pages):
        runner = CliRunner()
        with runner.isolation() as streams:
            code = run(progs[argv[0]], argv[0], argv[1:])
            out = streams[0].getvalue().decode()
            err = streams[1].getvalue().decode()
        assert code == 0, f"{page}: {' '.join(argv)} -> exit {code}: {err}"
        if expected is not None:
            assert out.splitlines()[0] == expected, f"{page}: {' '.join(argv)}"
            with_output += 1
        checked += 1
    assert checked >= 30 and with_output >= 15, (checked, with_output)


@pytest.mark.skipif(shutil.which("bash") is None, reason="bash is not installed")
@pytest.mark.parametrize("prog,words,expected", [
    ("zk", "zk send act", "action"),
    ("zap", "zap load present-v", "present-voltage"),
    ("zkzap", "zkzap zk send control --state st", "stop standby"),     # the codec's order
])
def test_committed_bash_script_completes_through_the_program(prog, words, expected):
    bindir = os.path.dirname(sys.executable)
    if not os.path.exists(os.path.join(bindir, prog)):
        pytest.skip(f"{prog} is not installed beside {sys.executable} (pip install -e .)")
    script = os.path.join(COMPLETIONS, "bash", prog)
    words_list = words.split(" ")
    code = (f"source {shlex.quote(script)}; COMP_WORDS=({' '.join(shlex.quote(w) for w in words_list)}); "
            f"COMP_CWORD={len(words_list) - 1}; _{prog}_completion {prog}; echo \"${{COMPREPLY[*]}}\"")
    env = dict(os.environ, PATH=bindir + os.pathsep + os.environ.get("PATH", ""))
    p = subprocess.run(["bash", "--norc", "--noprofile", "-c", code], capture_output=True, text=True, env=env,
                       timeout=30)
    assert p.stdout.strip() == expected, p.stderr


# --- each command's own exit statuses ------------------------------------------------------------

def _exit_section(text):
    return text.split(".SH EXIT STATUS", 1)[1].split(".SH", 1)[0]


def test_every_command_page_states_that_commands_exit_statuses(pages):
    from cmdtree import commands

    from zkzap.commands.options import exit_statuses

    for path, cmd in commands(hidden=False):
        page = pages["-".join(("zkzap", *path)) + ".1"]
        codes = [int(c) for c in re.findall(r"^\\fB(\d+)\\fR$", _exit_section(page), re.M)]
        own = exit_statuses(cmd)
        assert codes == [c for c, _ in own], path
        assert {0, 2, 130}.issubset(codes) or path[0] == "sim", path


def test_the_check_page_has_the_limit_no_frame_carried(pages):
    section = _exit_section(pages["zkzap-zk-check.1"])
    assert "\\fB1\\fR\nA limit no frame carried" in section
    assert "\\fB6\\fR" not in section                       # no checksum on ZK status frames to fail
    scan = _exit_section(pages["zkzap-zap-scan.1"])
    assert "\\fB3\\fR\nNothing answers." in scan and "\\fB6\\fR" in scan
    assert "\\fB1\\fR" not in _exit_section(pages["zkzap-zk-states.1"])


def test_what_a_help_text_says_of_exit_statuses_is_declared():
    """Every 'exit status N' / 'exit N' a command's help mentions is one of its statuses."""
    from cmdtree import commands

    from zkzap.commands.options import exit_statuses

    checked = 0
    for path, cmd in commands(hidden=False):
        text = " ".join(filter(None, [cmd.help, cmd.epilog] + [getattr(p, "help", None) for p in cmd.params]))
        said = set()
        for m in re.finditer(r"\bexit(?:s| status(?:es)?)? ((?:\d+(?:/\d+)?(?:,| and| or|)\s*)+)", text, re.I):
            said |= {int(n) for n in re.findall(r"\d+", m.group(1))}
        declared = {c for c, _ in exit_statuses(cmd)}
        assert said <= declared, (path, sorted(said - declared))
        checked += bool(said)
    assert checked >= 10


def test_committed_command_reference_is_current(tmp_path):
    """docs/reference/commands/*.md, committed so that links to it resolve outside the site too."""
    from zkzap.docs import site

    site.generate(str(tmp_path))
    diff = _differences(os.path.join(REPO, "docs", site.COMMANDS_DIR), str(tmp_path / site.COMMANDS_DIR))
    assert not diff, f"the command reference differs from the application: {', '.join(diff)}; {REGENERATE}"
