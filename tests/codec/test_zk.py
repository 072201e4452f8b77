"""ZK control and status frames: worked examples, ranges, round trips."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from zkzap.codec import zk
from zkzap.codec.crc import crc8_maxim
from zkzap.codec.fields import FieldValueError


def h(text):
    return bytes.fromhex(text)


# --- worked examples of the document ------------------------------------------------------------

def test_control_example_1():
    frame, notes = zk.encode_control("control", sw="stop", throttle_pct=10.0)
    assert frame == h("FF1464D3") and notes == []
    rec = zk.decode_control(frame)
    assert rec == {"kind": "control", "id": 1, "command": "control", "sw": 1, "state": "stop", "throttle_pct": 10.0}


def test_control_example_2():
    frame, _ = zk.encode_control("control", sw="run", throttle_pct=50)
    assert frame == h("FF1DF470")
    rec = zk.decode_control(h("FF1DF470"))
    assert (rec["sw"], rec["state"], rec["throttle_pct"]) == (3, "run", 50.0)


def test_status_example_1():
    frame = h("F1000000004CA0")
    zk.check_status(frame)
    rec = zk.decode_status(frame)
    assert rec == {"kind": "status", "id": 1, "rpm": 0, "engine_state": 0, "engine_state_name": "stop",
                   "error_code": 0, "error_name": "none", "egt_c": 26, "sw_state": 0, "sw_state_name": "stop"}


def test_status_example_2():
    frame = h("F60000A00010AB")
    zk.check_status(frame)
    rec = zk.decode_status(frame)
    assert rec["max_rpm"] == 160000
    assert rec["max_pump_voltage_v"] == 0.0
    assert rec["protocol_version"] == 4
    assert rec["status_rate_hz"] == 20


def test_bad_crc_is_reported_with_expected_and_found():
    with pytest.raises(zk.CrcError) as e:
        zk.check_control(h("FF1464D4"))
    assert (e.value.expected, e.value.found) == (0xD3, 0xD4)
    assert "expected D3, found D4" in str(e.value)
    with pytest.raises(zk.CrcError):
        zk.check_status(h("F1000000004CA1"))


def test_wrong_lengths_and_heads():
    for bad in (h("FF1464"), h("F1000000004C"), h("00")):
        with pytest.raises(zk.FrameError):
            zk.check_frame(bad)
    with pytest.raises(zk.FrameError, match="head"):
        zk.check_control(h("FE1464D3"))


# --- field layouts (docs/protocol.md) -----------------------------------------------------------

def test_every_control_command_has_its_id_in_b1_high_nibble():
    for cmd in zk.CONTROL:
        frame = zk.encode_control_raw(cmd.id)
        assert frame[0] == 0xFF and frame[1] >> 4 == cmd.id
        assert frame[3] == crc8_maxim(frame[1:3])


def test_control_layouts():
    assert zk.encode_control("action", param="pump-off")[0][1:3] == bytes([0x20, 13])
    assert zk.encode_control("ignition-voltage", ignition_voltage_v=5.1)[0][1:3] == bytes([0x40, 255])
    assert zk.encode_control("accel-curve", accel_curve=70)[0][1:3] == bytes([0x50, 70])
    # ID 6: RPM_X in b2[4:2], SW in b2[1:0]
    assert zk.encode_control("mode", rpm_factor=6, sw="run")[0][1:3] == bytes([0x60, (6 << 2) | 3])
    # ID 7: 12-bit value, b1[3:0] high
    frame, _ = zk.encode_control("rpm", target_rpm=4095 * 10 * 2, rpm_factor=2)
    assert frame[1:3] == bytes([0x7F, 0xFF])
    # ID 8: 10-bit pressure, b1[1:0] high
    assert zk.encode_control("pressure", pressure_hpa=1023)[0][1:3] == bytes([0x83, 0xFF])


def test_action_names_in_document_order():
    assert list(zk.ACTIONS.values()) == [
        "drain-oil", "test-glowplug", "test-main-valve", "test-ignition-valve", "test-pump", "test-starter",
        "rate-20hz", "rate-50hz", "rate-100hz", "reset-fuel", "zero-thrust", "pump-on", "pump-off"]
    assert list(zk.ACTIONS) == list(range(1, 14))


def test_status_layouts():
    # ID 1: error code = b4[1:0] << 3 | b3[7:5]; EGT = (b4[4:2] << 8 | b5) - 50; SwSt = b4[6:5]
    frame = zk.status_frame(1, [0x10, 0x27, 0b101_01011, 0b0_10_011_10, 0x20])
    rec = zk.decode_status(frame)
    assert rec["rpm"] == 0x2710 * 10
    assert rec["engine_state"] == 11 and rec["engine_state_name"] == "running"
    assert rec["error_code"] == (0b10 << 3) | 0b101 == 21
    assert rec["error_name"] == "undocumented-21"
    assert rec["egt_c"] == ((0b011 << 8) | 0x20) - 50
    assert rec["sw_state"] == 2 and rec["sw_state_name"] == "run"
    # ID 3: throttle b3 %, pressure (b5 << 8 | b4) x 2 Pa
    rec = zk.decode_status(zk.status_frame(3, [0, 0, 42, 0x8C, 0xC5]))
    assert rec["throttle_pct"] == 42 and rec["pressure_pa"] == 0xC58C * 2
    # ID 4: current (b4[0] << 8 | b3) x 0.1 A; thrust (b4[7:1] << 8 | b5) x 0.1 kg
    rec = zk.decode_status(zk.status_frame(4, [0, 0, 0x2C, 0b0000011_1, 0x10]))
    assert rec["current_a"] == round(0x12C * 0.1, 1) and rec["thrust_kg"] == round(((3 << 8) | 0x10) * 0.1, 1)
    # ID 5
    rec = zk.decode_status(zk.status_frame(5, [0, 0, 160, 30, 40]))
    assert (rec["ignition_pump_voltage_v"], rec["curve_inc"], rec["curve_dec"]) == (3.2, 30, 40)
    # ID 7: flow (b4[1:0] << 8 | b3) x 0.01 L/min; used (b5 << 6 | b4[7:2]) x 0.1 L
    rec = zk.decode_status(zk.status_frame(7, [0, 0, 0x20, 0b000101_01, 0x02]))
    assert rec["fuel_flow_l_min"] == round(0x120 * 0.01, 2)
    assert rec["fuel_used_l"] == round(((2 << 6) | 5) * 0.1, 1)
    # ID 8: idle b3 x 1000; ESR b4[5]; SCL b4[4]; startup (b4[3:0] << 8 | b5) x 0.1 s
    rec = zk.decode_status(zk.status_frame(8, [0, 0, 35, 0b0011_0001, 0x2C]))
    assert (rec["idle_rpm"], rec["esr"], rec["scl"], rec["startup_time_s"]) == (35000, 1, 1, round(0x12C * 0.1, 1))
    # ID 9: ECU temperature b3 - 50 (v5), prop rpm b5 << 8 | b4 (v6)
    rec = zk.decode_status(zk.status_frame(9, [0, 0, 90, 0x34, 0x12]), 6, 6)
    assert rec["ecu_temp_c"] == 40 and rec["prop_rpm"] == 0x1234
    rec = zk.decode_status(zk.status_frame(9, [0, 0, 90, 0x34, 0x12]), 5, 5)
    assert rec["ecu_temp_c"] == 40 and rec["prop_rpm"] is None
    # ID 10 (V1.4): fuel pump rpm
    assert zk.decode_status(zk.status_frame(10, [0, 0, 0, 0x10, 0x27]))["fuel_pump_rpm"] == 10000


def test_voltage_unit_follows_protocol_version():
    frame = zk.status_frame(2, [0, 0, 50, 120, 30])
    old = zk.decode_status(frame, version=3, known=3)
    new = zk.decode_status(frame, version=4, known=4)
    assert (old["radio_voltage_v"], old["power_voltage_v"], old["pump_voltage_v"]) == (5.0, 12.0, 3.0)
    assert (new["radio_voltage_v"], new["power_voltage_v"], new["pump_voltage_v"]) == (10.0, 24.0, 6.0)
    # ID 6 carries its own version: max pump voltage uses it
    v3 = zk.status_frame(6, [0, 0, 160, 60, 3 << 2])
    v4 = zk.status_frame(6, [0, 0, 160, 60, 4 << 2])
    assert zk.decode_status(v3, version=6)["max_pump_voltage_v"] == 6.0
    assert zk.decode_status(v4, version=1)["max_pump_voltage_v"] == 12.0


def test_decoder_learns_version_from_status_6():
    d = zk.ZkDecoder()
    v2 = zk.status_frame(2, [0, 0, 50, 120, 30])
    assert d.decode(v2)["power_voltage_v"] == 24.0 and d.version_source == "default"
    d.decode(zk.status_frame(6, [0, 0, 160, 0, 3 << 2]))
    assert d.version == 3 and d.version_source == "frame"
    assert d.decode(v2)["power_voltage_v"] == 12.0
    assert zk.ZkDecoder(protocol_version=2).decode(v2)["power_voltage_v"] == 12.0


def test_decoder_tracks_rpm_factor_for_id7():
    d = zk.ZkDecoder()
    rpm7 = zk.encode_control("rpm", target_rpm=60000, rpm_factor=2)[0]
    assert d.decode(rpm7)["target_rpm"] is None and d.decode(rpm7)["rpm_value"] == 3000
    d.decode(zk.encode_control("mode", rpm_factor=2, sw="run")[0])
    assert d.decode(rpm7)["target_rpm"] == 60000


# --- ranges and messages --------------------------------------------------------------------------

@pytest.mark.parametrize("name,kw,needle", [
    ("control", {"sw": "run", "throttle_pct": 100.1}, "throttle: 100.1 is out of range; allowed 0..100 %"),
    ("control", {"sw": "run", "throttle_pct": -1}, "throttle"),
    ("control", {"sw": "fly"}, "state: unknown name 'fly'"),
    ("action", {"param": "launch"}, "action: unknown name 'launch'"),
    ("action", {"param": 14}, "action: 14 is out of range"),
    ("ignition-voltage", {"ignition_voltage_v": 5.2}, "ignition-voltage: 5.2 is out of range; allowed 0..5.1 V"),
    ("accel-curve", {"accel_curve": 9}, "accel-curve: 9 is out of range; allowed 10..70"),
    ("mode", {"rpm_factor": 7}, "rpm-factor: 7 is out of range; allowed 0..6"),
    ("rpm", {"target_rpm": 40960, "rpm_factor": 1}, "rpm: 40960 is out of range; allowed 0..40950 rpm"),
    ("rpm", {"target_rpm": 1000}, "rpm-factor: required"),
    ("pressure", {"pressure_hpa": 1024}, "pressure: 1024 is out of range; allowed 0..1023 hPa"),
])
def test_out_of_range_names_the_field(name, kw, needle):
    with pytest.raises(FieldValueError) as e:
        zk.encode_control(name, **kw)
    assert needle in str(e.value)


def test_off_grid_values_round_with_a_note():
    frame, notes = zk.encode_control("control", sw="run", throttle_pct=33.33)
    assert zk.decode_control(frame)["throttle_pct"] == 33.3
    assert notes and "rounded to 33.3" in notes[0]
    frame, notes = zk.encode_control("ignition-voltage", ignition_voltage_v=3.21)
    assert zk.decode_control(frame)["ignition_voltage_v"] == 3.2 and notes


def test_raw_encoding_checks_bits_and_fields():
    assert zk.encode_control_raw(1, sw=3, throttle_pct=500) == h("FF1DF470")
    with pytest.raises(FieldValueError, match="throttle_pct: raw value 1001 is out of range 0..1000"):
        zk.encode_control_raw(1, throttle_pct=1001)
    with pytest.raises(FieldValueError, match="not a field of command 1"):
        zk.encode_control_raw(1, param=3)
    frame = zk.encode_control_raw(0, reserved_b2=0x55)
    assert zk.decode_control(frame)["reserved"] == "b2=0x55"


def test_hazards():
    assert zk.control_hazard(h("FF1DF470"))            # run
    assert not zk.control_hazard(h("FF1464D3"))        # stop
    assert zk.control_hazard(zk.encode_control("action", param="test-starter")[0])
    assert not zk.control_hazard(zk.encode_control("action", param="rate-50hz")[0])
    assert zk.control_hazard(zk.encode_control("mode", sw="run", rpm_factor=1)[0])


# --- properties -----------------------------------------------------------------------------------

def _raw_values(layout_fields):
    return st.fixed_dictionaries({f.key: st.integers(f.lo, f.hi) for f in layout_fields})


@pytest.mark.parametrize("cmd", zk.CONTROL, ids=lambda c: c.name)
@given(data=st.data())
def test_control_raw_round_trip(cmd, data):
    raws = data.draw(_raw_values(cmd.fields))
    frame = zk.encode_control_raw(cmd.id, **{(f.raw_key or f.key): raws[f.key] for f in cmd.fields})
    zk.check_control(frame)
    rec = zk.decode_control(frame, {"rpm_factor": 1}, raw=True)
    for f in cmd.fields:
        assert rec[f.key + "_raw"] == raws[f.key]
    assert "reserved" not in rec


@pytest.mark.parametrize("cmd", [c for c in zk.CONTROL if c.fields], ids=lambda c: c.name)
@given(data=st.data())
def test_control_physical_round_trip(cmd, data):
    ctx = {p.key: data.draw(st.integers(p.lo, p.hi)) for p in cmd.params}
    values = {}
    for f in cmd.fields:
        raw = data.draw(st.integers(f.lo, f.hi))
        values[f.key] = f.names[raw] if f.names else f.to_physical(raw, ctx)
    frame, notes = zk.encode_control(cmd.name, **values, **ctx)
    assert notes == []
    rec = zk.decode_control(frame, ctx)
    for f in cmd.fields:
        got = rec[f.name_key] if f.names else rec[f.key]
        assert got == values[f.key]


@pytest.mark.parametrize("st_frame", zk.STATUS, ids=lambda s: s.name)
@given(data=st.data(), version=st.integers(1, 63))
def test_status_round_trip(st_frame, data, version):
    raws = data.draw(_raw_values(st_frame.fields))
    frame = bytearray(7)
    frame[0] = 0xF0 | st_frame.id
    for f in st_frame.fields:
        f.insert(frame, raws[f.key])
    frame[6] = crc8_maxim(frame[:6])
    zk.check_status(bytes(frame))
    rec = zk.decode_status(bytes(frame), version, None, raw=True)
    for f in st_frame.fields:
        assert rec[f.key + "_raw"] == raws[f.key]
    # and the physical values encode back to the same frame
    phys = {f.key: rec[f.key] for f in st_frame.fields if rec[f.key] is not None}
    if st_frame.id == 6:
        version = raws["protocol_version"]
    again = zk.encode_status(st_frame.id, version=version, **phys)
    assert again == bytes(frame) or any(rec[f.key] is None for f in st_frame.fields)


def _status(payload):
    from zkzap.codec.crc import crc8_maxim

    b = bytes(payload)
    return b + bytes((crc8_maxim(b),))


@pytest.mark.parametrize("payload,flagged", [
    ([0xF3, 0, 0, 102, 0, 0], ["throttle_pct"]),                 # throttle above 100 %
    ([0xF3, 0, 0, 100, 0, 0], []),
    ([0xF5, 0, 0, 0, 9, 71], ["curve_inc", "curve_dec"]),        # accel curve outside 10..70
    ([0xF5, 0, 0, 0, 10, 70], []),
    ([0xF1, 0, 0, 20, 0, 0], ["engine_state"]),                  # states beyond the appendix
    ([0xF1, 0, 0, 0x19, 0x03, 0], ["engine_state", "error_code"]),
    ([0xF1, 0, 0, 0, 0x60, 0], ["sw_state"]),
    ([0xF6, 0, 0, 160, 0, (4 << 2) | 3], ["status_rate_hz"]),
    ([0xF6, 0, 0, 160, 0, (4 << 2) | 2], []),
])
def test_out_of_range_values_are_listed_and_kept(payload, flagged):
    from zkzap.io.writers import csv_dialect, json_dialect
    from zkzap.io.zk_lines import ZkLines

    frame = _status(payload)
    rec = zk.decode_status(frame, known=6)
    assert rec.get("out_of_range", []) == flagged
    for key in flagged:
        assert rec[key] is not None or key == "status_rate_hz"      # the value itself is unchanged
    # the generated text encoders say the same, line for line, as the dict decoder
    for dialect in (json_dialect(), csv_dialect(["kind", "id"] + zk.STATUS_KEYS + ["frame"])):
        lines = ZkLines(zk.ZkDecoder(6), dialect)
        want = dialect.record(dict(zk.ZkDecoder(6).decode(frame), frame=frame.hex(" ").upper()))
        assert lines.encode(frame) == want
        assert lines.encode(frame) == want                          # from the memo, too
    assert zk.STATUS_KEYS[-1] == "out_of_range"
