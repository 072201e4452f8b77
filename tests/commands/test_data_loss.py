"""No run destroys data it was not asked to replace.

- A run that fails to start (no port, a silent ECU, a malformed URL) leaves every existing
  output file (-o, --raw-log, --summary-json) byte for byte as it was.
- An output that is also an input, or two outputs naming one file, is refused (exit 2, file
  untouched).
- --append continues a file only in its own format: the same CSV header (else refused), a
  new line after a cut last line, a JSON array that stays one array.
- --summary-json is checked before the run, and a failed run never leaves an older summary.
"""

from __future__ import annotations

import json
import os
import subprocess

import pytest

from zkzap.api.telemetry import record_columns  # noqa: E402

OLD_CSV = ",".join(record_columns(True)) + "\n2024-05-01T12:00:00.000Z,0.1,1,5000\n"
OLD_BIN = b"\xf1\x00\x00\x00\x00\x4c\xa0" * 3
SIM = "sim://zk?speed=20"
SILENT = "sim://zk?silent_after=0"


def _files(tmp_path):
    out, raw = tmp_path / "keep.csv", tmp_path / "keep.bin"
    out.write_text(OLD_CSV)
    raw.write_bytes(OLD_BIN)
    return out, raw


def _schedule(tmp_path):
    p = tmp_path / "stand.csv"
    p.write_text("0,0,stop\n1,0,stop\n")
    return str(p)


FAILED_STARTS = [
    # (command before the port, port, expected exit status); SILENT never sends a frame, so a
    # short --timeout only ends the wait for one sooner
    ("zk monitor", "/dev/ttyNOPE", 4),
    ("zk monitor", "socket://127.0.0.1:1", 4),
    ("zk monitor --timeout 0.05", SILENT, 3),
    ("zk send control --state stop --for 1", "/dev/ttyNOPE", 4),
    ("zk send control --state stop --for 1 --timeout 0.05", SILENT, 3),
    ("zk send keepalive --for 0 --timeout 0.05", SILENT, 3),
    ("zk profile {schedule}", "/dev/ttyNOPE", 4),
    ("zk profile {schedule} --timeout 0.05", SILENT, 3),
    ("zk monitor", "socket://127.0.0.1", 2),
]


@pytest.mark.parametrize("append", [False, True], ids=["replace", "append"])
@pytest.mark.parametrize("command,port,code", FAILED_STARTS, ids=[f"{c} -p {p}" for c, p, _ in FAILED_STARTS])
def test_a_failed_start_leaves_existing_outputs_untouched(cli, tmp_path, command, port, code, append):
    out, raw = _files(tmp_path)
    args = command.format(schedule=_schedule(tmp_path)).split() + ["-p", port, "-o", str(out), "--raw-log", str(raw)]
    r = cli(*args, *(["--append"] if append else []))
    assert r.exit_code == code, r
    assert out.read_text() == OLD_CSV
    assert raw.read_bytes() == OLD_BIN


def test_a_failed_start_creates_no_new_files(cli, tmp_path):
    out, raw = tmp_path / "new.csv", tmp_path / "new.bin"
    r = cli("zk", "monitor", "-p", "/dev/ttyNOPE", "-o", str(out), "--raw-log", str(raw))
    assert r.exit_code == 4
    assert not out.exists() and not raw.exists()


def test_a_run_that_starts_replaces_and_a_quiet_good_run_still_creates(cli, tmp_path):
    out, raw = _files(tmp_path)
    r = cli("zk", "monitor", "-p", SIM, "--count", "3", "-o", str(out), "--raw-log", str(raw))
    assert r.exit_code == 0, r
    lines = out.read_text().splitlines()
    assert lines[0].startswith("time,t,id,rpm,engine_state") and len(lines) == 4
    assert raw.read_bytes() != OLD_BIN and len(raw.read_bytes()) >= 21


