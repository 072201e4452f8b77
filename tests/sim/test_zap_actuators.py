"""The actuator-bus simulator, driven directly through the Device interface with model time."""

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zkzap.codec import zap
from zkzap.codec.framing import ZapFramer
from zkzap.sim import make_device
from zkzap.sim.zap_actuators import (BOOT_TIME, FIRMWARE_VERSION, FULL_SPEED, MODEL_NUMBER, NV_WRITE_TIME, TURNAROUND, ActuatorBus,
                               from_options, parse_fault, parse_ids)


class Host:
    """Talks to a bus with explicit model time; ``ask`` returns the replies by ``after``."""

    def __init__(self, bus, baud=57600):
        self.bus, self.baud, self.t = bus, baud, 0.0

    def send(self, pkt, baud="default"):
        self.bus.receive(pkt, self.t, self.baud if baud == "default" else baud)

    def ask(self, pkt, after=0.05, baud="default"):
        self.send(pkt, baud)
        self.t += after
        data = self.bus.poll(self.t)
        return ZapFramer().feed(data) if data else []

    def wait(self, seconds):
        self.t += seconds
        self.bus.poll(self.t)

    def read(self, ident, name):
        reg = zap.register(name)
        (reply,) = self.ask(zap.load(ident, reg))
        assert reply[3] == ident
        return int.from_bytes(reply[6:-1], "little")


@pytest.fixture
def bus():
    return from_options(ids="1,2")


@pytest.fixture
def host(bus):
    return Host(bus)


def test_make_device_builds_the_bus():
    bus = make_device("zap", ids="3,4")
    assert isinstance(bus, ActuatorBus)
    assert [a.ident for a in bus.actuators] == [3, 4]


def test_echo_reply_is_the_documented_feedback():
    bus = from_options(ids="0")
    h = Host(bus)
    assert h.ask(zap.echo(0)) == [bytes.fromhex("FFFFFF000200FD")]


def test_reply_waits_for_the_request_turnaround_and_wire_time(bus):
    bus.receive(zap.echo(1), 1.0, 57600)
    byte = 10 / 57600
    wire = 7 * byte                                         # the request's and the reply's time on the line
    # the host's UART delivers the first byte once it has crossed, the rest with the last one
    assert bus.poll(1.0 + wire + TURNAROUND + byte - 1e-4) == b""
    assert bus.next_wakeup(1.0) == pytest.approx(1.0 + wire + TURNAROUND + byte)
    assert bus.poll(1.0 + wire + TURNAROUND + byte + 1e-6) == b"\xff"
    assert bus.poll(1.0 + wire + TURNAROUND + wire - 1e-4) == b""
    assert bus.poll(1.0 + wire + TURNAROUND + wire + 1e-6) == zap.packet(1, 0)[1:]
    assert bus.next_wakeup(2.0) is None


def test_turnaround_and_byte_gap_options():
    bus = from_options(ids="1", turnaround="20", gap="1")
    bus.receive(zap.echo(1), 0.0, 57600)
    byte = 10 / 57600
    first = 7 * byte + 0.020 + byte
    assert bus.next_wakeup(0.0) == pytest.approx(first)
    got = b""
    t = 0.0
    times = []
    while bus.next_wakeup(t) is not None:
        t = bus.next_wakeup(t)
        out = bus.poll(t)
        got += out
        times.append(t)
    assert got == zap.packet(1, 0)
    assert len(times) == 7 and times[-1] == pytest.approx(first + 6 * (byte + 0.001))
    with pytest.raises(ValueError, match="turnaround"):
        from_options(ids="1", turnaround="nan")
    with pytest.raises(ValueError, match="gap"):
        from_options(ids="1", gap="-1")


def test_bytes_written_back_to_back_queue_on_the_line(bus):
    """Two commands written at once are heard one after the other, each after its own bytes."""
    bus.receive(zap.echo(1) + zap.echo(2), 0.0, 57600)
    byte = 10 / 57600
    assert bus.next_wakeup(0.0) == pytest.approx(7 * byte + TURNAROUND + byte)
    assert [bytes(p) for p in bus.received] == [zap.echo(1), zap.echo(2)]


