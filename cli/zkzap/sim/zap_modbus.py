"""A simulated 17Lf: mightyZAP actuators that speak Modbus RTU, on the same simulated line.

The line (wire time, turnaround, collisions, the adapter's echo, baud rates, faults, the state
file) is :class:`zkzap.sim.zap_actuators.ActuatorBus`'s, and the motion model (rod travel at the
goal speed, clamped to the stroke limits, ``moving``, present current, force and alarms) is
:class:`zkzap.sim.zap_actuators.Actuator`'s: it speaks register names, and here they are the
17Lf control table's (:data:`zkzap.codec.regmap.builtin` ``17lf-modbus``), 16 bits each at one
address. What this module adds is the protocol family: Modbus requests and their replies.

Every unicast request is answered (ID 0, broadcast, never):

- 0x03 Read Holding Registers of 1..125 registers that all lie in the control table; an
  indirect-data register reads the register its indirect-address names;
- 0x06 / 0x10 writes of registers that all lie in the table and are writable, with values
  inside their documented range (goal-position is then clamped to the stroke limits);
- exception replies otherwise: 1 an unknown function, 2 an address outside the table or a
  read-only register written, 3 a count or a value out of range, 6 (busy: parameters locked)
  a write to a stored (NV) register while the ``locked`` fault holds.

A new ID applies at once (the reply comes from the old one); a new baud rate after the reply.
Faults are the IR simulator's (overload sets hardware-error bit 6, voltage bit 0) plus
``locked``.
"""

from __future__ import annotations

from ..codec import modbus
from ..codec.framing import RtuFramer
from ..codec.regmap import builtin
from ..errors import InvalidValue
from . import zap_actuators as ir

MAP = builtin("17lf-modbus")
REG = MAP.by_name
STATE_FORMAT = "zkzap-zap-modbus-bus/1"
#: The 17Lf's hardware-error bits.
OVERLOAD_BIT = 0x40
VOLTAGE_BIT = 0x01
#: Supply voltage window of the simulated 17Lf (the map gives none): the 12Lf's 7.0..13.0 V.
VOLTAGE_WINDOW = (70, 130)
#: Values for registers the control table gives no default ("per model"): a plausible 17Lf.
SIM_DEFAULTS = {
    "model-number": 0x1711,
    "firmware-version": 0x0100,
    "long-stroke-limit": 10000,
    "acceleration": 20,
    "deceleration": 64,
    "min-position-calibration": 0,
    "max-position-calibration": 10000,
    "current-i-gain": 20,
    "current-p-gain": 30,
    "speed-d-gain": 0,
    "speed-i-gain": 10,
    "speed-p-gain": 40,
    "goal-position": 0,
    "goal-speed": 1000,
    "goal-current": 800,
    "action-enable": 0,
}
STORED = tuple(r for r in MAP.registers if r.stored and r.writable)


