"""zk report's inputs come from the field: whatever the run, steps or summary file holds, the
report is drawn or refused in one line naming the file (and line or key), exit 2, never a
traceback. Drawn with --terminal (rich only), so matplotlib is not needed here."""

from __future__ import annotations

import json

import pytest

CSV = "time,t,rpm,egt_c,engine_state_name\n" + "".join(
    f"2026-01-01T00:00:{i:02d}.000Z,{i},{1000 * i},{20 + i},{'running' if i > 3 else 'ignition'}\n" for i in range(10))
STEPS = "step,mode,state,target,step_start_s,step_end_s,rpm_mean,thrust_kg_mean\n1,throttle,run,40,0,9,5000,1.5\n"
SUMMARY = {"duration_s": 9.0, "states": ["ignition", "running"], "errors": [{"code": 7, "name": "egt-high", "t": 3.0}],
           "limits": [{"limit": "egt_c<=600", "verdict": "ok", "first_violation_t": None, "extreme": 29}]}


def _files(tmp_path, run=CSV.encode(), steps=STEPS.encode(), summary=json.dumps(SUMMARY).encode(), name="tel.csv"):
    paths = {}
    for key, n, data in (("run", name, run), ("steps", "steps.csv", steps), ("summary", "sum.json", summary)):
        p = tmp_path / n
        p.write_bytes(data)
        paths[key] = str(p)
    return paths


def report(cli, f):
    return cli("zk", "report", f["run"], "--steps", f["steps"], "--summary", f["summary"], "--terminal")


def test_whole_inputs_draw(cli, tmp_path):
    r = report(cli, _files(tmp_path))
    assert r.exit_code == 0 and "Engine speed" in r.stdout, r


def _with(text: bytes, at: int, junk: bytes) -> bytes:
    return text[:at] + junk + text[at:]


SUMMARY_TEXT = json.dumps(SUMMARY, indent=1).encode()

#: (which file, its content, the one line expected on stderr)
BAD = [
    ("run", _with(CSV.encode(), 120, b"\xff"),
     f"run: {{run}}:{CSV[:120].count(chr(10)) + 1}: not UTF-8 text (byte 0xFF at byte 120)"),
    ("run", b"\xef\xbb\xbf" + _with(CSV.encode(), 40, b"\xc3"), "run: {run}:2: not UTF-8 text (byte 0xC3 at byte 43)"),
    ("run", b"t,rpm\n0,\"" + b"9" * 200_000 + b"\"\n", "run: {run}:2: not a CSV row: field larger than field limit"),
    ("run", b"\xff\xfet\x00,\x00", "run: {run}: UTF-16 text"),
    ("steps", _with(STEPS.encode(), 90, b"\xfe"), "steps: {steps}:2: not UTF-8 text (byte 0xFE at byte 90)"),
    ("summary", _with(SUMMARY_TEXT, 10, b"\xff"), "summary: {summary}:2: not UTF-8 text (byte 0xFF at byte 10)"),
    ("summary", json.dumps({**SUMMARY, "states": ["ignition", 5]}).encode(),
     "summary: {summary}: states[1]: 5 is not a state name (a string)"),
    ("summary", json.dumps({**SUMMARY, "errors": [7]}).encode(),
     "summary: {summary}: errors[0]: 7 is not an ECU error: an object with code, name and t"),
    ("summary", json.dumps({**SUMMARY, "limits": [{"limit": 3}]}).encode(),
     "summary: {summary}: limits[0]: {{\"limit\": 3}} is not a limit"),
    ("summary", json.dumps({**SUMMARY, "states": "running"}).encode(),
     "summary: {summary}: states: \"running\" is not a list of state names"),
    ("summary", b"[" * 5000, "summary: {summary}:1: nested more than 100 levels deep"),
    ("summary", b'{"frames": 1, "frames": 2}', "summary: {summary}:1: key 'frames' is given twice"),
]