SAME_FILE = [
    # (args with {f} for the shared file, what stderr names)
    ("zk decode --binary {f} -o {f}", "output: {f} is also the input (FILE {f})"),
    ("zap decode --binary {f} -o {f}", "output: {f} is also the input (FILE {f})"),
    ("zk monitor --replay {f} -o {f}", "output: {f} is also the input (--replay {f})"),
    ("zk monitor --replay {f} --fast -f csv -o {d}/../{n}", "is also the input (--replay"),
    ("zk monitor -p sim://zk --count 1 -o {f} --raw-log {f}", "output: {f} is also given to --raw-log"),
    ("zk send control --state stop --for 1 --sim -o {f} --raw-log {f}", "output: {f} is also given to --raw-log"),
    ("zk profile {f} --sim -o {f}", "output: {f} is also the input (SCHEDULE {f})"),
    ("zk profile {f} --sim --raw-log {f}", "raw-log: {f} is also the input (SCHEDULE {f})"),
    ("zk profile {f} --sim --summary-json {f}", "summary-json: {f} is also the input (SCHEDULE {f})"),
    ("zk profile {s} --sim -o {f} --summary-json {f}", "summary-json: {f} is also given to --output"),
    ("zk profile {f} -n -o {f}", "output: {f} is also the input (SCHEDULE {f})"),
]


@pytest.mark.parametrize("args,needle", SAME_FILE, ids=[a for a, _ in SAME_FILE])
def test_an_output_that_is_an_input_or_another_output_is_refused(cli, tmp_path, args, needle):
    f = tmp_path / "same.csv"
    content = "0,0,stop\n1,0,stop\n"
    f.write_text(content)
    fmt = dict(f=str(f), d=str(tmp_path), n=f"{tmp_path.name}/same.csv", s=_schedule(tmp_path))
    r = cli(*args.format(**fmt).split())
    assert r.exit_code == 2, r
    assert needle.format(**fmt) in r.stderr
    assert f.read_text() == content and r.stdout == ""


def test_hex_on_stdin_from_the_output_file_is_refused(sh, tmp_path):
    f = tmp_path / "dump.txt"
    f.write_text("FF 1D F4 70\n")
    with open(f) as stdin:
        p = subprocess.run([_exe("zk"), "decode", "-f", "jsonl", "-o", str(f)], stdin=stdin, capture_output=True, text=True,
                           timeout=30)
    assert p.returncode == 2, p
    assert "is also the input (stdin" in p.stderr
    assert f.read_text() == "FF 1D F4 70\n"


def _exe(name):
    import shutil
    import sys

    here = os.path.join(os.path.dirname(sys.executable), name)
    return here if os.path.exists(here) else shutil.which(name)


# --- --append -------------------------------------------------------------------------------

APPEND_MISMATCH = [
    ("zk monitor -p " + SIM + " --count 2 --ids 1", "zk monitor -p " + SIM + " --count 2 --ids 2"),
    ("zk monitor -p " + SIM + " --count 2 --snapshot", "zk monitor -p " + SIM + " --count 2 --frames"),
    ("zk decode --accept status F1 00 00 00 00 4C A0", "zk decode F1 00 00 00 00 4C A0"),
    ("zk decode F1 00 00 00 00 4C A0", "zk decode --raw F1 00 00 00 00 4C A0"),
    # (IDs 1-9: a record from the first frames, however a loaded machine slices half a second)
    ("zk send control --state stop --for 0.5 -p " + SIM + " --ids 1-9",
     "zk send control --state stop --for 0.5 -p " + SIM + " --ids 1-10"),
]


@pytest.mark.parametrize("first,second", APPEND_MISMATCH, ids=[b for _, b in APPEND_MISMATCH])
def test_append_onto_a_csv_with_other_columns_is_refused(cli, tmp_path, first, second):
    out = tmp_path / "log.csv"
    r = cli(*first.split(), "-f", "csv", "-o", str(out))
    assert r.exit_code == 0, r
    before = out.read_text()
    r = cli(*second.split(), "-f", "csv", "-o", str(out), "--append")
    assert r.exit_code == 2, r
    assert "has other CSV columns" in r.stderr
    assert out.read_text() == before


