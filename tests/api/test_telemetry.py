"""Telemetry rules: frames held until status ID 6, the default version, snapshot rows, the --ids
filter, the stale rule, health, the summary and ECU error tracking; the shared helpers."""

import pytest

from zkzap.api.telemetry import HOLD_FRAMES, Telemetry, iso_utc, parse_ids, record_columns
from zkzap.codec import zk
from zkzap.errors import UsageError


def frames_of(ecu, seconds, start=0.0):
    from zkzap.codec.framing import ZkFramer

    data = ecu.poll(start + seconds)
    return ZkFramer("status").feed(data)


def test_frames_are_held_until_id6_so_voltages_use_the_ecu_unit():
    from zkzap.sim.zk_ecu import ZkEcu

    frames = frames_of(ZkEcu(protocol_version=3), 0.99)
    frames = frames[1:] + frames[:1]                                   # start mid-cycle, at ID 2
    tel = Telemetry()
    out = []
    for i, f in enumerate(frames):
        out += tel.feed(i * 0.05, f)
    assert out[0]["id"] == 2 and out[0]["power_voltage_v"] == 12.0    # 0.1 V units, version 3
    assert tel.decoder.version == 3 and tel.version_note is None
    given = Telemetry(protocol_version=4)                            # told wrong: decoded at once
    assert given.feed(0.0, frames[0])[0]["power_voltage_v"] == 24.0


def test_without_id6_the_default_version_is_used_and_said():
    from zkzap.sim.zk_ecu import ZkEcu

    frames = [f for f in frames_of(ZkEcu(), 2.0) if f[0] != 0xF6]
    tel = Telemetry()
    out = []
    for i, f in enumerate(frames[:5]):
        out += tel.feed(i * 0.05, f)
    assert out == []
    out += tel.flush()
    assert len(out) == 5 and "assume protocol version 4" in tel.version_note
    tel = Telemetry()
    for i, f in enumerate(frames[:HOLD_FRAMES]):
        out = tel.feed(i * 0.05, f)
    assert len(out) == HOLD_FRAMES


def test_snapshot_rows_ids_filter_and_stale_rule():
    from zkzap.sim.zk_ecu import ZkEcu

    frames = frames_of(ZkEcu(), 1.99)
    tel = Telemetry(ids=frozenset({1, 6}), snapshot=True)
    rows = []
    for i, f in enumerate(frames):
        rows += tel.feed(i * 0.05, f)
    assert [r["id"] for r in rows] == [1, 6] * 4
    assert list(rows[0]) == record_columns(True, frozenset({1, 6}))
    assert rows[-1]["max_rpm"] == 160000 and rows[-1]["egt_c"] == 20 and "pump_voltage_v" not in rows[-1]
    assert not any(r["stale"] for r in rows)
    # IDs 1..10 at 20 Hz: 0.5 s apiece; stale after 3 periods (ID 1 last at 1.5 s, ID 6 at 1.75 s)
    assert tel.stale_ids(2.95) == [] and tel.stale_ids(3.05) == [1] and tel.stale_ids(3.3) == [1, 6]
    h = tel.health(3.3, None)
    assert h["stale"] is True and h["protocol_version"] == 6 and h["version_source"] == "frame"
    assert h["frames"] == 40
    snap = tel.snapshot(3.0)
    assert snap["time_s"] == 3.0 and set(zk.STATUS_KEYS) <= set(snap)


def test_summary_and_error_tracking():
    tel = Telemetry(protocol_version=6)

    def one(t, state, code, egt, rpm):
        return tel.feed(t, zk.encode_status(1, 6, rpm=rpm, engine_state=state, error_code=code, egt_c=egt,
                                           sw_state=2))

    one(0.0, 11, 2, 500, 80000)
    assert tel.new_error is None                                       # present at the start
    one(0.5, 11, 0, 650, 90000)
    one(1.0, 12, 8, 700, 50000)
    assert tel.new_error == (8, "egt-high", 1.0)
    tel.feed(1.2, zk.encode_status(7, 6, fuel_flow_l_min=0.2, fuel_used_l=1.0))
    tel.feed(1.7, zk.encode_status(7, 6, fuel_flow_l_min=0.2, fuel_used_l=1.3))
    s = tel.summary()
    assert s["max_rpm"] == 90000 and s["max_egt_c"] == 700 and s["fuel_used_l"] == 0.3
    assert s["states"] == ["running", "cooling"]
    assert [e["code"] for e in s["errors"]] == [2, 8]


def test_parse_ids():
    assert parse_ids("1,2,6") == {1, 2, 6}
    assert parse_ids("1-3, 9") == {1, 2, 3, 9}
    for bad, msg in (("0", "out of range"), ("15", "out of range"), ("a", "not an ID"), ("3-1", "empty range"),
                     (",", "no ID given")):
        with pytest.raises(UsageError, match=msg):
            parse_ids(bad)


def test_iso_utc():
    assert iso_utc(0.5) == "1970-01-01T00:00:00.500Z"
    assert iso_utc(1700000000.123) == "2023-11-14T22:13:20.123Z"