@pytest.mark.parametrize("first,second", [(3, 0), (1, 2), (0, 3)])
def test_two_packets_in_one_write_are_each_heard_at_their_own_last_byte(first, second):
    """Two Echo packets in one write get two clean replies, one after the other (not one reply
    ANDed from both: each packet is heard when its own last byte arrives)."""
    bus = from_options(ids="0,1,2,3")
    bus.receive(zap.echo(first) + zap.echo(second), 0.0, 57600)
    byte = 10 / 57600
    got = ZapFramer().feed(bus.poll(1.0))
    assert got == [zap.packet(first, 0), zap.packet(second, 0)]
    assert bus.collisions == []
    # the same two packets written 7 byte-times apart give the same
    bus2 = from_options(ids="0,1,2,3")
    bus2.receive(zap.echo(first), 0.0, 57600)
    bus2.receive(zap.echo(second), 7 * byte, 57600)
    assert ZapFramer().feed(bus2.poll(1.0)) == got


def test_a_reply_to_the_first_packet_of_a_write_meets_its_later_bytes():
    """With no turnaround, the reply to the first packet of a long write is on the line while
    the host still sends: both are garbled, and the simulator says so."""
    bus = from_options(ids="1,2", turnaround="0")
    bus.receive(zap.echo(1) + zap.load(2, 0, 50), 0.0, 57600)
    assert bus.collisions and bus.collisions[0]["kind"] == "host"


def test_defaults_follow_the_register_map(host):
    for reg in zap.REGISTERS:
        if reg.default is not None and reg.name not in ("id",):
            assert host.read(1, reg.name) == reg.default, reg.name
    assert host.read(1, "model-number") == MODEL_NUMBER
    assert host.read(2, "id") == 2
    assert host.read(1, "present-voltage") == 120


def test_load_reads_a_block_as_consecutive_registers(host):
    (reply,) = host.ask(zap.load(1, 0x00, 5))
    assert reply[6:-1] == bytes([MODEL_NUMBER & 0xFF, MODEL_NUMBER >> 8, FIRMWARE_VERSION, 1, 32])


@pytest.mark.parametrize("mode,answered", [
    (0, {"echo"}),
    (1, {"echo", "load"}),
    (2, {"echo", "load", "store", "send", "execute", "factory-reset", "restart"}),
])
def test_feedback_return_modes(mode, answered):
    packets = {
        "echo": zap.echo(1), "load": zap.load(1, "led"), "store": zap.store(1, "led", 2),
        "send": zap.send_data(1, "led", 4), "execute": zap.execute(1),
        "factory-reset": zap.factory_reset(1), "restart": zap.restart(1),
    }
    for name, pkt in packets.items():
        bus = from_options(ids="1", return_mode=str(mode))
        got = Host(bus).ask(pkt)
        assert bool(got) == (name in answered), (mode, name)
        if got:
            assert got[0][3] == 1 and not zap.is_command(got[0][5])


def test_broadcast_is_never_answered_but_applies_to_all(host, bus):
    for a in bus.actuators:
        a.set("feedback-return-mode", 2)
    assert host.ask(zap.echo(zap.BROADCAST)) == []
    assert host.ask(zap.store(zap.BROADCAST, "led", 4)) == []
    assert [a.get("led") for a in bus.actuators] == [4, 4]


def test_goal_position_moves_at_goal_speed(host, bus):
    host.ask(zap.store(1, "goal-speed", 512))
    host.ask(zap.store(1, "goal-position", 2000), after=0.0)
    rate = FULL_SPEED * 512 / 1023
    host.wait(0.1)
    pos = host.read(1, "present-position")
    assert pos == pytest.approx(rate * 0.1, abs=2)
    assert host.read(1, "moving") == 1
    assert host.read(1, "present-motor-operating-rate") == 1024 + 512     # extending
    assert host.read(1, "present-current") > 100
    host.wait(1.0)
    assert host.read(1, "present-position") == 2000
    assert host.read(1, "moving") == 0
    assert host.read(1, "present-motor-operating-rate") == 0
    host.ask(zap.store(1, "goal-position", 1000), after=0.01)
    assert 0 < host.read(1, "present-motor-operating-rate") <= 1023       # retracting


