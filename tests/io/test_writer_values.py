"""No output format writes a value it cannot hold: whatever numbers reach a writer (NaN,
±Infinity, 1e400 read as a float, an integer of 5000 digits, beside ordinary values, in lists
and dicts too), every format's output is read back by a strict reader of that format, and a
number it could not hold is there as no value. Every format of a logging session is tried."""

from __future__ import annotations

import csv
import io
import json
import math
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zkzap.io import SESSION_FORMATS
from zkzap.io.writers import make_writer

COLUMNS = ["time", "t", "kind", "id", "a", "b", "c", "d"]
ODD = [math.nan, math.inf, -math.inf, float("1e400"), 10 ** 5000, -(10 ** 5000), 2 ** 64, -(2 ** 63) - 1,
       10 ** 400]
values = st.one_of(st.sampled_from(ODD), st.floats(), st.integers(), st.none(), st.booleans(),
                   st.text(max_size=8), st.lists(st.sampled_from(ODD + [1, 2.5]), max_size=3),
                   st.dictionaries(st.sampled_from(["x", "y"]), st.sampled_from(ODD + [1]), max_size=2))
records = st.lists(st.fixed_dictionaries({"t": st.floats(0, 1e6), "kind": st.just("status"), "id": st.just(1)},
                                         optional={k: values for k in "abcd"}), min_size=1, max_size=4)


def _strict_json(text):
    def refuse(name):
        raise AssertionError(f"{name} in JSON output")
    return json.loads(text, parse_constant=refuse)


def _finite_numbers(value):
    if isinstance(value, dict):
        return all(_finite_numbers(v) for v in value.values())
    if isinstance(value, list):
        return all(_finite_numbers(v) for v in value)
    return not isinstance(value, float) or math.isfinite(value)


def _check_jsonl(text, recs):
    lines = text.split("\n")[:-1]
    assert len(lines) == len(recs)
    for line in lines:
        assert _finite_numbers(_strict_json(line))


def _check_json(text, recs):
    doc = _strict_json(text)
    assert len(doc) == len(recs) and _finite_numbers(doc)


_NOT_NUMBERS = re.compile(r"(?i)^[-+]?(nan|inf|infinity)$")


def _check_csv(text, recs):
    rows = list(csv.reader(io.StringIO(text)))
    assert rows[0] == COLUMNS and len(rows) == len(recs) + 1
    for row in rows[1:]:
        for cell in row:
            for part in re.split(r"[;=]", cell):
                assert not _NOT_NUMBERS.match(part), row
                if re.fullmatch(r"-?\d+", part):
                    assert len(part) < 4400


_LP_FIELD = re.compile(r'([^=,]+)=("(?:[^"\\]|\\.)*"|[^,]*)')


def _check_influx(text, recs):
    lines = text.split("\n")[:-1]            # only a newline ends a line of line protocol
    assert len(lines) == len(recs)
    for line in lines:
        head, fields = line.split(" ", 2)[:2]
        for _key, value in _LP_FIELD.findall(fields):
            if value.startswith('"') or value in ("true", "false"):
                continue
            if value.endswith("i"):
                assert -(1 << 63) <= int(value[:-1]) < 1 << 63, line
            else:
                assert math.isfinite(float(value)), line


def _write(fmt, recs, tmp_path):
    if fmt == "mcap":
        from zkzap.io.mcap import McapWriter

        out = io.BytesIO()
        w = McapWriter(out, flush_s=0)
        for r in recs:
            w.write(r)
        w.close()
        return out.getvalue()
    if fmt == "xlsx":
        from zkzap.io.xlsx import XlsxWriter

        path = tmp_path / "x.xlsx"
        if path.exists():
            path.unlink()
        w = XlsxWriter(str(path), COLUMNS)
        for r in recs:
            w.write(r)
        w.close()
        return path
    if fmt in ("parquet", "mf4"):
        from zkzap.io.columnar import writer

        path = tmp_path / f"x.{fmt}"
        if path.exists():
            path.unlink()
        w = writer(fmt, str(path), COLUMNS)
        for r in recs:
            w.write(r)
        w.close()
        return path
    out = io.StringIO()
    w = make_writer(fmt, out, COLUMNS)
    for r in recs:
        w.write(r)
    w.close()
    return out.getvalue()


def _check_mcap(data, recs):
    from mcap.reader import make_reader

    messages = [m for _, _, m in make_reader(io.BytesIO(data)).iter_messages()]
    assert len(messages) == len(recs)
    for m in messages:
        assert _finite_numbers(_strict_json(m.data.decode("utf-8")))


def _check_xlsx(path, recs):
    from openpyxl import load_workbook

    sheet = load_workbook(path, read_only=True).worksheets[0]
    rows = list(sheet.iter_rows(values_only=True))
    assert len(rows) == len(recs) + 2                 # the header and the units
    for row in rows[2:]:
        for v in row:
            assert not isinstance(v, (int, float)) or math.isfinite(float(v)), row
            assert not (isinstance(v, str) and _NOT_NUMBERS.match(v)), row


def _check_parquet(path, recs):
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    assert table.num_rows == len(recs)
    for column in table.columns:
        for v in column.to_pylist():
            assert not isinstance(v, float) or math.isfinite(v), column
            assert not (isinstance(v, str) and any(_NOT_NUMBERS.match(p) for p in re.split(r"[;=]", v))), column


def _check_mf4(path, recs):
    from asammdf import MDF

    with MDF(str(path)) as mdf:
        for name in mdf.channels_db:
            s = mdf.get(name)
            assert len(s.samples) == len(recs)
            # NaN is MDF's sample without a value; an infinity would be a wrong one
            assert all(not math.isinf(float(v)) for v in s.samples), name


CHECKS = {"jsonl": _check_jsonl, "json": _check_json, "csv": _check_csv, "influx": _check_influx,
          "mcap": _check_mcap, "xlsx": _check_xlsx, "parquet": _check_parquet, "mf4": _check_mf4}
WRITTEN = [f for f in SESSION_FORMATS if f != "table"]
NEEDS = {"mcap": "mcap", "xlsx": "openpyxl", "parquet": "pyarrow", "mf4": "asammdf"}


def test_every_format_has_a_strict_reader_here():
    assert set(WRITTEN) <= set(CHECKS), f"no strict reader for {sorted(set(WRITTEN) - set(CHECKS))}"


@pytest.mark.parametrize("fmt", WRITTEN)
@settings(max_examples=25, deadline=None)
@given(recs=records)
def test_no_format_writes_a_number_it_cannot_hold(fmt, recs, tmp_path_factory):
    if fmt in NEEDS:
        pytest.importorskip(NEEDS[fmt])
    _check = CHECKS[fmt]
    _check(_write(fmt, recs, tmp_path_factory.mktemp(fmt)), recs)


def test_a_value_it_cannot_hold_is_no_value_and_the_rest_is_kept():
    rec = {"t": 1.5, "kind": "status", "id": 1, "a": math.nan, "b": 2.25, "c": [math.inf, 3], "d": 10 ** 5000}
    assert _strict_json(_write("jsonl", [rec], None)) == {"t": 1.5, "kind": "status", "id": 1, "a": None,
                                                          "b": 2.25, "c": [None, 3], "d": None}
    assert _write("csv", [rec], None).splitlines()[1] == ",1.5,status,1,,2.25,;3,"
    line = _write("influx", [{**rec, "e": 2 ** 70, "f": -math.inf}], None)
    assert " t=1.5,b=2.25,c=\";3\",e=1.1805916207174113e+21\n" in line
