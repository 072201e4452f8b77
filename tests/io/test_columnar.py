"""-o run.parquet and -o run.mf4: the records with their channel names and units, read back by
pyarrow and asammdf; a declared sensor's unit is kept; what the formats cannot do is refused."""

from __future__ import annotations

import pytest


def _run(cli, tmp_path, name):
    cell = tmp_path / "cell.log"
    cell.write_text("thrust_n=98.0665\n" * 5)
    out = tmp_path / name
    r = cli("zk", "monitor", "--sim", "--duration", "3", "-o", str(out), "--aux", f"{cell},thrust_n:N:0..500")
    assert r.exit_code == 0, r
    return out


def test_parquet_has_typed_columns_with_units(cli, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    table = pq.read_table(_run(cli, tmp_path, "run.parquet"))
    schema = table.schema
    assert table.num_rows > 20 and str(schema.field("time").type) == "timestamp[ms, tz=UTC]"
    assert schema.field("rpm").metadata == {b"unit": b"rpm"} and str(schema.field("rpm").type) == "double"
    assert schema.field("thrust_kg").metadata == {b"unit": b"kgf"}
    assert schema.field("thrust_n").metadata == {b"unit": b"N"}                    # the sensor's declared unit
    assert str(schema.field("engine_state_name").type) == "string"
    # the file's five readings, then stale (blank) 2 s after they came
    assert table.column("thrust_n").to_pylist()[0] == 98.0665 and table.column("thrust_n").to_pylist()[-1] is None
    ts = table.column("t").to_pylist()
    assert ts == sorted(ts) and len(set(ts)) == len(ts)


def test_mf4_has_channels_with_units_on_the_session_time(cli, tmp_path):
    asammdf = pytest.importorskip("asammdf")
    with asammdf.MDF(str(_run(cli, tmp_path, "run.mf4"))) as mdf:
        rpm, egt, thrust = mdf.get("rpm"), mdf.get("egt_c"), mdf.get("thrust_n")
        assert len(rpm.samples) > 20 and rpm.unit == "rpm" and egt.unit == "°C" and thrust.unit == "N"
        assert thrust.samples[0] == 98.0665 and thrust.samples[-1] != thrust.samples[-1]     # then stale: NaN
        assert rpm.timestamps[0] >= 0 and mdf.header.start_time.year >= 2024
        assert "engine_state_name" not in mdf.channels_db                   # text: its number is there


@pytest.mark.parametrize("fmt", ["parquet", "mf4"])
def test_what_the_formats_cannot_do_is_refused(cli, tmp_path, fmt):
    r = cli("zk", "monitor", "--sim", "--duration", "1", "-f", fmt)
    assert r.exit_code == 2 and f"format {fmt}: needs a file" in r.stderr, r
    r = cli("zk", "monitor", "--sim", "--duration", "1", "-o", str(tmp_path / f"r.{fmt}"), "--append")
    assert r.exit_code == 2 and "cannot be appended to" in r.stderr, r