class ModbusActuator(ir.Actuator):
    """One simulated 17Lf (``slot``: its place on the bus)."""

    POSITION_MAX = 10000
    SPEED_MAX = 1000

    def __init__(self, slot: int, ident: int = 1, baud: int = 57600):
        self.words = {r.address: 0 for r in MAP.registers}
        self.locked = False
        super().__init__(slot, 0, baud)           # the motion model's state
        for r in MAP.registers:                   # ... and the 17Lf's control table
            self.words[r.address] = SIM_DEFAULTS.get(r.name, r.default) or 0
        self.words[REG["id"].address] = ident
        self.words[REG["baud-rate"].address] = _code_of(baud)
        self.power_on(0.0)

    # -- the control table behind the motion model's register names -------------------------------

    def _poke(self, reg, value):
        mine = REG.get(reg.name)
        if mine is not None:
            self.words[mine.address] = int(value) & 0xFFFF

    def _peek(self, reg) -> int:
        mine = REG.get(reg.name)
        if mine is not None:
            return self.words[mine.address]
        if reg.name == "lowest-limit-voltage":
            return VOLTAGE_WINDOW[0]
        if reg.name == "highest-limit-voltage":
            return VOLTAGE_WINDOW[1]
        return 0

    def get(self, name) -> int:
        """A register's value (by name or address of the 17Lf's map), as a read would see it now."""
        return self.words[MAP.register(name).address]

    def set(self, name, value) -> None:
        """Set a register directly (test set-up; no side effects)."""
        reg = MAP.register(name)
        self.words[reg.address] = value
        if reg.name == "baud-rate":
            self.baud = _baud_of(value)
        if reg.name == "present-position":
            self.pos = float(value)

    @property
    def ident(self) -> int:
        return self.words[REG["id"].address]

    @property
    def return_mode(self) -> int:
        return 2                          # every unicast request is answered

    def error_byte(self) -> int:
        err = OVERLOAD_BIT if self.overload else 0
        if not VOLTAGE_WINDOW[0] <= round(self.supply * 10) <= VOLTAGE_WINDOW[1]:
            err |= VOLTAGE_BIT
        return err

    def power_on(self, now: float) -> None:
        self.baud = _baud_of(self.words[REG["baud-rate"].address])
        super().power_on(now)
        self.baud = _baud_of(self.words[REG["baud-rate"].address])

    def _refresh(self, driving: bool, velocity: float) -> None:
        super()._refresh(driving, velocity)
        self.words[REG["hardware-error"].address] = self.error_byte()
        self.words[REG["present-voltage"].address] = max(0, min(0xFFFF, round(self.supply * 10)))

    # -- requests -------------------------------------------------------------------------------------

    def _read_word(self, address: int) -> int:
        reg = MAP.owner[address]
        if reg.name.startswith("indirect-data-"):
            target = self.words[REG["indirect-address-" + reg.name.rsplit("-", 1)[1]].address]
            return self.words.get(target, 0) if target in MAP.owner and not target == address else 0
        return self.words[address]

    def _check_write(self, address, values):
        """The exception code a write of ``values`` from ``address`` gets, or 0."""
        for i, value in enumerate(values):
            reg = MAP.owner.get(address + i)
            if reg is None or not reg.writable:
                return 2
        for i, value in enumerate(values):
            reg = MAP.owner[address + i]
            if not reg.allows(value) or (reg.name == "id" and not 1 <= value <= modbus.MAX_ID):
                return 3
        if self.locked and any(MAP.owner[address + i].stored for i in range(len(values))):
            return 6
        return 0

    def _write_words(self, address, values) -> bool:
        stored = False
        for i, value in enumerate(values):
            reg = MAP.owner[address + i]
            if reg.name.startswith("indirect-data-"):
                target = self.words[REG["indirect-address-" + reg.name.rsplit("-", 1)[1]].address]
                treg = MAP.owner.get(target)
                if treg is None or not treg.writable or not treg.allows(value):
                    continue
                reg = treg
            old = self.words[reg.address]
            self.words[reg.address] = value
            stored = stored or bool(reg.stored)
            self._effect(reg, old, value)
        return stored

    def handle(self, pkt: bytes, now: float):
        """Process one request addressed to this actuator (or broadcast): ``(start, reply,
        baud)`` or None."""
        if now < self.deaf_until:
            return None
        start = max(now, self.busy_until)
        self.update(start)
        req = modbus.Request(pkt)
        ident, fn = pkt[0], pkt[1]
        nv = False
        baud = self.baud
        new_baud = None
        if fn not in modbus.FUNCTIONS:
            reply = modbus.exception_reply(ident, fn, 1)
        elif req.malformed:
            reply = modbus.exception_reply(ident, fn, 3)
        elif fn == modbus.READ_HOLDING:
            addrs = range(req.address, req.address + req.count)
            if not 1 <= req.count <= modbus.MAX_READ:
                reply = modbus.exception_reply(ident, fn, 3)
            elif any(a not in MAP.owner for a in addrs):
                reply = modbus.exception_reply(ident, fn, 2)
            else:
                reply = modbus.read_reply(ident, [self._read_word(a) for a in addrs])
        else:
            if fn == modbus.WRITE_MULTIPLE and not 1 <= req.count <= modbus.MAX_WRITE:
                code = 3
            else:
                code = self._check_write(req.address, req.values)
            if code:
                reply = modbus.exception_reply(ident, fn, code)
            else:
                before = self.words[REG["baud-rate"].address]
                nv = self._write_words(req.address, req.values)
                after = self.words[REG["baud-rate"].address]
                if after != before:
                    new_baud = _baud_of(after)
                reply = pkt if fn == modbus.WRITE_SINGLE else modbus.write_multiple_reply(ident, req.address,
                                                                                          req.count)
        done = start + (ir.NV_WRITE_TIME if nv else 0.0)
        self.busy_until = done
        self.nv_dirty = self.nv_dirty or nv
        if new_baud is not None:
            self.baud = new_baud            # after this reply, which leaves at the old rate
        if ident == modbus.BROADCAST:
            return None
        return done + self.turnaround, reply, baud

    @staticmethod
    def _sender(reply) -> int:
        return reply[0]

    ID_AT = 0

    @staticmethod
    def _whole(reply) -> bool:
        return len(reply) >= 4 and modbus.crc_ok(reply)

    @staticmethod
    def _repack(reply, ident):
        return modbus.frame(ident, reply[1:-2])

    # -- persistence ----------------------------------------------------------------------------------

    def state(self) -> dict:
        return {"slot": self.slot, "position": round(self.pos),
                "registers": {r.name: self.words[r.address] for r in STORED}}

    def restore(self, st: dict) -> None:
        regs = st.get("registers", {})
        if not isinstance(regs, dict):
            raise InvalidValue("registers is not an object")
        for name, value in regs.items():
            reg = REG.get(name)
            if reg is None or not reg.stored or not reg.writable:
                raise InvalidValue(f"unknown stored register {name!r}")
            if not isinstance(value, int) or not reg.allows(value):
                raise InvalidValue(f"{name}: {value!r} is out of range; allowed {reg.describe_range()}")
            self.words[reg.address] = value
        pos = st.get("position", 0)
        if not isinstance(pos, int) or not 0 <= pos <= self.POSITION_MAX:
            raise InvalidValue(f"position: {pos!r} is out of range; allowed 0..{self.POSITION_MAX}")
        self.pos = float(pos)
        self.power_on(0.0)


