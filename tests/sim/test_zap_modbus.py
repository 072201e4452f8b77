"""The simulated 17Lf (Modbus RTU), driven through the Device interface with model time; the
faults both protocol families share, parametrised over both; a stateful model of the control
table; and pymodbus's own client driving the simulator over a pty."""

import json

import pytest
from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, rule

from zkzap.codec import modbus, zap
from zkzap.codec.framing import RtuFramer, ZapFramer
from zkzap.sim import make_device
from zkzap.sim.zap_actuators import NV_WRITE_TIME, TURNAROUND, from_options
from zkzap.sim.zap_modbus import MAP, ModbusActuatorBus

H = bytes.fromhex


class Host:
    """Talks to a bus with explicit model time; ``ask`` returns the frames that came back by ``after``."""

    def __init__(self, bus, protocol, baud=57600):
        self.bus, self.protocol, self.baud, self.t = bus, protocol, baud, 0.0

    def ask(self, frame, after=0.05, baud=None):
        self.bus.receive(frame, self.t, baud or self.baud)
        self.t += after
        data = self.bus.poll_line(self.t, baud or self.baud)
        framer = ZapFramer() if self.protocol == "ir" else RtuFramer()
        return (framer.feed(data) + framer.flush()) if data else []

    def raw(self, frame, after=0.05):
        self.bus.receive(frame, self.t, self.baud)
        self.t += after
        return self.bus.poll_line(self.t, self.baud)

    def read(self, ident, name):
        if self.protocol == "ir":
            (reply,) = self.ask(zap.load(ident, name))
            return int.from_bytes(reply[6:-1], "little")
        (reply,) = self.ask(modbus.read(ident, name))
        return modbus.parse_reply(modbus.read(ident, name), reply)[0]

    def request(self, ident):
        """A request answered on both protocols: a read of present-position."""
        return zap.load(ident, "present-position") if self.protocol == "ir" else modbus.read(ident, "present-position")

    def sender(self, frame):
        return frame[3] if self.protocol == "ir" else frame[0]

    def valid(self, frame):
        if self.protocol == "ir":
            return zap.checksum_ok(frame) if hasattr(zap, "checksum_ok") else _ir_ok(frame)
        return modbus.crc_ok(frame)


def _ir_ok(frame):
    try:
        zap.check_packet(frame)
    except zap.PacketError:
        return False
    return True


def mb_bus(ids="1,2", **options):
    return from_options(ids=ids, protocol="modbus", **options)


@pytest.fixture
def host():
    return Host(mb_bus(), "modbus")


def test_url_and_factory_build_a_17lf_bus():
    bus = make_device("zap", protocol="modbus", ids="3,4")
    assert isinstance(bus, ModbusActuatorBus) and [a.ident for a in bus.actuators] == [3, 4]
    assert [a.ident for a in make_device("zap", protocol="modbus").actuators] == [1]


@pytest.mark.parametrize("options,fault", [
    ({"ids": "0"}, "1..247"), ({"ids": "248"}, "out of range"), ({"return_mode": "2"}, "no feedback-return-mode"),
    ({"protocol": "can"}, "allowed ir, modbus"),
])
def test_bad_options(options, fault):
    options = {"protocol": "modbus", **options}
    with pytest.raises(ValueError, match=fault):
        from_options(**options)


def test_worked_example_read_and_write(host):
    host.bus.actuator(1).set("present-position", 1000)
    host.bus.actuator(1).set("goal-position", 1000)
    assert host.ask(H("01 03 00 D2 00 01 24 33")) == [H("01 03 02 03 E8 B8 FA")]
    assert host.ask(H("01 06 00 D1 03 20 D8 DB")) == [H("01 06 00 D1 03 20 D8 DB")]
    assert host.ask(H("01 10 00 D0 00 02 04 03 E8 03 20 7F AB")) == [H("01 10 00 D0 00 02 40 31")]
    assert host.read(1, "goal-speed") == 1000 and host.read(1, "goal-current") == 800


@pytest.mark.parametrize("frame,code", [
    (modbus.frame(1, H("04 00 00 00 01")), 1),                # an unknown function
    (modbus.read_registers(1, 300, 1), 2),                    # no such register
    (modbus.read_registers(1, 205, 3), 2),                    # a block across a gap in the table
    (modbus.write_register(1, 210, 5), 2),                    # present-position is read-only
    (modbus.write_register(1, 205, 10001), 3),                # goal-position outside 0..10000
    (modbus.write_register(1, 4, 0), 3),                      # ID 0 is broadcast, never an ID
    (modbus.write_register(1, 5, 7), 3),                      # not a baud-rate code
    (modbus.write_registers(1, 208, [100, 2000]), 0),         # fine: full 16-bit ranges
])
def test_exception_replies(host, frame, code):
    (reply,) = host.ask(frame)
    if code == 0:
        assert modbus.parse_reply(frame, reply) == [100, 2000]
        return
    with pytest.raises(modbus.ExceptionReply) as e:
        modbus.parse_reply(frame, reply)
    assert e.value.exception == code