def test_goal_clamped_to_stroke_limits_and_speed_limit(host, bus):
    host.ask(zap.store(1, "long-stroke-limit", 3000))
    host.ask(zap.store(1, "speed-limit", 100))
    start = host.t
    host.ask(zap.store(1, "goal-position", 4000))
    assert host.read(1, "goal-position") == 3000
    elapsed = host.t - start                                     # the position is read at this time
    assert host.read(1, "present-position") == pytest.approx(FULL_SPEED * 100 / 1023 * elapsed, abs=2)


def test_force_off_stops_and_goal_position_turns_it_on(host, bus):
    host.ask(zap.store(1, "goal-position", 3000))
    host.wait(0.05)
    host.ask(zap.store(1, "force-on-off", 0))
    stopped = host.read(1, "present-position")
    host.wait(0.2)
    assert host.read(1, "present-position") == stopped
    assert host.read(1, "moving") == 0
    assert host.read(1, "present-current") == 0
    host.ask(zap.store(1, "goal-position", 3000))
    assert host.read(1, "force-on-off") == 1
    host.wait(0.5)
    assert host.read(1, "present-position") == 3000


def test_out_of_range_and_read_only_writes_are_ignored(host):
    host.ask(zap.store(1, "baud-rate", 32))
    host.ask(zap.packet(1, 0xF3, bytes([0x04, 99])))            # not a baud code
    host.ask(zap.packet(1, 0xF3, bytes([0x10, 3])))             # return mode 3
    host.ask(zap.packet(1, 0xF3, bytes([0x8C, 0x10, 0x00])))    # present-position is read-only
    assert host.read(1, "baud-rate") == 32
    assert host.read(1, "feedback-return-mode") == 1
    assert host.read(1, "present-position") == 0


def test_send_data_is_staged_until_execution(host, bus):
    host.ask(zap.send_data(1, "led", 2))
    host.ask(zap.send_data(2, "led", 4))
    assert host.read(1, "led") == 0
    host.ask(zap.execute(zap.BROADCAST))
    assert host.read(1, "led") == 2 and host.read(2, "led") == 4
    host.ask(zap.execute(zap.BROADCAST))                         # nothing staged any more
    assert host.read(1, "led") == 2


def test_symmetric_store_writes_each_target(host):
    (pkt,) = zap.symmetric_store("goal-position", [(1, 1023), (2, 2047)])
    assert host.ask(pkt) == []
    assert host.read(1, "goal-position") == 1023
    assert host.read(2, "goal-position") == 2047
    host.wait(1.0)
    assert host.read(2, "present-position") == 2047


def test_id_change_applies_at_once(host, bus):
    host.ask(zap.store(1, "id", 9))
    assert host.ask(zap.echo(1)) == []
    assert host.ask(zap.echo(9)) == [zap.packet(9, 0)]


def test_baud_change_applies_after_restart_and_a_wrong_baud_is_not_heard(host, bus):
    host.ask(zap.store(1, "baud-rate", zap.BAUD_TO_CODE[115200]))
    assert host.ask(zap.echo(1)) == [zap.packet(1, 0)]                   # still 57600
    host.ask(zap.restart(1))
    host.wait(BOOT_TIME)
    assert host.ask(zap.echo(1)) == []                                   # host still at 57600
    assert host.ask(zap.echo(1), baud=115200) == [zap.packet(1, 0)]
    assert host.ask(zap.echo(1), baud=None) == [zap.packet(1, 0)]        # a socket: no baud


