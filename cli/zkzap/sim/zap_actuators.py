"""A simulated mightyZAP bus: one or more 12Lf actuators on a half-duplex line.

Each actuator holds the full register map (:data:`zkzap.codec.zap.REGISTERS`) in a 256-byte
memory, answers exactly as its feedback-return mode says (0: Echo only; 1: Load Data and Echo;
2: every command; broadcast never), and models what a script can observe:

- goal-position moves present-position at goal-speed over model time (``moving`` = 1 meanwhile,
  present-motor-operating-rate and present-current meaningful), clamped to the stroke limits;
  force-on-off 0 stops the rod, a goal position turns the force back on (unless an alarm in
  alarm-shutdown holds it off);
- Send Data stages one write per actuator, Execution applies it; Symmetric Store; Factory Reset
  (option bit0 resets the ID, bit1 the baud rate) and Restart (both restart the actuator: it is
  deaf for :data:`BOOT_TIME`, volatile registers return to power-on values, a new baud rate
  takes effect);
- a host at another baud rate than the actuator's is not heard (pty and ``sim://`` transports
  pass the host's baud; a TCP client has none and always matches);
- a command is heard once its last byte has crossed the line (the request's own time on the
  wire at the host's baud rate); replies leave the actuator's turnaround after that
  (:data:`TURNAROUND` by default, ``turnaround=MS``; plus :data:`NV_WRITE_TIME` after a write to
  stored registers), take their real time on the wire (plus ``gap=MS`` between two bytes, like
  a device or USB adapter that trickles its bytes), and never overlap; two actuators answering
  at once collide (wired-AND of their bytes, like an open-drain line);
- stored (NV) registers and the rod position are kept in a JSON state file (``state=FILE``)
  across restarts of the simulator.

Faults, per actuator (``faults=`` option, ``zkzap sim zap --fault``, or :meth:`ActuatorBus.inject`),
written ``[ID:]KIND[=VALUE][/COUNT]`` (ID ``all`` or omitted: every actuator; COUNT: only the next
COUNT replies):

=============  ===========================================================================
overload       overload error (bit5): force cut (alarm-shutdown bit5) until restart
voltage[=V]    supply voltage V (default 6.0): error bit0 while outside the voltage limits
silent         never answers (aliases: no-reply, mute)
corrupt        replies with a wrong checksum (alias: checksum)
truncate[=N]   replies cut short by N bytes (default 2)
wrong-id[=ID]  replies carry another ID (default ID + 1)
delay=MS       replies MS model milliseconds late (default 20)
noise[=N]      N stray bytes (default 1) on the line before each reply (a line fault)
drop[=N]       N bytes (default 1) of each reply lost on the line, from its middle
twice          each reply sent twice (two replies where one was due)
stuck          the rod is blocked: ``moving`` stays 1 and the position does not change
echo           the adapter echoes the host's bytes back, like a half-duplex adapter (bus-wide)
=============  ===========================================================================
"""

from __future__ import annotations

import bisect
import json
import math
import os
import random
from collections import deque

from ..codec import zap
from ..errors import InvalidValue, unknown_name
from ..codec.framing import ZapFramer
from ..link.port import wire_time
from .base import parse_flag, parse_number

#: Actuator processing time before a reply starts (model seconds).
TURNAROUND = 0.002
#: Pause after a write to stored (NV) registers: replies and commands wait for the memory.
NV_WRITE_TIME = 0.005
#: After Restart / Factory Reset the actuator hears nothing for this long.
BOOT_TIME = 0.02
#: Rod speed at goal-speed 1023, in position units per model second (full stroke in ~0.4 s).
FULL_SPEED = 10000.0
#: A real 12Lf's identity, as logged from one by a community control app (the e-manual gives no
#: model number): model 41234 (0xA112), firmware-version 21 (which IR Robot's Arduino examples
#: print as raw x 0.1, "2.10"), present-temperature (undocumented, 0x93) 245.
MODEL_NUMBER = 0xA112
FIRMWARE_VERSION = 21
PRESENT_TEMPERATURE = 245
SUPPLY_VOLTAGE = 12.0

#: Values for registers the data map gives no default: a real 12Lf's where known (acceleration
#: 20, deceleration 64), else simulator choices, plausible for a 12Lf.
SIM_DEFAULTS = {
    "model-number": MODEL_NUMBER,
    "firmware-version": FIRMWARE_VERSION,
    "lowest-limit-voltage": 70,
    "highest-limit-voltage": 130,
    "start-compliance-margin": 7,
    "end-compliance-margin": 7,
    "calibration-short-stroke": 0,
    "calibration-long-stroke": 4095,
    "acceleration": 20,
    "deceleration": 64,
    "current-i-gain": 20,
    "current-p-gain": 30,
    "speed-d-gain": 0,
    "speed-i-gain": 10,
    "speed-p-gain": 40,
    "min-position-calibration": 0,
    "max-position-calibration": 0,
    "present-position": 0,
    "present-current": 0,
    "present-motor-operating-rate": 0,
    "present-voltage": 120,
    "goal-position": 0,
}

R = zap.REGISTER_BY_NAME
STORED = tuple(r for r in zap.REGISTERS if r.stored)
OVERLOAD_BIT = 0x20
VOLTAGE_BIT = 0x01
STATE_FORMAT = "zkzap-zap-bus/1"

