"""The zap console's plot, packet panel and byte log on a Modbus RTU bus (the 17Lf): a plotted
register is the map's (never the 12Lf IR register of that name, at another address), the packet
panel composes any request (the spec's worked examples byte for byte) and asks what the library's
permission table asks for it, and the bytes on the bus are framed by the bus's framer and decoded
as Modbus RTU both ways (exception replies named, a bad CRC never a value)."""

from __future__ import annotations

import time

import pytest

from zkzap import Bus
from zkzap.codec import modbus
from zkzap.sim import start_zap
from zkzap.web.console import Request
from zkzap.web.zap_console import ZapConsole


class Hub:
    def __init__(self):
        self.sent, self.items, self.bytes = [], [], []

    def send(self, cid, msg):
        self.sent.append(msg)

    def broadcast(self, msg):
        self.sent.append(msg)

    def sample(self, item):
        self.items.append(item)

    def traffic(self, item):
        self.bytes.append(item)


@pytest.fixture
def rig():
    with start_zap(ids=[1], virtual=True, protocol="modbus") as sim, \
            Bus(sim, protocol="modbus", timeout=0.05) as bus:
        console = ZapConsole(bus, scan_ids=None)
        console.hub = Hub()
        for rec in bus.scan([1]):
            console.actuators[rec["id"]] = dict(rec, polled=True, link=None)
        yield sim, bus, console


def _ask(console, op, **fields):
    console.hub.sent.clear()
    console.handle(Request(1, "page 1", {"op": op, "req": 3, **fields}))
    return console.hub.sent


def test_a_plotted_register_is_the_maps(rig):
    sim, bus, console = rig
    _ask(console, "plot", register="goal-speed")
    assert console.plotted is bus.map.by_name["goal-speed"]
    with sim.lock:
        sim.device.actuator(1).set("goal-speed", 321)
    assert bus.read(1, console.plotted) == 321      # what the live view polls for the plot


def _done(sent):
    errors = [m for m in sent if m["type"] in ("error", "consent")]
    assert not errors, errors
    return next(m for m in sent if m["type"] == "done")


@pytest.mark.parametrize(("fields", "frame", "words"), [
    ({"instruction": "read", "register": "present-position"}, "01 03 00 D2 00 01 24 33",
     "read present-position (1 register) from actuator 1"),
    ({"instruction": "read", "register": "present-current"}, "01 03 00 D3 00 01 75 F3",
     "read present-current (1 register) from actuator 1"),
    ({"instruction": "write", "register": "goal-position", "value": 1000}, "01 06 00 CD 03 E8 18 8B",
     "write goal-position=1000 to actuator 1"),
    ({"instruction": "write", "register": "goal-current", "value": "800"}, "01 06 00 D1 03 20 D8 DB",
     "write goal-current=800 to actuator 1"),
    ({"instruction": "write-multiple", "register": "goal-speed", "values": "1000 800"},
     "01 10 00 D0 00 02 04 03 E8 03 20 7F AB", "write goal-speed=1000 goal-current=800 to actuator 1"),
    ({"instruction": "0x10", "register": "208", "values": [1000, 800]},
     "01 10 00 D0 00 02 04 03 E8 03 20 7F AB", "write goal-speed=1000 goal-current=800 to actuator 1"),
    ({"instruction": 3, "params": "00 D2 00 01"}, "01 03 00 D2 00 01 24 33",
     "read present-position (1 register) from actuator 1"),
    ({"instruction": "read", "register": "present-position", "count": 2}, "01 03 00 D2 00 02 64 32",
     "read present-position..present-current (2 registers) from actuator 1"),
])
def test_a_composed_request_is_the_spec_s_frame(rig, fields, frame, words):
    """The worked examples of the 17Lf's protocol manual, byte for byte (the CRC appended)."""
    sim, _, console = rig
    before = len(sim.device.received)
    got = _done(_ask(console, "compose", id=1, **fields))
    assert got["frame"] == frame and got["describe"] == words and got["reply"] is True
    assert got["needs"] == [] and got["asks"] is None
    assert len(sim.device.received) == before                  # composing sends nothing


def test_what_the_table_asks_is_the_command_line_s(rig):
    """The permissions shown are the library's table (modbus.Request.needs against the map),
    the rule `zap raw/store --protocol modbus` follow."""
    from zkzap.codec import modbus

    _, bus, console = rig
    for fields in ({"instruction": "write-multiple", "register": "speed-limit", "values": "700"},
                   {"instruction": "write", "register": "id", "value": 9},
                   {"instruction": "write", "register": "present-position", "value": 5},
                   {"instruction": "write", "register": "3", "value": 5},
                   {"instruction": "1", "params": "00 00 00 01"},
                   {"instruction": "write", "register": "goal-position", "value": 1000, "id": 0},
                   {"instruction": "write", "register": "speed-limit", "value": 1000, "id": 0}):
        got = _done(_ask(console, "compose", **{"id": 1, **fields}))
        req = modbus.Request(bytes.fromhex(got["frame"]))
        assert [n["permission"] for n in got["needs"]] == [p.name.lower() for p in req.needs(bus.map)], fields
        assert [n["reason"] for n in got["needs"]] == list(req.needs(bus.map).values())
        forced = any(p & modbus_force() for p in req.needs(bus.map))
        assert got["asks"] == ("force" if forced else None), (fields, got)       # a simulator waives consent
    got = _done(_ask(console, "compose", instruction="write", id=0, register="goal-position", value=1000))
    assert got["reply"] is False                                  # a broadcast is never answered


