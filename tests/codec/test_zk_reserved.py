"""Reserved bits in crafted ZK control frames never reach a real field: over every command and
every bit of bytes 1 and 2, a reserved bit is set and shows up as ``reserved`` (with every
field still 0), and any other bit is refused naming the key."""

from __future__ import annotations

import pytest

from zkzap.codec import zk
from zkzap.codec.fields import FieldValueError

CASES = [(cmd.id, key, byte, bit)
         for cmd in zk.CONTROL
         for key, byte, bits in (("reserved_b1", 1, range(4)), ("reserved_b2", 2, range(8)))
         for bit in bits]


@pytest.mark.parametrize("cmd_id,key,byte,bit", CASES)
def test_reserved_bit_is_set_only_where_no_field_lives(cmd_id, key, byte, bit):
    cmd = zk.control_command(cmd_id)
    value = 1 << bit
    if cmd.layout.reserved[byte] & value:
        frame = zk.encode_control_raw(cmd_id, **{key: value})
        rec = zk.decode_control(frame)
        assert rec["reserved"] == f"b{byte}={value:#04x}"
        assert frame[1] >> 4 == cmd_id
        for f in cmd.fields:                      # no field's bit is set
            assert all(frame[i] & f.mask_of(i) == 0 for i in (1, 2)), f.key
        assert frame[byte] & ~value & 0xFF == zk.encode_control_raw(cmd_id)[byte]
    else:
        with pytest.raises(FieldValueError, match=f"^{key}: {value:#04x} sets bits {value:#04x} that are not reserved"):
            zk.encode_control_raw(cmd_id, **{key: value})


def test_control_run_cannot_be_reached_through_reserved_bits():
    # FF 1C 00 A1 (state run) must not be reachable from sw=1 plus a 'reserved' 8
    with pytest.raises(FieldValueError, match="command 1 \\(control\\) has no reserved bits"):
        zk.encode_control_raw(1, sw=1, reserved_b1=8)


@pytest.mark.parametrize("value", [-1, 0x100, "x"])
def test_reserved_value_out_of_byte_range(value):
    with pytest.raises(FieldValueError, match="reserved_b2: .* is out of range"):
        zk.encode_control_raw(0, reserved_b2=value)