def test_restart_is_deaf_while_booting_and_resets_volatile(bus):
    h = Host(bus)
    h.ask(zap.store(1, "led", 2))
    h.ask(zap.store(1, "goal-speed", 100))
    h.send(zap.restart(1))
    h.t += TURNAROUND
    assert h.ask(zap.echo(1), after=0.001) == []
    h.wait(BOOT_TIME)
    assert h.read(1, "led") == 0
    assert h.read(1, "goal-speed") == 1023


@pytest.mark.parametrize("option,expect_id,expect_baud", [(0, 1, 16), (1, 0, 16), (2, 1, 32), (3, 0, 32)])
def test_factory_reset_options(option, expect_id, expect_baud):
    bus = from_options(ids="1")
    h = Host(bus)
    h.ask(zap.store(1, "baud-rate", 16))
    h.ask(zap.store(1, "long-stroke-limit", 3000))
    h.ask(zap.factory_reset(1, bool(option & 1), bool(option & 2)))
    h.wait(BOOT_TIME)
    a = bus.actuators[0]
    assert (a.ident, a.get("baud-rate"), a.get("long-stroke-limit")) == (expect_id, expect_baud, 3686)
    assert a.baud == zap.BAUD_CODES[expect_baud]


def test_nv_write_pauses_the_actuator(bus):
    bus.actuators[0].set("feedback-return-mode", 2)
    bus.receive(zap.store(1, "long-stroke-limit", 3000), 0.0, 57600)
    bus.receive(zap.echo(1), 0.0, 57600)
    first = bus.next_wakeup(0.0)
    assert first >= NV_WRITE_TIME + TURNAROUND
    out = bus.poll(1.0)
    assert ZapFramer().feed(out) == [zap.packet(1, 0), zap.packet(1, 0)]


def test_state_file_keeps_stored_registers_and_position(tmp_path):
    path = str(tmp_path / "bus.json")
    bus = from_options(ids="1,2", state=path)
    h = Host(bus)
    h.ask(zap.store(1, "long-stroke-limit", 3000))
    h.ask(zap.store(2, "id", 7))
    h.ask(zap.store(1, "goal-position", 1500))
    h.wait(1.0)
    h.ask(zap.store(1, "led", 2))                                # volatile: not kept
    bus.close()
    doc = json.load(open(path))
    assert doc["actuators"][1]["registers"]["id"] == 7

    again = from_options(ids="5", state=path)                    # the file wins over ids
    assert again.restored
    assert [a.ident for a in again.actuators] == [1, 7]
    h2 = Host(again)
    assert h2.read(1, "long-stroke-limit") == 3000
    assert h2.read(1, "present-position") == 1500
    assert h2.read(1, "goal-position") == 1500
    assert h2.read(1, "led") == 0


def test_state_file_rejects_garbage(tmp_path):
    path = tmp_path / "bus.json"
    path.write_text('{"format": "something else"}')
    with pytest.raises(ValueError, match="not a zkzap actuator-bus state file"):
        from_options(state=str(path))
    path.write_text(json.dumps({"format": "zkzap-zap-bus/1", "actuators": [{"registers": {"id": 999}}]}))
    with pytest.raises(ValueError, match="id: 999 is out of range"):
        from_options(state=str(path))


# -- faults ---------------------------------------------------------------------------------------

def test_overload_sets_bit5_in_every_reply_and_cuts_force_until_restart(host, bus):
    bus.inject(2, "overload")
    (reply,) = host.ask(zap.echo(2))
    assert reply[5] == 0x20
    assert host.read(2, "force-on-off") == 0
    host.ask(zap.store(2, "goal-position", 2000))
    host.wait(0.5)
    assert host.read(2, "present-position") == 0                 # the force stays cut
    host.ask(zap.restart(2))
    host.wait(BOOT_TIME)
    assert host.ask(zap.echo(2)) == [zap.packet(2, 0)]


