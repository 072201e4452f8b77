"""Modbus RTU frames of the mightyZAP 17Lf: the worked examples of IR Robot's protocol manual,
byte for byte, and every frame kind checked against pymodbus, an independent Modbus stack."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymodbus.framer import FramerRTU
from pymodbus.pdu import DecodePDU
from pymodbus.pdu.register_message import (ReadHoldingRegistersRequest, ReadHoldingRegistersResponse,
                                           WriteMultipleRegistersRequest, WriteMultipleRegistersResponse,
                                           WriteSingleRegisterRequest, WriteSingleRegisterResponse)

from zkzap.codec import modbus
from zkzap.codec.crc import crc16_modbus
from zkzap.codec.framing import RtuFramer
from zkzap.codec.permissions import Permission
from zkzap.errors import exit_code

H = bytes.fromhex

# The protocol manual's examples (every CRC checked with CRC-16/MODBUS).
WORKED = [
    (modbus.read(1, "present-position"), "01 03 00 D2 00 01 24 33"),
    (modbus.read_reply(1, [1000]), "01 03 02 03 E8 B8 FA"),
    (modbus.read(1, "present-current"), "01 03 00 D3 00 01 75 F3"),
    (modbus.read_reply(1, [426]), "01 03 02 01 AA 39 AB"),
    (modbus.exception_reply(1, modbus.READ_HOLDING, 4), "01 83 04 40 F3"),
    (modbus.write(1, "goal-position", 1000), "01 06 00 CD 03 E8 18 8B"),
    (modbus.write(1, "goal-current", 800), "01 06 00 D1 03 20 D8 DB"),
    (modbus.write_block(1, {"goal-speed": 1000, "goal-current": 800})[0], "01 10 00 D0 00 02 04 03 E8 03 20 7F AB"),
    (modbus.write_multiple_reply(1, 0xD0, 2), "01 10 00 D0 00 02 40 31"),
]


def _pymodbus_frame(pdu, ident):
    pdu.dev_id = ident
    return FramerRTU(DecodePDU(False)).buildFrame(pdu)


@pytest.mark.parametrize("ours,text", WORKED)
def test_worked_examples_byte_identical(ours, text):
    assert ours == H(text)
    assert modbus.crc_ok(ours)


def test_worked_examples_are_what_pymodbus_builds():
    assert _pymodbus_frame(ReadHoldingRegistersRequest(address=0xD2, count=1), 1) == WORKED[0][0]
    assert _pymodbus_frame(ReadHoldingRegistersResponse(registers=[1000]), 1) == WORKED[1][0]
    assert _pymodbus_frame(WriteSingleRegisterRequest(address=0xCD, registers=[1000]), 1) == WORKED[5][0]
    assert _pymodbus_frame(WriteMultipleRegistersRequest(address=0xD0, registers=[1000, 800]), 1) == WORKED[7][0]
    assert _pymodbus_frame(WriteMultipleRegistersResponse(address=0xD0, count=2), 1) == WORKED[8][0]


def test_crc_catalogue_value_and_pymodbus():
    assert crc16_modbus(b"123456789") == 0x4B37
    assert FramerRTU.compute_CRC(b"123456789") == 0x374B   # pymodbus gives it byte-swapped (wire order)


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=80))
def test_crc_matches_pymodbus(data):
    ours = crc16_modbus(data).to_bytes(2, "little")
    assert ours == FramerRTU.compute_CRC(data).to_bytes(2, "big")


IDS = st.integers(1, modbus.MAX_ID)
WORD = st.integers(0, 0xFFFF)


@settings(max_examples=40, deadline=None)
@given(IDS, st.integers(0, 0xFFFF - 125), st.integers(1, 125))
def test_read_request_matches_pymodbus(ident, address, count):
    assert modbus.read_registers(ident, address, count) == \
        _pymodbus_frame(ReadHoldingRegistersRequest(address=address, count=count), ident)


@settings(max_examples=40, deadline=None)
@given(IDS, st.lists(WORD, min_size=1, max_size=125))
def test_read_reply_matches_pymodbus_and_parses(ident, values):
    reply = modbus.read_reply(ident, values)
    assert reply == _pymodbus_frame(ReadHoldingRegistersResponse(registers=values), ident)
    assert modbus.parse_reply(modbus.read_registers(ident, 0, len(values)), reply) == values


@settings(max_examples=40, deadline=None)
@given(st.integers(0, modbus.MAX_ID), st.integers(0, 0xFFFF), WORD)
def test_write_single_matches_pymodbus(ident, address, value):
    ours = modbus.write_register(ident, address, value)
    assert ours == _pymodbus_frame(WriteSingleRegisterRequest(address=address, registers=[value]), ident)
    assert ours == _pymodbus_frame(WriteSingleRegisterResponse(address=address, registers=[value]), ident)
    if ident:
        assert modbus.parse_reply(ours, ours) == [value]


@settings(max_examples=40, deadline=None)
@given(st.integers(0, modbus.MAX_ID), st.integers(0, 0xFFFF - 123), st.lists(WORD, min_size=1, max_size=123))
def test_write_multiple_matches_pymodbus(ident, address, values):
    ours = modbus.write_registers(ident, address, values)
    assert ours == _pymodbus_frame(WriteMultipleRegistersRequest(address=address, registers=values), ident)
    reply = modbus.write_multiple_reply(ident, address, len(values))
    assert reply == _pymodbus_frame(WriteMultipleRegistersResponse(address=address, count=len(values)), ident)
    if ident:
        assert modbus.parse_reply(ours, reply) == values


@pytest.mark.parametrize("code,name", [(1, "illegal-function"), (2, "illegal-data-address"),
                                       (3, "illegal-data-value"), (4, "slave-device-failure"),
                                       (5, "acknowledge"), (6, "slave-device-busy")])
@pytest.mark.parametrize("fn", [modbus.READ_HOLDING, modbus.WRITE_SINGLE, modbus.WRITE_MULTIPLE])
def test_exception_replies_are_named_errors(code, name, fn):
    req = {modbus.READ_HOLDING: modbus.read_registers(3, 205, 1), modbus.WRITE_SINGLE: modbus.write_register(3, 205, 1),
           modbus.WRITE_MULTIPLE: modbus.write_registers(3, 205, [1, 2])}[fn]
    reply = modbus.exception_reply(3, fn, code)
    assert reply[1] == fn | 0x80          # 0x90 for a write multiple, not the manual's 0x83
    with pytest.raises(modbus.ExceptionReply) as e:
        modbus.parse_reply(req, reply)
    assert e.value.exception == code and e.value.name == name and name in str(e.value)
    assert exit_code(e.value) == 5


@pytest.mark.parametrize("reply,kind", [
    ("02 03 02 03 E8", "other-id"),                  # another actuator's (CRC irrelevant)
    ("01 06 00 D2 00 01", "wrong-function"),
    ("01 03 02 03", "short"),
    ("01 03 02 03 E8 B8 FB", "crc"),
    ("01 03 04 03 E8 00 00", "length"),
])
def test_not_the_reply_is_never_a_value(reply, kind):
    data = H(reply)
    if kind == "other-id":
        data = modbus.frame(2, H("03 02 03 E8"))
    elif kind == "wrong-function":
        data = modbus.frame(1, H("06 00 D2 00 01"))
    elif kind == "length":
        data = modbus.read_reply(1, [1000, 0])
    with pytest.raises(modbus.ReplyMismatch) as e:
        modbus.parse_reply(modbus.read(1, "present-position"), data)
    assert e.value.kind == kind
    assert exit_code(e.value) == 6


def test_reply_reader_skips_the_adapters_echo_and_counts():
    req = modbus.read(1, "present-position")
    r = modbus.ReplyReader(req)
    for b in req + H("01 03 02 03 E8 B8 FA"):
        r.feed(bytes((b,)))
    assert r.done and r.echoes == 1 and r.result() == [1000]
    r = modbus.ReplyReader(req)
    r.feed(modbus.read_reply(2, [5]))
    assert r.other_id == 1
    with pytest.raises(modbus.ReplyMismatch):
        r.result()
    r = modbus.ReplyReader(req)
    r.feed(H("01 03 02"))
    r.finish()
    assert r.short == 1
    w = modbus.write(1, "goal-position", 1000)
    r = modbus.ReplyReader(w, echo=True)
    r.feed(w + w)                       # echo, then the identical reply
    assert r.echoes == 1 and r.result() == [1000]


def test_typed_request_answers_reply_and_hazard():
    read = modbus.Request(modbus.read(1, "present-position"))
    assert read.reply_length() == 7 and read.expects_reply() and not read.hazardous
    goal = modbus.Request(modbus.write(1, "goal-position", 500))
    assert goal.reply_length() == 8 and goal.needs() == {}
    bc = modbus.Request(modbus.write(0, "goal-position", 500))
    assert bc.broadcast and bc.reply_length() is None and not bc.expects_reply()
    ident = modbus.Request(modbus.write(1, "id", 9))
    assert ident.permissions() == Permission.STORED | Permission.IDENTITY
    bcid = modbus.Request(modbus.write_register(0, 4, 9))
    assert Permission.BROADCAST in bcid.needs()
    unknown = modbus.Request(modbus.write_register(1, 300, 9))
    assert Permission.UNDOCUMENTED in unknown.needs()
    limit = modbus.Request(modbus.write(1, "speed-limit", 500))
    assert set(limit.needs()) == {Permission.STORED}


def test_read_only_refused_before_sending():
    with pytest.raises(modbus.FieldValueError, match="read-only"):
        modbus.write(1, "present-position", 5)
    with pytest.raises(modbus.FieldValueError, match="out of range"):
        modbus.write(1, "goal-position", 10001)
    with pytest.raises(modbus.FieldValueError, match="broadcast"):
        modbus.read_registers(0, 210, 1)


def test_write_block_one_frame_per_run():
    frames = modbus.write_block(1, {"goal-position": 5, "goal-speed": 100, "goal-current": 200})
    assert [modbus.Request(f).function for f in frames] == [modbus.WRITE_SINGLE, modbus.WRITE_MULTIPLE]


def _stream_frames():
    frames = [w for w, _ in WORKED]
    frames += [modbus.exception_reply(5, modbus.WRITE_MULTIPLE, 2), modbus.read_registers(200, 60, 50),
               modbus.read_reply(200, list(range(50)))]
    return frames


@settings(max_examples=40, deadline=None)
@given(st.lists(st.sampled_from(_stream_frames()), min_size=1, max_size=12), st.integers(1, 9), st.data())
def test_framer_cuts_any_chunking(frames, step, data):
    stream = b"".join(frames)
    f = RtuFramer()
    out = []
    for i in range(0, len(stream), step):
        out += f.feed(stream[i:i + step])
    out += f.flush()
    assert out == frames and f.bad == f.skipped == f.truncated == 0


def test_framer_counts_bad_and_truncated_and_keeps_the_next_frame():
    good = WORKED[0][0]
    bad = good[:-1] + bytes((good[-1] ^ 1,))
    f = RtuFramer()
    out = f.feed(bad + good + good[:5]) + f.flush()
    assert out == [good]
    assert f.bad == 1 and f.truncated == 1 and f.skipped == len(bad) + 5


@pytest.mark.parametrize("baud,seconds", [(9600, 3.5 * 11 / 9600), (19200, 3.5 * 11 / 19200), (38400, 0.00175),
                                          (57600, 0.00175), (115200, 0.00175)])
def test_inter_frame_silence(baud, seconds):
    assert modbus.silence(baud) == pytest.approx(seconds)


def test_the_bus_keeps_the_silence_between_frames():
    """Every request starts at least 3.5 characters (1.75 ms at 57600) after the last byte on
    the line, sent or received."""
    import time

    from zkzap.link.modbus_bus import ModbusBus
    from zkzap.link.port import open_port
    from zkzap.sim import start_zap

    with start_zap(ids=[1], protocol="modbus") as sim:
        bus = ModbusBus(open_port(sim.url, 57600, timeout=0.1), url=sim.url)
        writes = []
        real = bus.port.write

        def write(data):
            writes.append((time.monotonic(), bus._line_free))
            return real(data)

        bus.port.write = write
        for _ in range(5):
            bus.read(1, "present-position")
        assert all(t - free >= modbus.silence(57600) * 0.999 for t, free in writes[1:])