def modbus_force():
    from zkzap.codec.permissions import FORCE

    return FORCE


@pytest.mark.parametrize(("fields", "says"), [
    ({"instruction": "load", "register": "goal-position"}, "function"),
    ({"instruction": "0x83", "params": "02"}, "0x80 and up mark exception replies"),
    ({"instruction": "read", "register": "goal-position", "id": 248}, "id"),
    ({"instruction": "read", "register": "goal-position", "id": 0}, "broadcast"),
    ({"instruction": "read", "register": "goal-position", "count": 126}, "count"),
    ({"instruction": "write", "register": "goal-position", "value": 65536}, "goal-position"),
    ({"instruction": "write", "register": "no-such-register", "value": 1}, "register"),
    ({"instruction": "write-multiple", "register": "goal-speed", "values": "1 x"}, "not a number"),
    ({"instruction": "write-multiple", "register": "goal-speed", "values": " ".join(["1"] * 124)}, "1..123"),
    ({"instruction": "write-multiple", "register": "goal-speed", "values": ""}, "values"),
    ({"instruction": "read", "params": "GG"}, "params"),
    ({"instruction": "read", "params": "00 " * 253}, "at most 252"),
])
def test_bad_input_is_refused_and_nothing_goes_out(rig, fields, says):
    sim, _, console = rig
    before = len(sim.device.received)
    for op in ("compose", "packet"):
        sent = _ask(console, op, **{"id": 1, **fields})
        error = next(m for m in sent if m["type"] == "error")
        assert says in error["text"], (fields, error)
    assert len(sim.device.received) == before


def test_a_packet_goes_out_and_its_reply_or_exception_comes_back_decoded(rig):
    sim, _, console = rig
    with sim.lock:
        sim.device.actuator(1).set("goal-speed", 321)
    got = _done(_ask(console, "packet", instruction="read", id=1, register="goal-speed", count=2))
    assert got["reply"].startswith("01 03 04 01 41") and got["errors"] == []
    assert got["decoded"]["values"]["goal-speed"] == 321
    got = _done(_ask(console, "packet", instruction="write", id=1, register="goal-position", value=1234))
    assert got["reply"] == got["frame"] == "01 06 00 CD 04 D2 9A A8"        # a write single is answered by its echo
    with sim.lock:
        assert sim.device.actuator(1).get("goal-position") == 1234
    got = _done(_ask(console, "packet", instruction="read", id=1, register="300"))
    assert got["reply"][:5] == "01 83" and got["errors"] == ["illegal-data-address"]
    assert got["exception"].startswith("exception 2 (illegal-data-address): illegal data address")
    assert got["decoded"]["kind"] == "exception" and "value" not in got["decoded"]


def test_a_packet_needing_force_is_asked_for_and_not_sent(rig):
    sim, _, console = rig
    before = len(sim.device.received)
    sent = _ask(console, "packet", instruction="write", id=1, register="id", value=9)
    consent = next(m for m in sent if m["type"] == "consent")
    assert consent["permission"] == "force" and "answers to ID 9" in consent["text"]
    assert len(sim.device.received) == before
    console.handle(Request(1, "page 1", {"op": "packet", "req": 4, "instruction": "write", "id": 1,
                                         "register": "id", "value": 9, "grant": ["force"]}))
    with sim.lock:
        assert [a.ident for a in sim.device.actuators] == [9]
    assert any("scan again" in m.get("text", "") for m in console.hub.sent if m["type"] == "log")


def test_the_bytes_on_the_bus_are_modbus_frames_decoded(rig):
    _, bus, console = rig
    console.hub.bytes.clear()
    assert bus.read(1, "goal-speed") is not None
    items = console.hub.bytes
    assert [i["dir"] for i in items] == ["tx", "rx"], items
    assert all(not i.get("bad") for i in items), items
    assert items[0]["text"] == "read goal-speed (1 register) from actuator 1", items
    assert items[1]["text"].startswith("reply of ID 1: goal-speed="), items


def test_an_exception_reply_is_named_and_a_bad_crc_is_never_a_value(rig):
    sim, bus, console = rig
    console.hub.bytes.clear()
    _done(_ask(console, "packet", instruction="read", id=1, register="300"))
    rx = [i for i in console.hub.bytes if i["dir"] == "rx"]
    assert rx[-1]["text"] == ("exception reply of ID 1 to read: 2 illegal-data-address (illegal data address: no "
                              "such register, or a block past the table)"), rx
    console.hub.bytes.clear()
    with sim.lock:
        sim.device.inject(1, "corrupt", count=1)
    got = _done(_ask(console, "packet", instruction="read", id=1, register="goal-speed"))
    assert got["reply"].startswith("01 03 02")                 # the retry's good reply
    items = console.hub.bytes
    bad = [i for i in items if i.get("bad")]
    assert len(bad) == 1 and bad[0]["dir"] == "rx" and "CRC mismatch" in bad[0]["text"], items
    assert bad[0]["text"].startswith("not a frame: ") and "goal-speed" not in bad[0]["text"]
    assert [i["dir"] for i in items] == ["tx", "rx", "tx", "rx"], items        # the bad reply, then the retry
    assert items[-1]["text"].startswith("reply of ID 1: goal-speed=")


