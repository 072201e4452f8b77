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


MF4_SCRIPT = """
import json, math, os, resource, sys
from zkzap.io.columnar import writer
path, n = sys.argv[1], int(sys.argv[2])
cols = ["t", "time", "engine_state_name"] + [f"c{j}" for j in range(20)]
w = writer("mf4", path, cols, {"c0": "N"})
def rec(i):
    r = {"t": i * 0.02, "time": "2026-01-01T00:00:00.000Z", "engine_state_name": "running"}
    for j in range(20):
        r[f"c{j}"] = math.nan if (i + j) % 97 == 0 else i * 0.5 + j
    return r
for i in range(5000):
    w.write(rec(i))
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
on_disk = 0
for i in range(5000, n):
    w.write(rec(i))
    if i == n // 2:
        on_disk = os.path.getsize(w.tmp)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
w.close()
print(json.dumps({"grown_kib": peak - base, "on_disk_half": on_disk}))
"""


def test_mf4_is_streamed_to_disk_in_constant_memory(tmp_path):
    """200,000 records of 21 channels (34 MB): the memory after the first 5,000 does not grow, and
    half-way through the file already holds half of them; asammdf reads every value back."""
    import json
    import subprocess
    import sys

    asammdf = pytest.importorskip("asammdf")
    path = tmp_path / "big.mf4"
    n = 200_000
    out = subprocess.run([sys.executable, "-c", MF4_SCRIPT, str(path), str(n)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    record = 8 * 21
    assert got["on_disk_half"] >= (n // 2 - 256) * record                # appended as it came, not at the end
    assert got["grown_kib"] < 4096, got                                  # a chunk, not the run
    assert path.stat().st_size >= n * record and path.read_bytes()[:8] == b"MDF     "
    with asammdf.MDF(str(path)) as mdf:
        c0, c7 = mdf.get("c0"), mdf.get("c7")
        assert len(c0.samples) == n and c0.unit == "N" and "engine_state_name" not in mdf.channels_db
        assert c7.samples[12345] == 12345 * 0.5 + 7 and c7.timestamps[12345] == 12345 * 0.02
        assert c0.samples[97] != c0.samples[97]                         # no value: NaN
        assert mdf.header.start_time.year == 2026