FAULT_KINDS = {
    "overload": "overload", "voltage": "voltage", "silent": "silent", "no-reply": "silent",
    "noreply": "silent", "mute": "silent", "corrupt": "corrupt", "checksum": "corrupt",
    "truncate": "truncate", "truncated": "truncate", "wrong-id": "wrong-id", "delay": "delay",
    "stuck": "stuck", "echo": "echo", "locked": "locked", "noise": "noise", "drop": "drop", "twice": "twice",
}
FAULT_HELP = ("overload, voltage[=V], silent, corrupt, truncate[=N], wrong-id[=ID], delay=MS, stuck, "
              "echo, locked (Modbus), noise[=N], drop[=N], twice")
#: Faults that change replies (COUNT applies to them).
REPLY_FAULTS = ("silent", "corrupt", "truncate", "wrong-id", "delay", "drop", "noise", "twice")


class NoActuator(InvalidValue, KeyError):
    """No actuator with that ID on the simulated bus (an :class:`~zkzap.errors.InvalidValue`
    and a KeyError)."""

    __str__ = Exception.__str__


def baud_of(code: int) -> int:
    return zap.BAUD_CODES.get(code, 57600)


class Fault:
    __slots__ = ("kind", "value", "count")

    def __init__(self, kind, value=None, count=None):
        self.kind, self.value, self.count = kind, value, count

    def __repr__(self):
        return f"Fault({self.kind!r}, {self.value!r}, {self.count!r})"


def parse_fault(text: str):
    """``"[ID:]KIND[=VALUE][/COUNT]"`` -> ``(ident or None for all, kind, value, count)``.

    Raises ValueError with a one-line message naming what is wrong and what is allowed.
    """
    spec = text.strip()
    if not spec:
        raise InvalidValue("fault: empty; expected [ID:]KIND[=VALUE][/COUNT]")
    ident = None
    if ":" in spec:
        who, spec = spec.split(":", 1)
        who = who.strip().lower()
        if who not in ("all", "*", ""):
            try:
                ident = int(who, 0)
            except ValueError:
                raise InvalidValue(f"fault {text!r}: ID {who!r} is not a number; allowed 0..253 or all") from None
            if not 0 <= ident <= zap.MAX_ID:
                raise InvalidValue(f"fault {text!r}: ID {ident} is out of range; allowed 0..253 or all")
    count = None
    if "/" in spec:
        spec, cnt = spec.rsplit("/", 1)
        try:
            count = int(cnt)
        except ValueError:
            count = -1
        if count < 1:
            raise InvalidValue(f"fault {text!r}: COUNT {cnt!r} must be a positive integer")
    name, _, raw = spec.partition("=")
    kind = FAULT_KINDS.get(name.strip().lower())
    if kind is None:
        raise InvalidValue(f"fault {text!r}: unknown kind {name!r}; allowed {FAULT_HELP}")
    value = None
    if raw:
        try:
            value = parse_number(kind, raw) if kind in ("voltage", "delay") else int(raw, 0)
        except ValueError as e:
            if "finite" in str(e):
                raise InvalidValue(f"fault {text!r}: {e}") from None
            raise InvalidValue(f"fault {text!r}: value {raw!r} is not a number") from None
        if kind == "voltage" and not 0 <= value <= 25.5:
            raise InvalidValue(f"fault {text!r}: voltage {value} is out of range; allowed 0..25.5 V")
        if kind == "delay" and not 0 <= value <= 60000:
            raise InvalidValue(f"fault {text!r}: delay {value} is out of range; allowed 0..60000 ms")
        if kind in ("noise", "drop") and not 1 <= value <= 255:
            raise InvalidValue(f"fault {text!r}: {kind} {value} is out of range; allowed 1..255 bytes")
        if kind == "truncate" and not 1 <= value <= 255:
            raise InvalidValue(f"fault {text!r}: truncate {value} is out of range; allowed 1..255 bytes")
        if kind == "wrong-id" and not 0 <= value <= 254:
            raise InvalidValue(f"fault {text!r}: wrong-id {value} is out of range; allowed 0..254")
        if kind in ("overload", "silent", "corrupt", "stuck", "echo", "twice"):
            raise InvalidValue(f"fault {text!r}: {kind} takes no value")
    return ident, kind, value, count


def parse_ids(text: str):
    """``"1,2,5-8,3@115200"`` -> list of (id, baud or None). Duplicates are allowed (a real bus
    can hold two actuators with one ID; their replies collide)."""
    out = []
    for part in str(text).replace(" ", ",").split(","):
        part = part.strip()
        if not part:
            continue
        part, _, baud = part.partition("@")
        b = None
        if baud:
            try:
                b = int(baud)
            except ValueError:
                b = -1
            if b not in zap.BAUD_TO_CODE:
                raise InvalidValue(f"ids: baud {baud!r} in {part}@{baud}; allowed "
                                 f"{', '.join(str(v) for v in sorted(zap.BAUD_TO_CODE))}")
        lo, dash, hi = part.partition("-")
        try:
            first = int(lo, 0)
            last = int(hi, 0) if dash else first
        except ValueError:
            raise InvalidValue(f"ids: {part!r} is not an ID or range (like 1,2,5-8)") from None
        if not (0 <= first <= zap.MAX_ID and 0 <= last <= zap.MAX_ID) or last < first:
            raise InvalidValue(f"ids: {part!r} is out of range; allowed 0..253")
        out.extend((i, b) for i in range(first, last + 1))
    if not out:
        raise InvalidValue("ids: none given; expected a list like 1,2,5-8")
    return out