def test_bytes_that_make_no_frame_are_said_as_such_when_the_next_request_goes(rig):
    """A reply cut short (the line dropped its end) is shown when the next request goes out,
    as bytes that made no frame, never as a value."""
    _, bus, console = rig
    console._monitor("tx", bytes.fromhex("01 03 00 D2 00 01 24 33"))
    console.hub.bytes.clear()
    console._monitor("rx", bytes.fromhex("01 03 02 03"))          # 4 of a 7-byte reply
    assert console.hub.bytes == []                                 # perhaps more to come
    console._monitor("tx", bytes.fromhex("01 03 00 D3 00 01 75 F3"))
    first, second = console.hub.bytes
    assert first["dir"] == "rx" and first["bad"] and first["text"].startswith("not a frame: 4 bytes"), first
    assert second["dir"] == "tx" and second["text"] == "read present-current (1 register) from actuator 1"
    console.hub.bytes.clear()
    console._monitor("rx", bytes.fromhex("01 03 02 01 AA 39 AB"))   # the manual's reply: 426
    assert [i["text"] for i in console.hub.bytes] == ["reply of ID 1: present-current=426"]


@pytest.mark.parametrize("count", [1, 4, 11])
@pytest.mark.parametrize("crc", ["good", "bad"])
def test_a_reply_split_across_reads_is_judged_as_one_frame(rig, count, crc):
    """A reply that comes in two reads (a USB adapter's or a socket's chunks, a moment apart, less
    than the 3.5-character silence) is one frame: a value when its CRC holds, else one line of
    bytes in no frame saying the CRC failed, said as soon as the reply's length is in; never two
    pieces, never a value. Every cut, for the live view's reads (1, 4 and 11 registers)."""
    _, bus, console = rig
    req = modbus.read_registers(1, 208, count)
    values = [1000 + 37 * k for k in range(count)]
    reply = modbus.frame(1, bytes((modbus.READ_HOLDING, 2 * count)) + b"".join(v.to_bytes(2, "big") for v in values))
    if crc == "bad":
        reply = reply[:-1] + bytes((reply[-1] ^ 0x5A,))         # the simulator's corrupt fault
    gap = modbus.silence(bus.link.baud) / 4
    for cut in range(1, len(reply)):
        console._monitor("tx", req)
        console.hub.bytes.clear()
        console._monitor("rx", reply[:cut])
        time.sleep(gap)
        console._monitor("rx", reply[cut:])
        said = list(console.hub.bytes)
        console._monitor("tx", req)                                  # the next request: nothing more
        assert said == console.hub.bytes[:len(said)] and len(console.hub.bytes) == len(said) + 1, (cut, console.hub.bytes)
        assert len(said) == 1 and said[0]["dir"] == "rx" and said[0]["n"] == len(reply), (cut, said)
        if crc == "good":
            assert not said[0].get("bad") and said[0]["text"].startswith("reply of ID 1: goal-speed=1000"), (cut, said)
        else:
            assert said[0]["bad"] and said[0]["text"].startswith("not a frame: Modbus RTU frame: CRC mismatch"), \
                (cut, said)
            assert "goal" not in said[0]["text"], (cut, said)


def test_an_adapter_s_echo_is_said_as_such(rig):
    _, bus, console = rig
    req = bytes.fromhex("01 03 00 D2 00 01 24 33")
    console._monitor("tx", req)
    console.hub.bytes.clear()
    console._monitor("rx", req[:5])
    console._monitor("rx", req[5:] + bytes.fromhex("01 03 02 03 E8 B8 FA"))
    assert [i["text"] for i in console.hub.bytes] == ["the request's echo (the adapter's)",
                                                      "reply of ID 1: present-position=1000"]


def test_the_page_plans_a_path_with_the_bus_s_own_frames(rig):
    """A path planned from the page on a Modbus bus is the library's Modbus plan: one answered Write
    Multiple Registers per actuator, the 17Lf's range (never IR Symmetric Store packets)."""
    _, _, console = rig
    sent = _ask(console, "plan", text='t,id,position\n0,1,9000\n0.5,1,100\n', name="wave.csv")
    reply = next(m for m in sent if m.get("req") == 3)
    assert [s["frames"] for s in reply["steps"]] == [["01 10 00 CD 00 01 02 23 28 AF 63"],
                                                     ["01 10 00 CD 00 01 02 00 64 B7 A6"]], reply
    sent = _ask(console, "plan", text='t,id,position\n0,248,5\n', name="bad.csv")
    assert any(m.get("type") == "error" and "1..247" in m.get("text", "") for m in sent), sent
