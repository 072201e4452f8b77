"""Inputs damaged or made up to crash a reader are exit 2 naming the file and what is wrong,
never exit 1 with a traceback: a record with a number no float holds, a summary whose limit
has a list for its field, a logbook whose text columns hold BLOBs, a capture whose times MCAP
cannot hold (and then no output file at all)."""

from __future__ import annotations

import csv
import json
import sqlite3

import pytest

BIG = "9" * 400


def _records(cli, tmp_path):
    """Status records as 'zk monitor -f jsonl' writes them (engine frames and voltages)."""
    return [{"t": round(0.02 * i, 3), "kind": "status", "id": 1 + i % 2, "rpm": 0, "egt_c": 20 + i,
             "engine_state_name": "stop"} for i in range(10)]


def test_a_record_with_a_400_digit_integer_is_named(cli, tmp_path):
    recs = _records(cli, tmp_path)
    jl = tmp_path / "big.jsonl"
    lines = [json.dumps(r) for r in recs]
    lines[3] = lines[3].replace('"rpm": 0', f'"rpm": {BIG}', 1)
    assert BIG in lines[3]
    jl.write_text("\n".join(lines) + "\n")
    r = cli("zk", "report", str(jl), "--terminal")
    assert r.exit_code == 2 and r.stdout == "", r
    assert f"{jl}:4: rpm: an integer of 400 digits is beyond a float's range" in r.stderr
    # the same as a CSV cell and in a JSON array
    rows = [["t", "id", "rpm"]] + [[str(x.get("t")), str(x.get("id")), str(x.get("rpm"))] for x in recs]
    rows[2][2] = BIG
    with open(tmp_path / "big.csv", "w", newline="") as f:
        csv.writer(f).writerows(rows)
    r = cli("zk", "report", str(tmp_path / "big.csv"), "--terminal")
    assert r.exit_code == 2 and "big.csv:3: rpm: " in r.stderr and "beyond a float's range" in r.stderr, r
    (tmp_path / "big.json").write_text("[\n" + ",\n".join(lines) + "\n]\n")
    r = cli("zk", "report", str(tmp_path / "big.json"), "--terminal")
    assert r.exit_code == 2 and "big.json:5: rpm: " in r.stderr, r


@pytest.mark.parametrize("key,value", [("field", [1, 2]), ("op", {"a": 1}), ("threshold", [900]),
                                       ("threshold", int(BIG)), ("warn", "800")])
def test_a_summary_limit_of_the_wrong_shape_is_named(cli, tmp_path, key, value):
    recs = _records(cli, tmp_path)
    (tmp_path / "tel.jsonl").write_text("".join(json.dumps(r) + "\n" for r in recs))
    limit = {"limit": "egt_c<=900", "field": "egt_c", "op": "<=", "threshold": 900.0, "warn": None,
             "verdict": "ok", "first_violation_t": None}
    limit[key] = value
    (tmp_path / "sum.json").write_text(json.dumps({"limits": [limit]}))
    r = cli("zk", "report", str(tmp_path / "tel.jsonl"), "--summary", str(tmp_path / "sum.json"), "--terminal")
    assert r.exit_code == 2 and r.stdout == "", r
    assert "sum.json: limits[0]: " in r.stderr and "is not a limit" in r.stderr, r


def _logbook(cli, tmp_path):
    db = tmp_path / "lb.db"
    r = cli("zk", "monitor", "-p", "sim://zk?speed=20", "--duration", "0.3", "--logbook", str(db),
            "--engine", "K1", "-o", str(tmp_path / "x.csv"))
    assert r.exit_code == 0, r
    assert cli("zk", "logbook", str(db), "--service", "K1").exit_code == 0
    return db


@pytest.mark.parametrize("table,column", [("runs", c) for c in ("started", "ended", "command", "port", "schedule",
                                                                "outcome", "engine", "max_rpm", "errors",
                                                                "throttle_s")]
                         + [("services", c) for c in ("at", "note")])
def test_a_logbook_blob_is_named(cli, tmp_path, table, column):
    db = _logbook(cli, tmp_path)
    with sqlite3.connect(db) as c:
        c.execute(f"UPDATE {table} SET {column} = X'DEADBEEF'")      # noqa: S608 - the test's own names
    for args in ([], ["-f", "json"], ["--engine", "K1"]) if table == "runs" else (["--engine", "K1"],):
        r = cli("zk", "logbook", str(db), *args)
        assert r.exit_code == 2 and r.stdout == "", (args, r)
        assert f": {column}: " in r.stderr and "Traceback" not in r.stderr, (args, r)


def test_a_logbook_with_an_extra_blob_column_still_lists(cli, tmp_path):
    db = _logbook(cli, tmp_path)
    with sqlite3.connect(db) as c:
        c.execute("ALTER TABLE runs ADD COLUMN photo BLOB")
        c.execute("UPDATE runs SET photo = X'00FF'")
    r = cli("zk", "logbook", str(db), "-f", "json")
    assert r.exit_code == 0, r
    doc = json.loads(r.stdout)
    assert len(doc["runs"]) == 1 and doc["totals"]["runs"] + doc["totals"]["simulated_runs"] == 1


@pytest.mark.parametrize("ts", [2.0e10, 1.9e10])
def test_a_capture_mcap_cannot_date_leaves_no_file(cli, tmp_path, ts):
    pytest.importorskip("mcap")
    from zkzap.codec import zk
    from zkzap.link.pcapng import INBOUND, Writer

    cap = tmp_path / "far.pcapng"
    w = Writer(str(cap))
    i = w.interface("zk", "/dev/ttyUSB0", 115200)
    for k in range(3):
        w.packet(i, ts + k, zk.encode_status(1, rpm=0, egt_c=20), INBOUND)
    w.close()
    out = tmp_path / "x.mcap"
    r = cli("zk", "monitor", "--replay", str(cap), "-o", str(out))
    assert r.exit_code == 2, r
    assert "MCAP's log time" in r.stderr and "Traceback" not in r.stderr, r
    assert not out.exists()