def test_locked_parameters_answer_busy_but_volatile_writes_go_through(host):
    host.bus.inject(1, "locked")
    (reply,) = host.ask(modbus.write(1, "speed-limit", 500))
    with pytest.raises(modbus.ExceptionReply) as e:
        modbus.parse_reply(modbus.write(1, "speed-limit", 500), reply)
    assert e.value.name == "slave-device-busy" and host.read(1, "speed-limit") == 1000
    assert host.ask(modbus.write(1, "goal-speed", 300)) == [modbus.write(1, "goal-speed", 300)]
    host.bus.clear_faults()
    host.ask(modbus.write(1, "speed-limit", 500))
    assert host.read(1, "speed-limit") == 500


def test_ir_bus_refuses_the_modbus_fault():
    with pytest.raises(ValueError, match="locked"):
        from_options(ids="1", faults="1:locked")


def test_goal_is_clamped_to_the_stroke_limits_and_the_rod_moves(host):
    host.ask(modbus.write_block(1, {"short-stroke-limit": 1000, "long-stroke-limit": 8000})[0])
    host.ask(modbus.write(1, "goal-position", 9500))
    assert host.read(1, "goal-position") == 8000
    assert host.read(1, "moving") == 1 and host.read(1, "present-current") > 0
    host.t += 2.0
    assert host.read(1, "present-position") == 8000 and host.read(1, "moving") == 0


def test_a_new_id_answers_at_once_and_the_reply_comes_from_the_old(host):
    assert host.ask(modbus.write(1, "id", 9)) == [modbus.write(1, "id", 9)]
    assert host.read(9, "id") == 9
    assert host.ask(modbus.read(1, "id")) == []


def test_broadcast_is_obeyed_and_never_answered(host):
    assert host.raw(modbus.write(0, "goal-speed", 400)) == b""
    assert host.read(1, "goal-speed") == 400 and host.read(2, "goal-speed") == 400


def test_a_new_baud_rate_applies_after_the_reply(host):
    w = modbus.write(1, "baud-rate", 8)           # 115200
    assert host.ask(w) == [w]
    assert host.ask(modbus.read(1, "id")) == []
    assert host.ask(modbus.read(1, "id"), baud=115200) != []


def test_stored_write_waits_for_memory_and_state_persists(tmp_path):
    state = tmp_path / "bus.json"
    bus = mb_bus("1", state=str(state))
    h = Host(bus, "modbus")
    h.bus.receive(modbus.write(1, "speed-limit", 321), 0.0, 57600)
    wire = 8 * 10 / 57600
    due = bus._line[0].due
    assert due == pytest.approx(wire + NV_WRITE_TIME + TURNAROUND + 10 / 57600, rel=0.05)
    doc = json.loads(state.read_text())
    assert doc["format"] == "zkzap-zap-modbus-bus/1" and doc["actuators"][0]["registers"]["speed-limit"] == 321
    again = mb_bus("5", state=str(state))
    assert again.restored and again.actuator(1).get("speed-limit") == 321


def test_overload_sets_its_hardware_error_bit_and_cuts_the_force_where_shutdown_says(host):
    # the factory alarm-shutdown (33: bits 0 and 5) does not hold bit 6, overload
    host.bus.inject(1, "overload")
    assert host.read(1, "hardware-error") == 0x40 and host.read(1, "force-on-off") == 1
    host.ask(modbus.write(2, "alarm-shutdown", 0x41))
    host.bus.inject(2, "overload")
    assert host.read(2, "hardware-error") == 0x40 and host.read(2, "force-on-off") == 0


def test_indirect_data_reads_the_register_it_names(host):
    host.bus.actuator(1).set("present-position", 1234)
    host.bus.actuator(1).set("goal-position", 1234)
    host.ask(modbus.write(1, "indirect-address-0", 210))
    assert host.read(1, "indirect-data-0") == 1234


# -- the faults both families share, one test each over both ------------------------------------

@pytest.fixture(params=["ir", "modbus"])
def either(request):
    bus = from_options(ids="1,2", protocol=request.param)
    return Host(bus, request.param)


def test_silent_fault(either):
    either.bus.inject(1, "silent")
    assert either.ask(either.request(1)) == []
    assert len(either.ask(either.request(2))) == 1


def test_corrupt_fault_spoils_the_check(either):
    either.bus.inject(1, "corrupt", count=1)
    data = either.raw(either.request(1))
    assert data and not either.valid(data)
    (good,) = either.ask(either.request(1))
    assert either.valid(good)


def test_truncate_fault_cuts_the_reply(either):
    either.bus.inject(1, "truncate", 3)
    whole = len(either.raw(either.request(2)))
    assert len(either.raw(either.request(1))) == whole - 3


def test_wrong_id_fault(either):
    either.bus.inject(1, "wrong-id", 7)
    (reply,) = either.ask(either.request(1))
    assert either.sender(reply) == 7 and either.valid(reply)