@pytest.mark.parametrize("fmt", ["csv", "jsonl", "json"])
@pytest.mark.parametrize("command", ["zk decode FF 1D F4 70", "zap decode FF FF FF 00 02 F1 0C",
                                     "zk monitor -p sim://zk?speed=20 --count 2"])
def test_append_after_a_cut_last_line_starts_a_new_line_and_json_stays_valid(cli, tmp_path, command, fmt):
    out = tmp_path / f"log.{fmt}"
    args = command.split() + ["-f", fmt, "-o", str(out)]
    assert cli(*args).exit_code == 0
    whole = out.read_text()
    if fmt != "json":
        with open(out, "a") as f:
            f.write(whole.splitlines()[-1][:7])          # a record cut by a killed run
    r = cli(*args, "--append")
    assert r.exit_code == 0, r
    text = out.read_text()
    if fmt == "json":
        records = json.loads(text)
        assert len(records) == 2 * len(json.loads(whole))
        r = cli(*args, "--append")
        assert len(json.loads(out.read_text())) == 3 * len(json.loads(whole))
        return
    lines = text.splitlines()
    n = len(whole.splitlines())
    cut = lines[n]
    assert len(cut) == 7                                 # the cut line stays apart
    rest = lines[n + 1:]
    assert len(rest) == n - (fmt == "csv")               # no second header
    if fmt == "jsonl":
        for line in rest:
            json.loads(line)


def test_append_continues_an_array_a_killed_run_left_open(cli, tmp_path):
    out = tmp_path / "log.json"
    out.write_text('[\n{"kind":"control","id":0}')
    r = cli("zk", "decode", "FF 1D F4 70", "-f", "json", "-o", str(out), "--append")
    assert r.exit_code == 0, r
    assert [rec["id"] for rec in json.loads(out.read_text())] == [0, 1]


@pytest.mark.parametrize("existing,fmt", [('{"a":1}\n', "json"), ("[\n{}\n]\n", "jsonl"), ("garbage", "json")])
def test_append_in_another_format_is_refused(cli, tmp_path, existing, fmt):
    out = tmp_path / "log.txt"
    out.write_text(existing)
    r = cli("zk", "decode", "FF 1D F4 70", "-f", fmt, "-o", str(out), "--append")
    assert r.exit_code == 2, r
    assert out.read_text() == existing


# --- --summary-json --------------------------------------------------------------------------

def test_summary_json_unwritable_is_refused_before_the_run(cli, tmp_path):
    out = tmp_path / "telemetry.csv"
    r = cli("zk", "profile", _schedule(tmp_path), "--sim", "-o", str(out),
            "--summary-json", str(tmp_path / "missing" / "summary.json"))
    assert r.exit_code == 2, r
    assert "summary-json: cannot open" in r.stderr
    assert not out.exists()                            # nothing ran


def test_a_failed_run_replaces_an_older_summary_with_its_failure(cli, tmp_path):
    summary = tmp_path / "summary.json"
    summary.write_text('{"outcome": "duration", "exit_status": 0}\n')
    r = cli("zk", "profile", _schedule(tmp_path), "-p", "/dev/ttyNOPE", "--summary-json", str(summary))
    assert r.exit_code == 4, r
    s = json.loads(summary.read_text())
    assert s["outcome"] == "error" and s["exit_status"] == 4 and "/dev/ttyNOPE" in s["error"]


def test_a_good_run_writes_the_summary_whole(cli, tmp_path):
    summary = tmp_path / "summary.json"
    summary.write_text("old")
    r = cli("zk", "profile", _schedule(tmp_path), "-p", SIM, "--summary-json", str(summary), "-o",
            str(tmp_path / "t.jsonl"))
    assert r.exit_code == 0, r
    s = json.loads(summary.read_text())
    assert s["outcome"] == "duration" and s["frames"] > 0
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []   # no temporary left