@pytest.mark.parametrize("which,content,said", BAD, ids=[f"{b[0]}-{i}" for i, b in enumerate(BAD)])
def test_a_bad_input_is_one_line_naming_the_file(cli, tmp_path, which, content, said):
    f = _files(tmp_path, **{which: content})
    r = report(cli, f)
    assert (r.exit_code, r.stdout) == (2, ""), r
    assert said.format(**f) in r.stderr and len(r.stderr.splitlines()) == 1, r.stderr


@pytest.mark.parametrize("text,said", [
    ('{"t": 0, "rpm": 1}\n[1]\n', "run: {run}:2: not a JSON record (an object)"),
    ('{"t": 0, "rpm": 1}\n{"t": 1, \n', "run: {run}:2: not a JSON record"),
    ('{"t": 0}\n' + "[" * 100_000 + "\n", "run: {run}:2: not a JSON record"),
    ('[\n{"t": 0, "rpm": 1},\n7\n]\n', "run: {run}:3: not a JSON record (an object)"),
    ('[\n{"t": 0, "rpm": 1}\n]\n{"t": 1}\n', "run: {run}:4: text after the JSON array's closing bracket"),
])
def test_json_runs_name_the_line_of_what_is_not_a_record(cli, tmp_path, text, said):
    f = _files(tmp_path, run=text.encode(), name="tel.json")
    r = report(cli, f)
    assert (r.exit_code, r.stdout) == (2, ""), r
    assert said.format(**f) in r.stderr, r.stderr


def test_a_json_array_cut_by_a_killed_run_reads_to_its_last_whole_record(cli, tmp_path):
    whole = "[\n" + ",\n".join(json.dumps({"t": i, "rpm": 1000 * i, "engine_state_name": ["odd"]})
                               for i in range(5)) + "\n]\n"
    for cut, records, also in ((3, 5, ""), (10, 4, " and its last record is cut")):
        f = _files(tmp_path, run=whole[:-cut].encode(), name="tel.json")
        r = report(cli, f)
        assert r.exit_code == 0, r
        assert f"{f['run']}: the JSON array is not closed{also} (a run that was stopped by force?): " \
               f"read its {records} whole records" in r.stderr
    # laid out over many lines, as another tool pretty-prints it
    f = _files(tmp_path, run=json.dumps([{"t": i, "rpm": i} for i in range(3)], indent=4).encode(), name="t.json")
    r = report(cli, f)
    assert r.exit_code == 0 and "not closed" not in r.stderr, r


def test_what_is_not_a_run_is_refused(cli, tmp_path):
    import random

    rnd = random.Random(36)
    junk = tmp_path / "chunk.bin"
    junk.write_bytes(bytes(rnd.randrange(256) for _ in range(100_000)))       # frames a CRC lets through
    r = cli("zk", "report", str(junk), "--terminal")
    assert r.exit_code == 2 and "not a run" in r.stderr and "are no ZK status frame" in r.stderr, r
    few = tmp_path / "few.bin"
    from zkzap.codec import zk

    few.write_bytes(b"".join(zk.encode_status(1, rpm=50000, engine_state=6, error_code=0, egt_c=500, sw_state=3)
                             for _ in range(3)))
    r = cli("zk", "report", str(few), "--terminal")
    assert r.exit_code == 2 and "not a run: 3 status records (at least 10)" in r.stderr, r
    wild = tmp_path / "wild.csv"
    wild.write_text("t,rpm,throttle_pct\n" + "".join(f"{i},{650000 + i},160\n" for i in range(20)))
    r = cli("zk", "report", str(wild), "--terminal")
    assert r.exit_code == 2 and "outside the protocol's range" in r.stderr and "throttle_pct 160" in r.stderr, r


def test_its_own_workbook_and_mcap_are_runs(cli, tmp_path):
    pytest.importorskip("openpyxl")
    pytest.importorskip("mcap")
    for name in ("run.xlsx", "run.mcap"):
        out = tmp_path / name
        r = cli("zk", "monitor", "--sim", "--duration", "2", "-o", str(out))
        assert r.exit_code == 0, r
        r = cli("zk", "report", str(out), "--terminal")
        assert r.exit_code == 0 and "Engine speed" in r.stdout and "not a run" not in r.stderr, (name, r)
