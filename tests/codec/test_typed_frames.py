"""Typed frames: zk.ControlFrame and zap.Command answer what a frame means, each in one place."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from zkzap.codec import zap, zk
from zkzap.codec.crc import crc8_maxim


def control(b1, b2):
    return bytes((0xFF, b1, b2, crc8_maxim(bytes((b1, b2)))))


@pytest.mark.parametrize("kind, fields, hazardous, controls", [
    ("keepalive", {}, False, False),
    ("control", {"sw": "run", "throttle_pct": 40}, True, True),
    ("control", {"sw": "standby", "throttle_pct": 0}, False, True),
    ("control", {"sw": "pwm", "throttle_pct": 0}, False, False),
    ("action", {"param": "test-starter"}, True, True),
    ("action", {"param": "rate-50hz"}, False, False),
    ("action", {"param": "pump-off"}, False, False),
    ("mode", {"sw": "none", "rpm_factor": 0}, False, False),
    ("mode", {"sw": "none", "rpm_factor": 2}, False, True),
    ("mode", {"sw": "run", "rpm_factor": 0}, True, True),
    ("rpm", {"target_rpm": 0, "rpm_factor": 1}, False, True),
    ("pressure", {"pressure_hpa": 1013}, False, False),
])
def test_control_frame_worked_examples(kind, fields, hazardous, controls):
    cf = zk.ControlFrame.build(kind, **fields)
    assert cf.hazardous is hazardous and (cf.hazard is not None) is hazardous
    assert cf.controls_engine is controls
    assert zk.control_hazard(cf.frame) == cf.hazard


@given(st.integers(0, 0x8F), st.integers(0, 255))
def test_control_frame_agrees_with_its_record(b1, b2):
    frame = control(b1, b2)
    cf = zk.ControlFrame(frame)
    if cf.command is None:
        assert not cf.controls_engine and not cf.hazardous
        return
    rec = cf.decode()
    if cf.id == 1:
        assert cf.controls_engine == (rec["sw"] != 0)
        assert cf.hazardous == (rec["state"] == "run")
    elif cf.id == 6:
        assert cf.controls_engine == (rec["sw"] != 0 or rec["rpm_factor"] != 0)
    elif cf.id == 7:
        assert cf.controls_engine
    elif cf.id == 2:
        assert cf.hazardous == (b2 in zk.HAZARDOUS_ACTIONS) == cf.controls_engine


def test_protocol_version_read_once():
    six = zk.encode_status(6, max_rpm=160000, max_pump_voltage_v=10.0, protocol_version=5, status_rate_hz=20)
    assert zk.protocol_version_of(six) == 5
    assert zk.protocol_version_of(zk.encode_status(1)) is None


def test_command_symmetric_store_parsed_once():
    pkt = zap.symmetric_store("protocol-type", {1: 1, 2: 0})[0]
    cmd = zap.Command(pkt)
    assert cmd.code == zap.SYMMETRIC_STORE and cmd.broadcast
    assert cmd.targets == [(1, b"\x01"), (2, b"\x00")]
    assert cmd.target_ids() == [1, 2]
    assert cmd.stored_writes == ["protocol-type"]
    assert cmd.leaves_protocol
    assert not cmd.expects_reply(2)


def test_command_writes_and_replies():
    cmd = zap.Command(zap.store(1, "goal-position", 2047))
    assert cmd.address == 0x86 and cmd.data == b"\xff\x07" and cmd.stored_writes == []
    assert [cmd.expects_reply(m) for m in (0, 1, 2)] == [False, False, True]
    assert cmd.written_value("goal-position") == [2047]
    load = zap.Command(zap.load(3, "present-position"))
    assert (load.address, load.length, load.reply_data_length) == (0x8C, 2, 2)
    assert [load.expects_reply(m) for m in (0, 1, 2)] == [False, True, True]
    assert zap.Command(zap.echo(3)).expects_reply(0)
    assert zap.Command(zap.factory_reset(1)).stored_writes == ["every stored setting (factory reset)"]
    assert zap.Command(zap.restart(1)).restarts
    odd = zap.Command(zap.packet(1, 0xE0, b"\x01"))
    assert odd.instruction is None and odd.reply_data_length is None and not odd.expects_reply(2)
    vendor = zap.Command(zap.packet(1, 0xF9, b"\x01"))          # IR Robot's system write: named, undocumented
    assert vendor.instruction.cli == "system-write" and not vendor.instruction.documented


@given(st.integers(0, 253), st.sampled_from([r for r in zap.REGISTERS if r.writable]), st.data())
def test_command_stored_writes_follow_the_map(ident, reg, data):
    value = data.draw(st.sampled_from(reg.values()))
    cmd = zap.Command(zap.store(ident, reg, value))
    assert cmd.stored_writes == ([reg.name] if reg.stored else [])
    assert cmd.leaves_protocol == (reg.name == "protocol-type" and value == 0)