def _baud_of(code: int) -> int:
    return MAP.baud_codes.get(code, 57600)


def _code_of(baud: int) -> int:
    for code, rate in MAP.baud_codes.items():
        if rate == baud:
            return code
    raise InvalidValue(f"baud: {baud}; allowed {', '.join(str(v) for v in sorted(MAP.baud_codes.values()))}")


class ModbusActuatorBus(ir.ActuatorBus):
    """The simulated line with 17Lf actuators on it (see :class:`zkzap.sim.zap_actuators.ActuatorBus`
    for the line, the faults and the test interface)."""

    actuator_class = ModbusActuator

    @staticmethod
    def framer_class():
        return RtuFramer(any_function=True)     # an unknown function is answered "illegal function"
    state_format = STATE_FORMAT

    @staticmethod
    def _single(data) -> bool:
        return len(data) < 4 or modbus.crc_ok(data)

    def _addressed(self, pkt: bytes, listeners: list):
        if modbus.frame_kind(pkt, None) not in ("request",):
            return None                    # a reply or exception from someone else
        if pkt[0] == modbus.BROADCAST:
            return listeners
        return [a for a in listeners if a.ident == pkt[0]]

    def inject(self, ident, kind, value=None, count=None) -> None:
        if kind == "locked":
            targets = self._targets(ident)
            if not targets:
                raise InvalidValue(f"fault: no actuator with ID {ident} on the simulated bus")
            for a in targets:
                a.locked = True
            return
        super().inject(ident, kind, value, count)
        if kind == "overload":                # the force cut shows in hardware-error at once
            for a in self._targets(ident):
                a.update(a.t)

    def clear_faults(self, ident=None) -> None:
        for a in self._targets(ident):
            a.locked = False
        super().clear_faults(ident)


def parse_ids(text: str) -> list:
    """``1,2,5-8`` or ``ID@BAUD`` items, as the IR simulator's, with Modbus IDs 1..247."""
    pairs = ir.parse_ids(text)
    for ident, _ in pairs:
        if not 1 <= ident <= modbus.MAX_ID:
            raise InvalidValue(f"ids: {ident} is out of range; a Modbus actuator's ID is 1..247")
    return pairs


def build(ids, baud: int, *, state=None, echo=False, turnaround=ir.TURNAROUND, gap=0.0) -> ModbusActuatorBus:
    """A bus of 17Lf actuators ``ids`` (``[(id, baud or None)]``) at ``baud``, or the one the
    state file holds."""
    bus = ModbusActuatorBus([], state_path=state or None, echo=echo, turnaround=turnaround, gap=gap)
    if not (state and bus.load_state()):
        bus.actuators = [ModbusActuator(i, ident, b or baud) for i, (ident, b) in enumerate(ids)]
        if state:
            bus.save()
    return bus
