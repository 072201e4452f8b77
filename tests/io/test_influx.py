"""InfluxDB line protocol (``-f influx``): the spec's escaping rules and types, worked examples,
an independent parser from PyPI, and the commands that write it."""

from __future__ import annotations

import io
import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zkzap.io.writers import InfluxWriter, lp_field_value, lp_key, lp_measurement

lpp = pytest.importorskip("line_protocol_parser")


def line(rec, **kw):
    s = io.StringIO()
    w = InfluxWriter(s, **kw)
    w.write(rec)
    w.close()
    text = s.getvalue()
    assert text.endswith("\n") and text.count("\n") == 1
    return text[:-1]


# --- the spec's escaping rules (docs.influxdata.com, line protocol reference) -------------------

@pytest.mark.parametrize("raw,escaped", [
    ("my measurement", "my\\ measurement"),
    ("a,b", "a\\,b"),
    ("a=b", "a=b"),                       # equals signs need no escape in a measurement
])
def test_measurement_escapes_commas_and_spaces(raw, escaped):
    assert lp_measurement(raw) == escaped


@pytest.mark.parametrize("raw,escaped", [
    ("tag key", "tag\\ key"), ("a,b", "a\\,b"), ("a=b", "a\\=b"), ("plain_key", "plain_key"),
])
def test_keys_and_tag_values_escape_commas_equals_spaces(raw, escaped):
    assert lp_key(raw) == escaped


@pytest.mark.parametrize("value,text", [
    (1, "1i"), (-3, "-3i"), (0, "0i"), (1.5, "1.5"), (12.0, "12.0"), (True, "true"), (False, "false"),
    ("run", '"run"'), ('say "hi"', '"say \\"hi\\""'), ("back\\slash", '"back\\\\slash"'),
    ([1, 2], '"1;2"'), ([], '""'), (None, None), (float("nan"), None), (float("inf"), None),
])
def test_field_values_are_typed(value, text):
    assert lp_field_value(value) == text


def test_a_status_record_line():
    rec = {"time": "2024-05-01T12:00:00.123Z", "t": 0.5, "kind": "status", "id": 1, "rpm": 40000,
           "engine_state": 10, "engine_state_name": "running", "egt_c": 580, "stale": False, "stale_ids": [],
           "frame": "F1 ..."}
    assert line(rec) == ('status,id=1,kind=status t=0.5,rpm=40000i,engine_state=10i,engine_state_name="running",'
                         'egt_c=580i,stale=false,stale_ids="",frame="F1 ..." 1714564800123000000')


def test_nulls_and_private_keys_are_left_out_and_no_time_means_no_timestamp():
    assert line({"kind": "control", "id": 7, "target_rpm": None, "rpm_value": 3333, "_summary": "x"}) == \
        "control,id=7,kind=control rpm_value=3333i"


def test_a_record_without_kind_uses_the_default_measurement_and_keeps_a_field():
    assert line({"id": 3}, default_measurement="status") == "status,id=3 present=true"


def test_timestamps_are_nanoseconds_from_the_record_time():
    s = io.StringIO()
    w = InfluxWriter(s)
    for ms in ("000", "010", "999"):
        w.write({"kind": "status", "id": 1, "time": f"2026-12-01T10:00:59.{ms}Z", "rpm": 1})
    w.write({"kind": "status", "id": 1, "time": "2026-12-01T10:01:00.000Z", "rpm": 1})
    stamps = [int(x.rsplit(" ", 1)[1]) for x in s.getvalue().splitlines()]
    assert [b - stamps[0] for b in stamps] == [0, 10_000_000, 999_000_000, 1_000_000_000]
    assert stamps[0] == 1796119259 * 10**9


# --- through an independent parser ----------------------------------------------------------------

_text = st.text(st.characters(blacklist_categories=("Cs", "Cc")), min_size=1, max_size=12)
# names: the spec leaves a backslash before a separator ambiguous, and a line starting with '#' is a
# comment; zkzap's kinds and keys have neither
_name = st.text(st.characters(blacklist_categories=("Cs", "Cc"), blacklist_characters="\\"), min_size=1,
                max_size=12).filter(lambda s: not s.startswith("#"))