def test_delay_fault(either):
    either.bus.inject(1, "delay", 30)
    assert either.ask(either.request(1), after=0.02) == []
    either.t += 0.03
    assert either.bus.poll_line(either.t, 57600) != b""


def test_echo_fault_echoes_the_request(either):
    either.bus.inject(None, "echo")
    req = either.request(1)
    data = either.raw(req)
    assert data.startswith(req) and len(data) > len(req)


def test_replies_of_two_actuators_that_overlap_collide(either):
    bus = from_options(ids="1,2", faults="1:delay=3", protocol=either.protocol)
    h = Host(bus, either.protocol)
    first, second = h.request(1), h.request(2)
    bus.receive(first, 0.0, 57600)                                  # answered 3 ms late ...
    bus.receive(second, len(first) * 10 / 57600 + 0.0015, 57600)    # ... just as ID 2 answers
    bus.poll(1.0)
    assert [c["kind"] for c in bus.collisions] == ["actuators"] and bus.collisions[0]["ids"] == [1, 2]


# -- a stateful model of the control table --------------------------------------------------------

SIMPLE = [r for r in MAP.registers if r.writable and r.documented and r.name not in
          ("id", "baud-rate", "goal-position", "force-on-off", "short-stroke-limit", "long-stroke-limit",
           "alarm-shutdown", "stop", "pause") and not r.name.startswith("indirect")]


class ControlTable(RuleBasedStateMachine):
    """Random reads and writes (single and multiple, good and bad) against one 17Lf; every
    answer is checked against a plain dict of what was written."""

    @initialize()
    def start(self):
        self.bus = mb_bus("1")
        self.host = Host(self.bus, "modbus")
        self.model = {r.address: self.bus.actuator(1).get(r.name) for r in SIMPLE}

    @rule(reg=st.sampled_from(SIMPLE), value=st.integers(0, 0xFFFF))
    def write(self, reg, value):
        frame = modbus.write_register(1, reg.address, value)
        (reply,) = self.host.ask(frame)
        if reg.allows(value):
            assert modbus.parse_reply(frame, reply) == [value]
            self.model[reg.address] = value
        else:
            with pytest.raises(modbus.ExceptionReply) as e:
                modbus.parse_reply(frame, reply)
            assert e.value.exception == 3

    @rule(start=st.sampled_from(SIMPLE), values=st.lists(st.integers(0, 1000), min_size=1, max_size=6))
    def write_many(self, start, values):
        addrs = range(start.address, start.address + len(values))
        frame = modbus.write_registers(1, start.address, values)
        (reply,) = self.host.ask(frame)
        regs = [MAP.owner.get(a) for a in addrs]
        if all(r is not None and r.writable for r in regs) and all(r.allows(v) for r, v in zip(regs, values)):
            assert modbus.parse_reply(frame, reply) == values
            for a, v in zip(addrs, values):
                if a in self.model:
                    self.model[a] = v
        else:
            with pytest.raises(modbus.ExceptionReply):
                modbus.parse_reply(frame, reply)

    @rule(reg=st.sampled_from(SIMPLE))
    def read(self, reg):
        frame = modbus.read_registers(1, reg.address, 1)
        (reply,) = self.host.ask(frame)
        assert modbus.parse_reply(frame, reply) == [self.model[reg.address]]

    @invariant()
    def every_value_as_written(self):
        if hasattr(self, "bus"):
            a = self.bus.actuator(1)
            assert all(a.words[addr] == v for addr, v in self.model.items())


ControlTable.TestCase.settings = settings(max_examples=25, stateful_step_count=20, deadline=None)
TestControlTable = ControlTable.TestCase


# -- pymodbus's client drives the simulator ----------------------------------------------------------

def test_pymodbus_client_drives_the_simulated_17lf():
    from pymodbus.client import ModbusSerialClient

    from zkzap.sim import start_zap

    with start_zap(ids=[1, 3], protocol="modbus", transport="pty") as sim:
        client = ModbusSerialClient(port=sim.url, baudrate=57600, timeout=1, retries=1)
        assert client.connect()
        try:
            with sim.lock:
                sim.device.actuator(1).set("present-position", 1000)
                sim.device.actuator(1).set("goal-position", 1000)
            r = client.read_holding_registers(210, count=2, device_id=1)
            assert not r.isError() and r.registers == [1000, sim.device.actuator(1).get("present-current")]
            assert not client.write_register(205, 3000, device_id=1).isError()
            assert not client.write_registers(208, [500, 600], device_id=3).isError()
            with sim.lock:
                assert sim.device.actuator(1).get("goal-position") == 3000
                a3 = sim.device.actuator(3)
                assert (a3.get("goal-speed"), a3.get("goal-current")) == (500, 600)
            bad = client.read_holding_registers(300, count=1, device_id=1)
            assert bad.isError() and bad.exception_code == 2
            bad = client.write_register(205, 20000, device_id=1)
            assert bad.isError() and bad.exception_code == 3
            # what pymodbus wrote, read back by zkzap's own codec from the same line
            r = client.read_holding_registers(205, count=1, device_id=1)
            assert r.registers == [3000]
        finally:
            client.close()