class Actuator:
    """One simulated 12Lf. ``slot`` is its place on the bus (stable across ID changes).

    The motion model speaks register names (goal-position, goal-speed, present-current, ...);
    another protocol family's actuator (:mod:`zkzap.sim.zap_modbus`) keeps its own control table
    behind :meth:`_peek`/:meth:`_poke` and its own scale (:attr:`POSITION_MAX`, :attr:`SPEED_MAX`)."""

    #: The highest position and the goal speed of full speed.
    POSITION_MAX = 4095
    SPEED_MAX = 1023

    def __init__(self, slot: int, ident: int = 0, baud: int = 57600):
        self.slot = slot
        self.mem = bytearray(256)
        for reg in zap.REGISTERS:
            default = SIM_DEFAULTS.get(reg.name, reg.default)
            self._poke(reg, default or 0)
        self._poke(R["id"], ident)
        self._poke(R["baud-rate"], zap.BAUD_TO_CODE[baud])
        self.mem[zap.UNDOCUMENTED_BY_NAME["present-temperature"].address] = PRESENT_TEMPERATURE
        self.baud = baud                  # the line speed in effect (baud-rate applies at restart)
        self.pos = 0.0                    # rod position (float, position units)
        self.t = 0.0                      # model time of the last update
        self.supply = SUPPLY_VOLTAGE
        self.overload = False
        self.stuck = False
        self.staged = None                # (address, data) from Send Data
        self.busy_until = 0.0
        self.tx_free = 0.0                # when its last reply has left (it sends one at a time)
        self.deaf_until = 0.0
        self.faults = {}                  # kind -> Fault (reply faults)
        self.nv_dirty = False             # stored registers changed since the last save
        self.turnaround = TURNAROUND      # processing time before a reply starts (model seconds)
        self.own_turnaround = None        # this actuator's own (None: the bus's)
        self.jitter = 0.0                 # up to this much more, at random, on every reply
        self.fast = False                 # behind a link that is not a UART at the baud rate (USB-CDC,
        #                                   a TCP bridge, a microcontroller): it hears a request as it
        #                                   is written and its reply takes no time on the wire
        self.power_on(0.0)

    # -- registers ----------------------------------------------------------------------------

    def _poke(self, reg, value):
        self.mem[reg.address:reg.address + reg.size] = int(value).to_bytes(reg.size, "little")

    def _peek(self, reg) -> int:
        return int.from_bytes(self.mem[reg.address:reg.address + reg.size], "little")

    def get(self, name) -> int:
        """A register's raw value (by name, address or Register), as a Load Data would see it now."""
        return self._peek(zap.register(name))

    def set(self, name, value) -> None:
        """Set a register directly (test set-up; no side effects, no NV pause)."""
        reg = zap.register(name)
        self._poke(reg, value)
        if reg.name == "baud-rate":
            self.baud = baud_of(value)
        if reg.name == "present-position":
            self.pos = float(value)

    @property
    def ident(self) -> int:
        return self.mem[R["id"].address]

    @property
    def return_mode(self) -> int:
        return self.mem[R["feedback-return-mode"].address]

    def error_byte(self) -> int:
        err = OVERLOAD_BIT if self.overload else 0
        volts = round(self.supply * 10)
        if not self._peek(R["lowest-limit-voltage"]) <= volts <= self._peek(R["highest-limit-voltage"]):
            err |= VOLTAGE_BIT
        return err

    def force_allowed(self) -> bool:
        return not (self.error_byte() & self._peek(R["alarm-shutdown"]))

    # -- life cycle ---------------------------------------------------------------------------

    def power_on(self, now: float) -> None:
        """Volatile registers to power-on values; the stored baud rate takes effect."""
        self.t = now
        self.overload = False
        self.staged = None
        self.baud = baud_of(self._peek(R["baud-rate"]))
        self._poke(R["force-on-off"], 1 if self.force_allowed() else 0)
        self._poke(R["led"], 0)
        self._poke(R["goal-position"], round(self.pos))
        self._poke(R["goal-speed"], self._peek(R["speed-limit"]))
        self._poke(R["goal-current"], self._peek(R["current-limit"]))
        self._refresh(False, 0.0)

    def factory_reset(self, option: int) -> None:
        keep_id, keep_baud = self._peek(R["id"]), self._peek(R["baud-rate"])
        for reg in STORED:
            self._poke(reg, SIM_DEFAULTS.get(reg.name, reg.default) or 0)
        if not option & 1:
            self._poke(R["id"], keep_id)
        if not option & 2:
            self._poke(R["baud-rate"], keep_baud)

    # -- motion -------------------------------------------------------------------------------

    def speed(self) -> int:
        """Effective speed 0..1023: goal speed within the speed and operating-rate limits."""
        return min(self._peek(R["goal-speed"]), self._peek(R["speed-limit"]),
                   self._peek(R["motor-operating-rate-limit"]))

    def _driving(self) -> bool:
        return self._peek(R["force-on-off"]) == 1 and round(self.pos) != self._peek(R["goal-position"]) \
            and self.speed() > 0

    def update(self, now: float) -> None:
        """Advance the rod to model time ``now`` and refresh the present-* registers."""
        dt = max(0.0, now - self.t)
        self.t = max(self.t, now)
        driving = self._driving()
        velocity = 0.0
        if driving and not self.stuck:
            goal = self._peek(R["goal-position"])
            velocity = FULL_SPEED * self.speed() / self.SPEED_MAX
            gap = goal - self.pos
            step = velocity * dt
            if abs(gap) <= step:
                self.pos = float(goal)
                driving = False
            else:
                self.pos += math.copysign(step, gap)
        self._refresh(driving, velocity)

    def _refresh(self, driving: bool, velocity: float) -> None:
        self._poke(R["present-position"], max(0, min(self.POSITION_MAX, round(self.pos))))
        self._poke(R["moving"], 1 if driving else 0)
        duty = self.speed() if driving else 0
        if duty and self._peek(R["goal-position"]) > self.pos:
            duty += 1024
        self._poke(R["present-motor-operating-rate"], min(duty, 2047))
        limit = self._peek(R["goal-current"])
        if driving and self.stuck:
            current = limit
        elif driving:
            current = min(limit, 120 + round(300 * velocity / FULL_SPEED))
        elif self._peek(R["force-on-off"]):
            current = min(limit, 15)
        else:
            current = 0
        self._poke(R["present-current"], current)
        self._poke(R["present-voltage"], max(0, min(255, round(self.supply * 10))))

    # -- writes -------------------------------------------------------------------------------

    def write(self, address: int, data: bytes) -> bool:
        """Write ``data`` at ``address`` as Store Data does; returns True when a stored (NV)
        register was written. Bytes of read-only or unmapped addresses are ignored, values out
        of range leave the register unchanged, goal-position is clamped to the stroke limits."""
        touched = {}
        for i in range(len(data)):
            addr = address + i
            if addr > 0xFF:
                break
            reg = _REG_AT.get(addr)
            if reg is None or not reg.writable:
                continue
            if reg.name not in touched:
                touched[reg.name] = (reg, self._peek(reg))
            self.mem[addr] = data[i]
        stored = False
        for reg, old in touched.values():
            new = self._peek(reg)
            if not self._accept(reg, new):
                self._poke(reg, old)
                continue
            stored = stored or bool(reg.stored)
            self._effect(reg, old, new)
        return stored

    def _accept(self, reg, value) -> bool:
        if reg.choices is not None:
            return value in reg.choices
        if reg.name == "id":
            return value <= zap.MAX_ID
        return reg.lo <= value <= reg.hi

    def _effect(self, reg, old, new):
        name = reg.name
        if name == "goal-position":
            lo, hi = self._peek(R["short-stroke-limit"]), self._peek(R["long-stroke-limit"])
            lo, hi = min(lo, hi), max(lo, hi)
            self._poke(reg, max(lo, min(hi, new)))
            if self.force_allowed():
                self._poke(R["force-on-off"], 1)
        elif name == "force-on-off" and new == 1 and not self.force_allowed():
            self._poke(reg, 0)

    # -- instructions -------------------------------------------------------------------------

    def handle(self, pkt: bytes, now: float):
        """Process one command packet addressed to this actuator (or broadcast).

        Returns ``(start_time, reply_bytes, baud)`` or None; may flag the actuator for restart.
        """
        if now < self.deaf_until:
            return None
        start = max(now, self.busy_until)
        self.update(start)
        ident, code, params = pkt[3], pkt[5], bytes(pkt[6:-1])
        ins = zap.INSTRUCTION_BY_CODE.get(code)
        if ins is None:
            return None
        answer = ins.answered(self.return_mode, ident)
        out = b""
        nv = False
        restart = False
        if code == zap.ECHO:
            if params:
                return None
        elif code == zap.LOAD_DATA:
            if len(params) != 2:
                return None
            address, length = params
            length = min(length, 256 - address, zap.MAX_SIZE - 2)
            out = bytes(self.mem[address:address + length])
        elif code == zap.STORE_DATA:
            if len(params) < 2:
                return None
            nv = self.write(params[0], params[1:])
        elif code == zap.SEND_DATA:
            if len(params) < 2:
                return None
            self.staged = (params[0], params[1:])
        elif code == zap.EXECUTION:
            if params:
                return None
            if self.staged is not None:
                nv = self.write(*self.staged)
                self.staged = None
        elif code == zap.FACTORY_RESET:
            if len(params) != 1:
                return None
            self.factory_reset(params[0])
            nv = restart = True
        elif code == zap.RESTART:
            if params:
                return None
            restart = True
        elif code == zap.SYMMETRIC_STORE:
            cmd = zap.Command(pkt)
            if cmd.targets is None:
                return None
            for target, data in cmd.targets:
                if target == self.ident:
                    nv = self.write(cmd.address, data)
        done = start + (NV_WRITE_TIME if nv else 0.0)
        self.busy_until = done
        self.nv_dirty = self.nv_dirty or nv
        reply = zap.packet(ident, self.error_byte(), out) if answer else None
        baud = self.baud
        if restart:
            self.deaf_until = done + BOOT_TIME
            self.update(done)
            self.power_on(done)
            self.t = done
        if reply is None:
            return None
        return done + self.turnaround, reply, baud

    @staticmethod
    def _sender(reply) -> int:
        """The ID a reply carries."""
        return reply[3]

    #: Where a reply carries its ID.
    ID_AT = 3

    @staticmethod
    def _whole(reply) -> bool:
        """Whether ``reply`` is a whole packet (no fault cut it short)."""
        return len(reply) >= 7 and reply[4] + 5 == len(reply)

    @staticmethod
    def _repack(reply, ident):
        """``reply`` as if ``ident`` had sent it (the wrong-id fault)."""
        return zap.packet(ident, reply[5], reply[6:-1])

    def apply_faults(self, t, reply):
        """Reply faults: returns (t, reply) or None (silent)."""
        for kind in REPLY_FAULTS:
            f = self.faults.get(kind)
            if f is None:
                continue
            if f.count is not None:
                f.count -= 1
                if f.count <= 0:
                    del self.faults[kind]
            if kind == "silent":
                return None
            if kind == "delay":
                t += (20.0 if f.value is None else f.value) / 1000.0
            elif kind == "wrong-id":
                if len(reply) <= self.ID_AT:
                    continue               # cut short before its ID (truncate came first)
                other = (self._sender(reply) + 1) % 254 if f.value is None else int(f.value)
                # a reply cut short keeps its length: the ID byte changed, its checksum no more
                reply = self._repack(reply, other) if self._whole(reply) \
                    else reply[:self.ID_AT] + bytes((other,)) + reply[self.ID_AT + 1:]
            elif kind == "corrupt":
                reply = reply[:-1] + bytes(((reply[-1] ^ 0x5A),))
            elif kind == "truncate":
                cut = 2 if f.value is None else int(f.value)
                reply = reply[:max(0, len(reply) - cut)]
            elif kind == "drop":
                cut = 1 if f.value is None else int(f.value)
                mid = max(3, len(reply) // 2)
                reply = reply[:mid] + reply[mid + cut:]
            elif kind == "noise":
                reply = bytes([0x55] * (1 if f.value is None else int(f.value))) + reply
            elif kind == "twice":
                reply = reply + reply
        return t, reply

    # -- persistence --------------------------------------------------------------------------

    def state(self) -> dict:
        return {"slot": self.slot, "position": round(self.pos),
                "registers": {r.name: self._peek(r) for r in STORED}}

    def restore(self, st: dict) -> None:
        regs = st.get("registers", {})
        if not isinstance(regs, dict):
            raise InvalidValue("registers is not an object")
        for name, value in regs.items():
            reg = R.get(name)
            if reg is None or not reg.stored:
                raise InvalidValue(f"unknown stored register {name!r}")
            if not isinstance(value, int) or not self._accept(reg, value):
                raise InvalidValue(f"{name}: {value!r} is out of range; allowed {reg.describe_range()}")
            self._poke(reg, value)
        pos = st.get("position", 0)
        if not isinstance(pos, int) or not 0 <= pos <= self.POSITION_MAX:
            raise InvalidValue(f"position: {pos!r} is out of range; allowed 0..{self.POSITION_MAX}")
        self.pos = float(pos)
        self.power_on(0.0)


_REG_AT = {}
for _r in zap.REGISTERS:
    for _a in range(_r.address, _r.address + _r.size):
        _REG_AT[_a] = _r


#: A reply of an actuator behind a link that is not a UART takes this share of its wire time.
FAST_SHARE = 0.02


class Heard:
    """One command an actuator heard (the simulator's ground truth): ``t`` (model time),
    ``slot`` (which actuator, stable across ID changes), ``ident`` (its ID when it heard it),
    ``packet``, ``reply`` (what it answered, before any fault; None: no reply), ``sent`` (what
    went on the line after the faults; None: nothing) and ``at`` (when that reply starts)."""

    __slots__ = ("t", "slot", "ident", "packet", "reply", "sent", "at")

    def __init__(self, t, slot, ident, packet, reply, sent, at):
        self.t, self.slot, self.ident, self.packet, self.reply, self.sent, self.at = \
            t, slot, ident, packet, reply, sent, at

    def __repr__(self):
        return (f"Heard(t={self.t:.6f}, slot={self.slot}, id={self.ident}, {self.packet.hex(' ')}, "
                f"reply={self.reply.hex(' ') if self.reply else None})")


class _Byte:
    """One byte on the line: its wire time, value, who sent it, when the host's UART delivers
    it, and the line speed it was sent at."""

    __slots__ = ("start", "end", "value", "host", "reply", "due", "baud", "ids")

    def __init__(self, start, end, value, due, baud, host=False, reply=False, ids=()):
        self.start, self.end, self.value, self.due, self.baud = start, end, value, due, baud
        self.host, self.reply, self.ids = host, reply, set(ids)


class ActuatorBus:
    """The bus: actuators, the line between them and the host, fault injection, persistence.

    For tests (``port.device`` behind ``sim://zap``): :meth:`actuator`, :meth:`inject`,
    :meth:`clear_faults`, the ``echo`` attribute (adapter echo), ``received`` (the last
    packets the actuators heard) and ``collisions`` (every time two transmissions met on the
    line: ``{"t", "kind", "ids"}``, kind ``host`` when the host transmitted while an actuator
    was replying, ``actuators`` when two actuators replied at once); ``on_collision`` is called
    with each.
    """

    #: The protocol family's actuator, framer and state-file format.
    actuator_class = Actuator
    framer_class = ZapFramer
    state_format = STATE_FORMAT

    def __init__(self, actuators, *, state_path=None, echo=False, turnaround=TURNAROUND, gap=0.0):
        self.actuators = list(actuators)
        self.state_path = state_path
        self.echo = echo
        self.turnaround = turnaround      # every actuator's reply turnaround (model seconds)
        self.gap = gap                    # pause between two reply bytes (model seconds)
        # model seconds per real second (the simulator's speed): a byte takes its real time on
        # the wire whatever the speed, so in model time it takes this many times longer; a reply
        # can never come sooner than the line can carry it
        self.wire_scale = 1.0
        self._rx_free = 0.0               # when the host's bytes written so far have crossed the line
        self.restored = False
        self.received = deque(maxlen=1000)
        self.collisions = []
        self.on_collision = None
        self._framers = {}
        self._line = []                   # _Byte not yet delivered to the host, by due time
        #: The ground truth (None until :meth:`record_truth`): a :class:`Heard` for every command
        #: an actuator heard, with what it answered.
        self.truth = None
        self._rng = random.Random(0)      # reply jitter and fault bytes: the same on every run

    # -- Python API for tests -----------------------------------------------------------------

    def record_truth(self, seed=0) -> list:
        """Keep the ground truth of the line from now on (:attr:`truth`, a list of
        :class:`Heard`), and seed the randomness of jitter and fault bytes with ``seed``."""
        self.truth = []
        self._rng = random.Random(seed)
        return self.truth

    def actuator(self, ident: int) -> Actuator:
        """The first actuator whose ID is ``ident`` (:class:`NoActuator`, a KeyError, if none)."""
        for a in self.actuators:
            if a.ident == ident:
                return a
        raise NoActuator(f"no actuator with ID {ident} on the simulated bus", ident=ident)

    def _targets(self, ident):
        if ident is None or ident == "all":
            return list(self.actuators)
        return [a for a in self.actuators if a.ident == ident]

    def inject(self, ident, kind, value=None, count=None) -> None:
        """Inject a fault on actuator ``ident`` (``None``/``"all"``: every actuator); see the
        module documentation for kinds. ``count`` limits a reply fault to the next N replies."""
        kind = FAULT_KINDS.get(kind, kind)
        if kind not in set(FAULT_KINDS.values()):
            raise InvalidValue(f"fault: unknown kind {kind!r}; allowed {FAULT_HELP}")
        if kind == "echo":
            self.echo = True
            return
        if kind == "locked":
            raise InvalidValue("fault: locked is a Modbus actuator's (parameters locked: exception 6); "
                               "the IR protocol has no such reply")
        targets = self._targets(ident)
        if not targets:
            raise InvalidValue(f"fault: no actuator with ID {ident} on the simulated bus")
        for a in targets:
            if kind == "overload":
                a.overload = True
                if not a.force_allowed():
                    a.update(a.t)
                    a._poke(R["force-on-off"], 0)
            elif kind == "voltage":
                a.supply = 6.0 if value is None else float(value)
                if not a.force_allowed():
                    a._poke(R["force-on-off"], 0)
            elif kind == "stuck":
                a.stuck = True
            else:
                a.faults[kind] = Fault(kind, value, count)

    def inject_text(self, text: str) -> None:
        ident, kind, value, count = parse_fault(text)
        self.inject(ident, kind, value, count)

    def clear_faults(self, ident=None) -> None:
        """Remove every injected fault (overload stays latched until restart, as on the real one)."""
        for a in self._targets(ident):
            a.faults.clear()
            a.stuck = False
            a.supply = SUPPLY_VOLTAGE
        if ident is None:
            self.echo = False

    # -- Device interface ---------------------------------------------------------------------

    def receive(self, data: bytes, now: float, baud=None) -> None:
        """The host's bytes, written at ``now`` at ``baud``: they take their time on the line, and
        each command is heard when its own last byte is in (two packets in one write are two
        commands, the first heard while the second is still on the wire); a byte that meets an
        actuator's reply on the line garbles both (wired-AND)."""
        if not data:
            return
        line = baud or (self.actuators[0].baud if self.actuators else 57600)
        byte = wire_time(1, line) * self.wire_scale
        start = max(now, self._rx_free)
        self._rx_free = start + byte * len(data)
        framer = self._framers.get(baud)
        if framer is None:
            framer = self._framers[baud] = self.framer_class()
        if self._single(data):
            self._hear(data, 0, start, byte, baud, framer)      # one packet (or part of one)
            return
        # several packets (or bytes besides one): each is heard when its own last byte is in,
        # and a reply to an earlier one may meet the later bytes on the line
        for i in range(len(data)):
            self._hear(data[i:i + 1], i, start, byte, baud, framer)

    def _hear(self, data, offset, start, byte, baud, framer) -> None:
        """Bytes ``offset`` .. of one write (started at ``start``) on the line, then the commands
        they complete, heard at the end of their last byte."""
        heard = bytearray(data)
        met = set()
        echoed = []
        for k, value in enumerate(data):
            i = offset + k
            b = _Byte(start + i * byte, start + (i + 1) * byte, value, start + (offset + len(data)) * byte, baud,
                      host=True)
            hit = self._meets(b.start, b.end)
            for x in hit:
                heard[k] &= x.value
                x.value &= value
                x.host = True
                met |= x.ids
            if not hit and self.echo:
                echoed.append((k, b))
        if met:
            self._collided(start + offset * byte, "host", met)
        for k, b in echoed:               # the adapter's echo: what crossed the line
            b.value = heard[k]
            self._queue(b)
        arrived = start + (offset + len(data)) * byte
        for pkt in framer.feed(bytes(heard)):
            self.received.append(bytes(pkt))
            self._dispatch(bytes(pkt), arrived, baud)

    def _collided(self, t, kind, ids) -> None:
        event = {"t": round(t, 6), "kind": kind, "ids": sorted(ids)}
        self.collisions.append(event)
        if self.on_collision is not None:
            self.on_collision(event)

    @staticmethod
    def _single(data) -> bool:
        """Whether one write's bytes are one packet (or part of one), heard as a whole."""
        return len(data) >= 7 and data[4] + 5 == len(data) or len(data) < 7

    def _addressed(self, pkt: bytes, listeners: list):
        """The actuators among ``listeners`` a packet addresses (None: not a command)."""
        ident, code = pkt[3], pkt[5]
        if not zap.is_command(code):
            return None                    # feedback from someone else: not for actuators
        if ident == zap.BROADCAST:
            return listeners
        return [a for a in listeners if a.ident == ident]

    def _dispatch(self, pkt: bytes, now: float, baud) -> None:
        targets = self._addressed(pkt, [a for a in self.actuators if baud is None or a.baud == baud])
        if targets is None:
            return
        replies = []
        stored = False
        for a in targets:
            a.turnaround = self.turnaround if a.own_turnaround is None else a.own_turnaround
            if a.jitter:
                a.turnaround += self._rng.random() * a.jitter
            heard = now - (len(pkt) - 1) * wire_time(1, baud or a.baud) * self.wire_scale if a.fast else now
            was = a.ident
            r = a.handle(pkt, heard)
            if a.nv_dirty:
                stored = True
                a.nv_dirty = False
            faulted = None
            if r is not None:
                faulted = a.apply_faults(r[0], r[1])
                if faulted is not None and faulted[1]:
                    replies.append((faulted[0], faulted[1], r[2], a))
            if self.truth is not None:
                self.truth.append(Heard(heard, a.slot, was, bytes(pkt), r[1] if r is not None else None,
                                        faulted[1] if faulted is not None else None,
                                        faulted[0] if faulted is not None else None))
        if stored:
            self.save()
        replies.sort(key=lambda r: r[0])
        starts = []
        for t, data, rbaud, a in replies:
            byte = wire_time(1, rbaud) * self.wire_scale * (FAST_SHARE if a.fast else 1.0)
            start = max(t, a.tx_free)     # one actuator sends one reply at a time
            # two transmitters are never in step: a reply that starts with another is a byte behind
            if any(abs(start - s) < byte for s in starts):
                start = max(starts) + byte
            starts.append(start)
            self._send(start, data, rbaud, a.ident, byte)
            a.tx_free = start + len(data) * (byte + self.gap)

    def _send(self, start, data, baud, ident, byte=None) -> None:
        """An actuator's reply on the line from ``start``: the host's UART delivers its first
        byte when that has crossed, the rest when the reply has (a receive FIFO); with ``gap``
        every byte on its own. A byte that meets another reply's garbles both."""
        if byte is None:
            byte = wire_time(1, baud) * self.wire_scale
        step = byte + self.gap
        n = len(data)
        last_end = start + (n - 1) * step + byte
        met = set()
        for i, value in enumerate(data):
            b_start = start + i * step
            b_end = b_start + byte
            due = b_end if (self.gap > 0 or i == 0) else last_end
            hit = self._meets(b_start, b_end)
            if hit:
                for x in hit:
                    x.value &= value
                    met |= x.ids - {ident}
                    x.ids.add(ident)
                continue
            self._queue(_Byte(b_start, b_end, value, due, baud, reply=True, ids=(ident,)))
        if met:
            self._collided(start, "actuators", met | {ident})

    def _meets(self, start, end) -> list:
        """The reply bytes on the line between ``start`` and ``end`` (by more than a hair)."""
        eps = (end - start) * 0.05
        return [x for x in self._line if x.reply and x.end > start + eps and x.start < end - eps]

    def _queue(self, b) -> None:
        keys = [x.due for x in self._line]
        self._line.insert(bisect.bisect_right(keys, b.due), b)

    def poll(self, now: float) -> bytes:
        return self.poll_line(now, None)

    def poll_line(self, now: float, baud=None) -> bytes:
        """What a host listening at ``baud`` hears by ``now``: replies sent at another baud rate
        (the host switched after asking) are lost on the line, not delivered late and clean."""
        line = self._line
        if not line or line[0].due > now:
            return b""
        out = bytearray()
        while line and line[0].due <= now:
            b = line.pop(0)
            if baud is None or b.baud is None or b.baud == baud:
                out.append(b.value)
        return bytes(out)

    def next_wakeup(self, now: float):
        return self._line[0].due if self._line else None

    def close(self) -> None:
        for a in self.actuators:
            a.update(a.t)
        self.save()

    # -- persistence --------------------------------------------------------------------------

    def save(self) -> None:
        """Write the stored registers and rod positions to the state file, whole
        (:func:`zkzap.outfile.write_whole`: atomically, keeping the file's mode)."""
        if not self.state_path:
            return
        doc = {"format": self.state_format, "actuators": [a.state() for a in self.actuators]}
        from ..outfile import write_whole

        write_whole(self.state_path, json.dumps(doc, indent=1) + "\n", what="state")

    def load_state(self) -> bool:
        """Restore actuators from the state file; False when the file does not exist."""
        from ..api.documents import read
        from ..errors import UsageError

        path = self.state_path
        if os.path.exists(path) and not os.path.isfile(path):
            raise InvalidValue(f"state {path}: not a regular file; a state file is read and rewritten whole")
        if not os.path.exists(path):
            return False
        try:
            doc, _ = read(path, "state")
        except UsageError as e:            # unreadable, not UTF-8, not JSON: FILE:LINE: what
            raise InvalidValue(str(e) if str(e).startswith("state: ") else f"state: {e}") from None
        if not isinstance(doc, dict) or doc.get("format") != self.state_format or \
                not isinstance(doc.get("actuators"), list) or not doc["actuators"]:
            raise InvalidValue(f"state {path}: not a zkzap actuator-bus state file (format {self.state_format})")
        actuators = []
        for i, st in enumerate(doc["actuators"]):
            a = self.actuator_class(i)
            try:
                a.restore(st)
            except (ValueError, TypeError, AttributeError) as e:
                raise InvalidValue(f"state {path}: actuator {i}: {e}") from None
            actuators.append(a)
        self.actuators = actuators
        self.restored = True
        return True


def _millis(key, value, top=1000.0) -> float:
    """A time option in milliseconds (a finite number 0..``top``) -> seconds."""
    try:
        ms = float(value)
    except (TypeError, ValueError):
        raise InvalidValue(f"{key}: {value!r} is not a number of milliseconds") from None
    if not (math.isfinite(ms) and 0 <= ms <= top):
        raise InvalidValue(f"{key}: {value!r} is out of range; allowed 0..{top:g} ms")
    return ms / 1000.0


def from_options(ids=None, state=None, baud="57600", echo="0", faults="", return_mode=None,
                 voltage=None, turnaround=None, gap=None, protocol="ir", **unknown) -> ActuatorBus:
    """Build a bus from string options (a ``sim://zap?...`` query or ``zkzap sim zap``).

    ``ids``: ``1,2,5-8`` (``ID@BAUD`` for one actuator at another baud rate); ``baud``: the
    others' baud rate; ``return_mode``: every actuator's feedback-return-mode; ``echo=1``: the
    adapter echoes; ``faults``: comma-separated ``[ID:]KIND[=VALUE][/COUNT]``; ``voltage``: the
    supply voltage; ``turnaround``: milliseconds from a command's last byte to the reply's first
    (default 2); ``gap``: milliseconds between two reply bytes (default 0); ``state``: a JSON
    file keeping stored registers across runs (when it exists
    it defines the bus and ``ids``/``baud``/``return_mode`` are not applied); ``protocol``:
    ``ir`` (12Lf actuators, IDs 0..253, default 0) or ``modbus`` (17Lf actuators,
    :mod:`zkzap.sim.zap_modbus`: IDs 1..247, default 1; no return mode).
    """
    allowed = ("ids", "state", "baud", "echo", "faults", "return_mode", "voltage", "turnaround", "gap", "speed",
               "protocol")
    if len(unknown) == 1:
        raise unknown_name("zap simulator", next(iter(unknown)), allowed, noun="option")
    if unknown:
        raise InvalidValue(f"unknown options {', '.join(sorted(unknown))}; allowed {', '.join(allowed)}")
    try:
        line = int(baud)
    except ValueError:
        line = -1
    if line not in zap.BAUD_TO_CODE:
        raise InvalidValue(f"baud: {baud!r}; allowed {', '.join(str(v) for v in sorted(zap.BAUD_TO_CODE))}")
    cls = ActuatorBus
    if protocol not in (None, "", "ir"):
        if protocol != "modbus":
            raise InvalidValue(f"protocol: {protocol!r}; allowed ir, modbus")
        if return_mode not in (None, ""):
            raise InvalidValue("return_mode: a Modbus actuator has no feedback-return-mode (it answers "
                               "every unicast request)")
        from .zap_modbus import ModbusActuatorBus as cls, parse_ids as modbus_ids
    if ids is None:
        ids = "0" if cls is ActuatorBus else "1"
    pairs = parse_ids(ids) if cls is ActuatorBus else modbus_ids(ids)
    bus = cls([], state_path=state or None, echo=parse_flag("echo", echo),
                      turnaround=TURNAROUND if turnaround in (None, "") else _millis("turnaround", turnaround),
                      gap=0.0 if gap in (None, "") else _millis("gap", gap, 100.0))
    if not (state and bus.load_state()):
        bus.actuators = [bus.actuator_class(i, ident, b or line) for i, (ident, b) in enumerate(pairs)]
        if return_mode not in (None, ""):
            if str(return_mode) not in ("0", "1", "2"):
                raise InvalidValue(f"return_mode: {return_mode!r}; allowed 0, 1, 2")
            for a in bus.actuators:
                a.set("feedback-return-mode", int(return_mode))
        if state:
            from ..errors import ZkzapError

            parent = os.path.dirname(os.path.abspath(os.path.realpath(state)))
            if not os.path.isdir(parent):
                raise InvalidValue(f"state {state}: cannot write: no such directory (no directory {parent})")
            try:
                bus.save()
            except (OSError, ZkzapError) as e:
                raise InvalidValue(f"state {state}: cannot write: {getattr(e, 'strerror', None) or e}") from None
    if voltage not in (None, ""):
        bus.inject(None, "voltage", parse_number("voltage", voltage, 0, 25.5))
    for text in str(faults or "").split(","):
        if text.strip():
            bus.inject_text(text)
    return bus