@settings(max_examples=100, deadline=None)
@given(kind=_name, key=_name.filter(lambda k: not k.startswith("_") and k not in ("id", "kind", "time")),
       # (the parser's strtod refuses subnormal floats, which InfluxDB reads; no ZK field has one)
       value=st.one_of(st.integers(-2**63, 2**63 - 1),
                       st.floats(allow_nan=False, allow_infinity=False, allow_subnormal=False),
                       st.booleans(), _text), ident=st.integers(0, 253))
def test_any_record_parses_back_with_line_protocol_parser(kind, key, value, ident):
    rec = {"time": "2024-05-01T12:00:00.001Z", "kind": kind, "id": ident, key: value}
    parsed = lpp.parse_line(line(rec) + "\n")
    assert parsed["measurement"] == kind
    assert parsed["tags"] == {"id": str(ident), "kind": kind}
    assert parsed["time"] == 1714564800001000000
    got = parsed["fields"][key]
    if isinstance(value, float):
        assert got == pytest.approx(value, rel=1e-15, abs=0)
    else:
        assert got == value and type(got) is type(value)


# --- the commands ---------------------------------------------------------------------------------

def test_zk_decode_writes_line_protocol(cli):
    r = cli("zk", "decode", "FF 1D F4 70", "F1 00 00 00 00 4C A0", "-f", "influx")
    assert r.exit_code == 0, r
    lines = [lpp.parse_line(x + "\n") for x in r.stdout.splitlines()]
    assert [x["measurement"] for x in lines] == ["control", "status"]
    assert lines[0]["fields"]["throttle_pct"] == 50.0 and lines[0]["fields"]["state"] == "run"
    assert lines[1]["fields"]["egt_c"] == 26 and lines[1]["tags"] == {"id": "1", "kind": "status"}
    assert "_summary" not in r.stdout


def test_zap_decode_writes_line_protocol(cli):
    r = cli("zap", "decode", "FF FF FF 00 04 F2 8C 02 7B", "FF FF FF 00 04 00 FF 07 F5", "-f", "influx")
    assert r.exit_code == 0, r
    lines = [lpp.parse_line(x + "\n") for x in r.stdout.splitlines()]
    assert [x["measurement"] for x in lines] == ["command", "feedback"]
    assert lines[1]["fields"]["value"] == 2047 and lines[1]["fields"]["register"] == "present-position"


def test_monitor_in_line_protocol_matches_its_json_lines(cli, tmp_path):
    raw = tmp_path / "run.bin"
    r = cli("zk", "monitor", "-p", "sim://zk?speed=20", "--count", "40", "-f", "jsonl", "--raw-log", str(raw))
    assert r.exit_code == 0, r
    want = [json.loads(x) for x in r.stdout.splitlines()]
    r = cli("zk", "monitor", "--replay", str(raw), "--fast", "--count", "40", "-o", str(tmp_path / "run.lp"))
    assert r.exit_code == 0, r
    got = [lpp.parse_line(x + "\n") for x in (tmp_path / "run.lp").read_text().splitlines()]
    assert len(got) == len(want) == 40
    for g, w in zip(got, want):
        assert g["measurement"] == "status" and g["tags"] == {"id": str(w["id"]), "kind": "status"}
        fields = {k: v for k, v in w.items() if k not in ("time", "t", "id", "kind", "stale", "stale_ids")
                  and v is not None}
        assert {k: g["fields"][k] for k in fields} == fields


def test_monitor_snapshot_rows_in_line_protocol(cli):
    r = cli("zk", "monitor", "-p", "sim://zk?speed=20", "--count", "12", "-f", "influx", "--snapshot")
    assert r.exit_code == 0, r
    first = lpp.parse_line(r.stdout.splitlines()[-1] + "\n")
    assert first["measurement"] == "status" and "rpm" in first["fields"] and "egt_c" in first["fields"]


def test_every_line_of_a_series_gets_its_own_time():
    import io as _io

    from zkzap.io.writers import InfluxWriter

    buf = _io.StringIO()
    w = InfluxWriter(buf)
    for rpm in (1, 2, 3):                       # three records of one series within one millisecond
        w.write({"time": "2026-01-01T00:00:00.123Z", "t": 0.1, "kind": "status", "id": 1, "rpm": rpm})
    w.write({"time": "2026-01-01T00:00:00.123Z", "t": 0.1, "kind": "status", "id": 2, "rpm": 4})
    stamps = [line.rsplit(" ", 1)[1] for line in buf.getvalue().splitlines()]
    base = 1767225600123000000
    assert stamps == [str(base), str(base + 1), str(base + 2), str(base)]     # another series keeps its own