def test_voltage_fault_sets_bit0(host, bus):
    bus.inject(1, "voltage", 6.5)
    (reply,) = host.ask(zap.load(1, "present-voltage"))
    assert reply[5] == 0x01 and reply[6] == 65
    bus.clear_faults()
    assert host.ask(zap.echo(1)) == [zap.packet(1, 0)]


@pytest.mark.parametrize("kind,value,check", [
    ("silent", None, lambda r, good: r == b""),
    ("corrupt", None, lambda r, good: r[:-1] == good[:-1] and r[-1] != good[-1]),
    ("truncate", 3, lambda r, good: r == good[:-3]),
    ("wrong-id", 9, lambda r, good: r == zap.packet(9, 0)),
])
def test_reply_faults(bus, kind, value, check):
    bus.inject(1, kind, value)
    bus.receive(zap.echo(1), 0.0, 57600)
    assert check(bus.poll(1.0), zap.packet(1, 0))


def test_fault_count_and_delay(bus):
    bus.inject(1, "corrupt", count=1)
    bus.receive(zap.echo(1), 0.0, None)
    assert bus.poll(1.0) != zap.packet(1, 0)
    bus.receive(zap.echo(1), 1.0, None)
    assert bus.poll(2.0) == zap.packet(1, 0)
    bus.inject(1, "delay", 30)
    bus.receive(zap.echo(1), 2.0, None)
    assert bus.next_wakeup(2.0) > 2.030


def test_stuck_keeps_moving_without_progress(host, bus):
    bus.inject(1, "stuck")
    host.ask(zap.store(1, "goal-position", 2000))
    host.wait(1.0)
    assert host.read(1, "present-position") == 0
    assert host.read(1, "moving") == 1
    assert host.read(1, "present-current") == 800                # stalled at the current limit


def test_adapter_echo_comes_first(bus):
    bus.echo = True
    bus.receive(zap.echo(1), 0.0, 57600)
    assert bus.poll(0.0) == b""                          # the echo crosses the line with the command
    assert bus.poll(7 * 10 / 57600) == zap.echo(1)
    assert bus.poll(1.0) == zap.packet(1, 0)


@pytest.mark.parametrize("overload", [False, True], ids=["same-state", "one-overloaded"])
def test_two_actuators_with_one_id_collide(overload):
    """Duplicate IDs garble the reply even when both would say the same: two transmitters are
    never in step (the second is modelled a byte behind; the line is the wired-AND)."""
    bus = from_options(ids="1,1")
    bus.actuators[1].overload = overload
    bus.receive(zap.echo(1), 0.0, None)
    out = bus.poll(1.0)
    a, b = zap.packet(1, 0), b"\xff" + zap.packet(1, 0x20 if overload else 0)
    assert out == bytes(x & y for x, y in zip(a + b"\xff", b))
    assert ZapFramer().feed(out) == []
    one = from_options(ids="1,2")
    one.receive(zap.echo(1), 0.0, None)
    assert one.poll(1.0) == zap.packet(1, 0)          # one actuator per ID: a clean reply


def test_a_reply_sent_at_another_baud_is_not_heard_clean():
    bus = from_options(ids="1")
    bus.receive(zap.echo(1), 0.0, 57600)
    assert bus.poll_line(1.0, 115200) == b""          # the host switched baud before reading
    bus.receive(zap.echo(1), 2.0, 57600)
    assert bus.poll_line(3.0, 57600) == zap.packet(1, 0)


def test_fault_text_and_options():
    assert parse_fault("2:overload") == (2, "overload", None, None)
    assert parse_fault("all:delay=30/2") == (None, "delay", 30.0, 2)
    assert parse_fault("corrupt") == (None, "corrupt", None, None)
    assert parse_fault("3:no-reply") == (3, "silent", None, None)
    for bad, needle in [("2:explode", "unknown kind"), ("x:silent", "not a number"),
                        ("300:silent", "out of range"), ("1:corrupt/0", "COUNT"),
                        ("1:overload=3", "takes no value"), ("1:voltage=abc", "not a number")]:
        with pytest.raises(ValueError, match=needle):
            parse_fault(bad)
    bus = from_options(ids="1,2", faults="2:silent,1:corrupt/1", echo="1", voltage="6")
    assert bus.echo and "silent" in bus.actuator(2).faults and bus.actuator(1).supply == 6.0


