"""mightyZAP packets: every worked example (as corrected in the README's decisions), the register map, round trips."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from zkzap.codec import zap
from zkzap.codec.fields import FieldValueError


def h(text):
    return bytes.fromhex(text.replace(" ", ""))


EXAMPLES = [
    # (what, built, expected hex) — the document's packets, corrected where the README's decisions say so
    ("echo", lambda: zap.echo(0), "FF FF FF 00 02 F1 0C"),
    ("factory reset ID", lambda: zap.factory_reset(1, reset_id=True), "FF FF FF 01 03 F6 01 04"),
    ("restart", lambda: zap.restart(0), "FF FF FF 00 02 F8 05"),
    ("store id", lambda: zap.store(0, "id", 1), "FF FF FF 00 04 F3 03 01 04"),
    ("goal position", lambda: zap.store(1, "goal-position", 2047), "FF FF FF 01 05 F3 86 FF 07 7A"),
    ("goal speed (checksum filled in)", lambda: zap.store(1, "goal-speed", 512), "FF FF FF 01 05 F3 88 00 02 7C"),
    ("stroke limit", lambda: zap.store(1, "short-stroke-limit", 100), "FF FF FF 01 05 F3 06 64 00 9C"),
    ("force off", lambda: zap.store(1, "force-on-off", 0), "FF FF FF 01 04 F3 80 00 87"),
    ("feedback return mode", lambda: zap.store(1, "feedback-return-mode", 2), "FF FF FF 01 04 F3 10 02 F5"),
    ("load present position", lambda: zap.load(0, "present-position"), "FF FF FF 00 04 F2 8C 02 7B"),
    ("load motor rate", lambda: zap.load(0, "present-motor-operating-rate"), "FF FF FF 00 04 F2 90 02 77"),
    ("load voltage", lambda: zap.load(0, "present-voltage"), "FF FF FF 00 04 F2 92 01 76"),
    ("send data", lambda: zap.send_data(1, "goal-position", 2047), "FF FF FF 01 05 F4 86 FF 07 79"),
    ("execution", lambda: zap.execute(1), "FF FF FF 01 02 F5 07"),
    ("symmetric store (broadcast ID)", lambda: zap.symmetric_store("goal-position", {1: 1023, 2: 2047})[0],
     "FF FF FF FE 0A 73 86 02 01 FF 03 02 FF 07 F1"),
]


@pytest.mark.parametrize("what,build,expected", EXAMPLES, ids=[e[0] for e in EXAMPLES])
def test_worked_examples(what, build, expected):
    pkt = build()
    assert pkt == h(expected)
    zap.check_packet(pkt)


FEEDBACK = [
    ("FF FF FF 00 02 00 FD", None, {"id": 0, "error": 0, "errors": []}),
    ("FF FF FF 01 02 00 FC", None, {"id": 1, "error": 0}),
    ("FF FF FF 00 04 00 FF 07 F5", "FF FF FF 00 04 F2 8C 02 7B", {"register": "present-position", "value": 2047}),
    ("FF FF FF 00 04 00 FF 03 F9", "FF FF FF 00 04 F2 90 02 77",
     {"register": "present-motor-operating-rate", "value": 1023}),
    ("FF FF FF 00 03 00 7B 81", "FF FF FF 00 04 F2 92 01 76",
     {"register": "present-voltage", "value": 123, "physical": 12.3, "unit": "V"}),
]


@pytest.mark.parametrize("pkt,request_,expected", FEEDBACK)
def test_feedback_examples(pkt, request_, expected):
    zap.check_packet(h(pkt))
    rec = zap.decode_packet(h(pkt), h(request_) if request_ else None)
    assert rec["kind"] == "feedback"
    for k, v in expected.items():
        assert rec[k] == v


def test_goal_current_is_at_0x8a_not_the_documents_repeat():
    pkt = zap.store(1, "goal-current", 800)
    assert pkt[6:9] == bytes([0x8A, 0x20, 0x03])
    assert pkt[-1] == 0xFF - (sum(pkt[3:-1]) & 0xFF)
    assert zap.register("current-limit").address == 0x34


def test_error_bits():
    pkt = zap.packet(3, 0x21)
    rec = zap.decode_packet(pkt)
    assert rec["kind"] == "feedback" and rec["errors"] == ["overload", "input-voltage"]
    assert zap.error_names(0x20) == ["overload"]
    assert zap.error_names(0x02) == ["undocumented-0x02"]


def test_register_map():
    names = [r.name for r in zap.REGISTERS]
    assert len(names) == len(set(names))
    assert zap.register("goal-position") is zap.register("0x86") is zap.register("134") is zap.register(0x86)
    assert zap.register("goal_position").address == 0x86
    r = zap.register("present-voltage")
    assert (r.size, r.access, r.memory, r.unit, r.scale) == (1, "R", "", "V", 0.1)
    r = zap.register("id")
    assert (r.writable, r.memory, r.lo, r.hi, r.default) == (True, "NV", 0, 253, 0)
    assert zap.register("goal-speed").memory == "V"
    # 2-byte registers do not overlap the next register
    ordered = sorted(zap.REGISTERS, key=lambda r: r.address)
    for a, b in zip(ordered, ordered[1:]):
        assert a.address + a.size <= b.address, (a.name, b.name)
    assert zap.register("0xF0").name == "0xf0"     # outside the map: raw one-byte access


@pytest.mark.parametrize("call,needle", [
    (lambda: zap.store(1, "present-position", 5), "present-position: read-only register"),
    (lambda: zap.store(1, "goal-position", 4096), "goal-position: 4096 is out of range; allowed 0..4095"),
    (lambda: zap.store(1, "baud-rate", 33), "baud-rate: 33 is not allowed; allowed 16 (115200 bps)"),
    (lambda: zap.store(1, "current-limit", 1601), "current-limit: 1601 is out of range; allowed 0..1600 mA"),
    (lambda: zap.store(254 + 1, "goal-position", 1), "id: 255 is out of range"),
    (lambda: zap.register("goal-positon"), "register: unknown name 'goal-positon'"),
    (lambda: zap.register("0x100"), "register: address 256 is out of range"),
    (lambda: zap.load(1, "goal-position", 0), "length: 0 is out of range"),
    (lambda: zap.symmetric_store("goal-position", {254: 1}), "id: 254 is out of range; allowed 0..253"),
    (lambda: zap.symmetric_store("goal-position", [(1, 1), (1, 2)]), "id: 1 is given twice"),
])
def test_refusals_name_the_field(call, needle):
    with pytest.raises(FieldValueError) as e:
        call()
    assert needle in str(e.value)


def test_check_id_accepts_broadcast_spellings():
    assert zap.check_id("broadcast") == zap.check_id("254") == zap.check_id(254) == 0xFE
    assert zap.check_id("0x10") == 16


def test_symmetric_store_splits_by_size():
    per = zap.max_per_packet(2)
    assert per == (255 - 4) // 3 == 83
    targets = {i: i * 10 for i in range(200)}
    pkts = zap.symmetric_store("goal-position", targets)
    assert len(pkts) == 3
    seen = {}
    for p in pkts:
        zap.check_packet(p)
        assert p[4] <= 255 and p[3] == 0xFE
        seen.update({int(k): v for k, v in zap.decode_packet(p)["targets"].items()})
    assert seen == targets
    assert len(zap.symmetric_store("led", {i: 1 for i in range(125)})) == 1   # 1-byte register: 125 per packet
    assert len(zap.symmetric_store("led", {i: 1 for i in range(126)})) == 2


def test_decode_instructions():
    rec = zap.decode_packet(zap.store(1, "goal-position", 2047))
    assert rec == {"kind": "command", "id": 1, "instruction": "store", "code": 0xF3, "params": "86 FF 07",
                   "address": 0x86, "register": "goal-position", "value": 2047}
    rec = zap.decode_packet(zap.factory_reset(2, reset_baud=True))
    assert rec["instruction"] == "factory-reset" and rec["reset_id"] is False and rec["reset_baud"] is True
    rec = zap.decode_packet(zap.load(5, "present-position", 4))
    assert rec["register"] == "present-position" and rec["length"] == 4


def test_decoder_pairs_multi_register_reads():
    d = zap.ZapDecoder()
    d.decode(zap.load(1, "present-position", 4))
    rec = d.decode(zap.packet(1, 0, bytes([0xFF, 0x07, 0x20, 0x03])))
    assert rec["values"] == {"present-position": 2047, "present-current": 800}


@given(ident=st.integers(0, 253), data=st.data())
def test_store_round_trip(ident, data):
    reg = data.draw(st.sampled_from([r for r in zap.REGISTERS if r.writable]))
    value = data.draw(st.sampled_from(reg.values()))
    pkt = zap.store(ident, reg.name, value)
    zap.check_packet(pkt)
    rec = zap.decode_packet(pkt)
    assert (rec["id"], rec["register"], rec["value"]) == (ident, reg.name, value)


@given(ident=st.integers(0, 254), code=st.integers(0, 255), params=st.binary(max_size=253))
def test_any_packet_round_trips(ident, code, params):
    pkt = zap.packet(ident, code, params)
    zap.check_packet(pkt)
    rec = zap.decode_packet(pkt)
    assert rec["id"] == ident and rec["kind"] == zap.packet_kind(code)
    assert rec["params"] == params.hex(" ").upper()


@given(targets=st.dictionaries(st.integers(0, 253), st.integers(0, 4095), min_size=1, max_size=254))
def test_symmetric_store_round_trip(targets):
    got = {}
    for p in zap.symmetric_store("goal-position", targets):
        zap.check_packet(p)
        got.update({int(k): v for k, v in zap.decode_packet(p)["targets"].items()})
    assert got == targets


@pytest.mark.parametrize("code,name", [(0xF9, "system-write"), (0x55, "status"), (0x82, "sync-read"),
                                       (0x92, "bulk-read"), (0x93, "bulk-write")])
def test_vendor_instructions_decode_by_name_never_as_errors(code, name):
    rec = zap.decode_packet(zap.packet(1, code, b"\x01"))
    assert (rec["kind"], rec["instruction"], rec["code"], rec["documented"]) == ("command", name, code, False)
    assert "errors" not in rec


def test_ir_robots_factory_reset_is_system_write():
    pkt = bytes.fromhex("FFFFFF0103F901") + bytes((zap.zap_checksum(bytes.fromhex("0103F901")),))
    zap.check_packet(pkt)
    assert zap.decode_packet(pkt)["instruction"] == "system-write"
    assert zap.INSTRUCTION_BY_NAME["factory-mode"].code == 0xF9


@pytest.mark.parametrize("code,kind", [(0x00, "feedback"), (0x01, "feedback"), (0x20, "feedback"),
                                       (0x21, "feedback"), (0x02, "unknown"), (0x40, "unknown"),
                                       (0x99, "unknown"), (0xF2, "command")])
def test_byte_after_size_kinds(code, kind):
    rec = zap.decode_packet(zap.packet(3, code, b""))
    assert rec["kind"] == kind
    if kind == "unknown":
        assert rec["code"] == code and "errors" not in rec


def test_undocumented_addresses_read_raw():
    for name, addr in (("present-temperature", 0x93), ("registered-instruction", 0x94), ("lock", 0x97)):
        reg = zap.register(name)
        assert reg.address == addr and zap.register(addr) is reg and reg.scale == 1
        assert reg not in zap.REGISTERS
    assert [(r.name, v) for r, v in zap._register_values(0x92, bytes((120, 245)))] == [
        ("present-voltage", 120), ("present-temperature", 245)]