def test_ids_option():
    assert parse_ids("1,2,5-7") == [(1, None), (2, None), (5, None), (6, None), (7, None)]
    assert parse_ids("3@115200") == [(3, 115200)]
    for bad in ("", "254", "3-1", "x", "1@1234"):
        with pytest.raises(ValueError):
            parse_ids(bad)
    with pytest.raises(ValueError, match="unknown option"):
        from_options(idz="1")
    with pytest.raises(ValueError, match="baud"):
        from_options(baud="1234")


@settings(max_examples=60, deadline=None)
@given(st.lists(st.binary(max_size=40), max_size=12))
def test_any_bytes_never_break_the_bus(chunks):
    bus = from_options(ids="0,1,2")
    t = 0.0
    for c in chunks:
        bus.receive(c, t, 57600)
        t += 0.01
        bus.poll(t)
    out = bus.poll(t + 1.0)
    # whatever it answered is made of whole, valid feedback packets
    framer = ZapFramer()
    pkts = framer.feed(out)
    assert framer.bad == 0 and framer.skipped == 0
    assert all(not zap.is_command(p[5]) for p in pkts)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from([r for r in zap.REGISTERS if r.writable and r.stored is not None]), st.data())
def test_store_then_load_round_trips(reg, data):
    value = data.draw(st.sampled_from(reg.values()))
    bus = from_options(ids="1")
    h = Host(bus)
    h.ask(zap.store(1, reg, value))
    if reg.name == "id":
        assert bus.actuators[0].ident == value
        return
    got = bus.actuators[0].get(reg)
    if reg.name == "goal-position":
        assert got == min(value, 3686)
    else:
        assert got == value


def test_a_host_transmitting_while_an_actuator_replies_garbles_both():
    """The line is half-duplex: the host's bytes meet the reply's on the wire (wired-AND)."""
    bus = from_options(ids="1,2", turnaround="20", echo="1")
    seen = []
    bus.on_collision = seen.append
    byte = 10 / 57600
    bus.receive(zap.echo(1), 0.0, 57600)
    reply_starts = 7 * byte + 0.020
    bus.receive(zap.echo(2), reply_starts + 2 * byte, 57600)       # the host does not wait
    out = bus.poll(1.0)
    assert bus.collisions == seen == [{"t": pytest.approx(reply_starts + 2 * byte, abs=1e-6), "kind": "host",
                                       "ids": [1]}]
    packets = ZapFramer().feed(out)
    assert zap.packet(1, 0) not in packets                          # ID 1's reply garbled
    assert zap.echo(2) not in packets and zap.packet(2, 0) not in packets   # ID 2 heard no command
    assert [p[3] for p in bus.received] == [1]


def test_a_host_that_waits_for_the_reply_meets_nothing():
    bus = from_options(ids="1,2", turnaround="20", gap="1", echo="1")
    bus.receive(zap.echo(1), 0.0, 57600)
    first = bus.poll(1.0)
    bus.receive(zap.echo(2), 1.0, 57600)
    second = bus.poll(2.0)
    assert first == zap.echo(1) + zap.packet(1, 0) and second == zap.echo(2) + zap.packet(2, 0)
    assert bus.collisions == []


def test_replies_of_two_actuators_that_overlap_collide():
    bus = from_options(ids="1,2", faults="1:delay=3")
    bus.receive(zap.echo(1), 0.0, 57600)                            # answered 3 ms late ...
    bus.receive(zap.echo(2), 7 * 10 / 57600 + 0.0015, 57600)        # ... just as ID 2 answers
    out = bus.poll(1.0)
    assert [c["kind"] for c in bus.collisions] == ["actuators"] and bus.collisions[0]["ids"] == [1, 2]
    assert ZapFramer().feed(out) == []
