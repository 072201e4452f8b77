"""What timed motion (:mod:`zkzap.api.motion`, :mod:`zkzap.api.cycle`) asks of a bus's
protocol family: the frames of a step, how long they hold the line, the log read, the stop.

:func:`wire_for` gives an :class:`IrWire` (the 12Lf's IR protocol) or a :class:`ModbusWire`
(Modbus RTU, the 17Lf's map or a user's), on a register map; :func:`wire_of` the one of an open
link. The procedures ask these questions only, never the packets of one protocol:

- **A step's frames** (:meth:`IrWire.step_frames`): on IR one Symmetric Store to broadcast per
  register (never answered), goal-current first, then goal-speed, then goal-position; on Modbus
  RTU, which has no multi-actuator write, one Write Multiple Registers per actuator of its
  adjacent goal-speed and goal-current, then one per actuator of goal-position, each answered
  (so each goal is confirmed).
- **Their time on the line** (:meth:`IrWire.frame_time`): the frame's bytes at 10 bits a byte;
  on Modbus RTU also the 3.5-character silence before it, the reply's bytes and the actuator's
  turnaround (the next frame waits for the reply).
- **A log read** (:meth:`IrWire.read_sample`): on IR one Load Data of present-position ..
  present-voltage, whose reply carries the error bits; on Modbus RTU the map's runs of
  hardware-error, present-position, present-current and present-voltage (Read Holding
  Registers; the 17Lf's table has gaps between them), the error bits from hardware-error. A
  :class:`Sample` is the same on both: position, current (mA), voltage (V where the map gives
  the unit; the raw value always), error names.
- **Stopping**: goal-position := present position, written to every actuator (on Modbus RTU
  one frame each, every one tried even when another fails), or force off.

Nothing here imports click or rich.
"""

from __future__ import annotations

from ..codec import zap
from ..errors import ZkzapError
from ..link.port import wire_time
from ..link.zap_timing import FLOOR as TURNAROUND

#: The registers a log read asks for.
LOG_NAMES = ("present-position", "present-current", "present-voltage")
#: Bytes of a Load Data command and of an IR reply without data.
LOAD_BYTES, REPLY_BYTES = 9, 7


class Sample:
    """One log read of one actuator: ``position``, ``current`` (mA), ``voltage_v`` (V; None
    where the map gives present-voltage no unit in volts), ``voltage_raw`` (the register's
    value), ``errors`` (error bit names), ``error`` (whether any is set), ``reply`` (the last
    reply)."""

    __slots__ = ("position", "current", "voltage_v", "voltage_raw", "errors", "error", "reply")

    def __init__(self, position=None, current=None, voltage_v=None, voltage_raw=None, errors=(), reply=None):
        self.position, self.current, self.voltage_v, self.voltage_raw = position, current, voltage_v, voltage_raw
        self.errors = list(errors)
        self.error = bool(self.errors)
        self.reply = reply


def _volts(reg, raw):
    if reg is None or raw is None or reg.unit != "V":
        return None
    return round(raw * reg.scale, 1)


class IrWire:
    """The IR protocol's answers (the 12Lf's map, or ``regmap``)."""

    protocol = "ir"
    #: Extra columns of a log row and a cycle record on this protocol.
    log_columns: tuple = ()

    def __init__(self, regmap=None):
        self.map = regmap if regmap is not None else zap.MAP

    def reg(self, name):
        return self.map.register(name)

    @property
    def position(self):
        return self.reg("goal-position")

    @property
    def speed(self):
        return self.reg("goal-speed")

    @property
    def current(self):
        return self.reg("goal-current")

    # -- a step ----------------------------------------------------------------------------------

    def step_frames(self, goals, speeds=None, currents=None) -> list:
        """The frames of one step ({ID: raw} each), in sending order."""
        frames = []
        for name, values in (("goal-current", currents), ("goal-speed", speeds), ("goal-position", goals)):
            if values:
                frames += zap.symmetric_store(self.reg(name), sorted(values.items()))
        return frames

    def frame_time(self, frame: bytes, baud: int, stop_bits: int = 1) -> float:
        """Seconds ``frame`` holds the line (a broadcast: its own bytes)."""
        return wire_time(len(frame), baud, stop_bits)

    def describe(self, frame: bytes) -> str:
        return zap.Command(frame).describe()

    def send(self, link, frame: bytes) -> None:
        link.command(frame)

    # -- reads -----------------------------------------------------------------------------------

    def _log_block(self):
        first = self.reg("present-position")
        last = self.reg("present-voltage")
        return first.address, last.address + last.size - first.address

    def reads(self) -> list:
        """``[(data_len, request + reply bytes)]`` of one log read's transactions."""
        _, length = self._log_block()
        return [(length, LOAD_BYTES + REPLY_BYTES + length)]

    def read_cost(self, link, ident, latency: float) -> float:
        """Seconds one log read of ``ident`` holds the line: the wire, and ``latency`` a reply."""
        return sum(link.wire(n) + latency for _, n in self.reads())

    def read_sample(self, link, ident, *, window=None, optional=False, retries=None):
        """One log read (:class:`Sample`), or None where an ``optional`` read got no reply."""
        address, length = self._log_block()
        kw = {"check": False}
        if retries is not None:
            kw["retries"] = retries
        if window is not None:
            kw["window"] = window
        if optional:
            kw["optional"] = True
        reply = link.load(ident, address, length, **kw)
        if reply is None:
            return None
        v = {reg.name: raw for reg, raw in zap._register_values(address, reply.data)}
        volts = self.map.by_name.get("present-voltage")
        raw = v.get("present-voltage")
        return Sample(v.get("present-position"), v.get("present-current"), _volts(volts, raw), raw, reply.errors,
                      reply)

    def read_margin(self, link, ident) -> int:
        """The actuator's end-compliance-margin (its error bits are the first log read's to report)."""
        reg = self.reg("end-compliance-margin")
        return link.load(ident, reg.address, reg.size, check=False).value

    def read_present(self, link, ident) -> int:
        return link.read(ident, self.reg("present-position"))

    # -- stopping --------------------------------------------------------------------------------

    def write_all(self, link, name, values) -> list:
        """Write register ``name`` of every actuator of ``values`` ({ID: raw}); returns the IDs
        whose write failed (none on IR: a broadcast is never answered)."""
        if values:
            link.symmetric_store(self.reg(name), sorted(values.items()))
        return []


class ModbusWire(IrWire):
    """Modbus RTU's answers (the 17Lf's map, or ``regmap``)."""

    protocol = "modbus"
    log_columns = ("voltage_raw",)
    #: Bytes of a Write Multiple Registers reply and of a read request, and of a read reply besides its data.
    WRITE_REPLY, READ_REQUEST, READ_REPLY = 8, 8, 5

    def __init__(self, regmap=None):
        if regmap is None:
            from ..codec.regmap import default_map

            regmap = default_map("modbus")
        super().__init__(regmap)

    def step_frames(self, goals, speeds=None, currents=None) -> list:
        from ..codec import modbus

        frames = []
        for ident in sorted(set(speeds or ()) | set(currents or ())):
            values = {}
            if ident in (speeds or {}):
                values["goal-speed"] = speeds[ident]
            if ident in (currents or {}):
                values["goal-current"] = currents[ident]
            frames += modbus.write_frames(ident, values, self.map)
        if goals:
            frames += modbus.sync_frames("goal-position", sorted(goals.items()), self.map)
        return frames

    def frame_time(self, frame: bytes, baud: int, stop_bits: int = 1) -> float:
        from ..codec import modbus

        if frame[0] == modbus.BROADCAST:
            return modbus.silence(baud) + wire_time(len(frame), baud, stop_bits)
        return (modbus.silence(baud) + wire_time(len(frame) + self.WRITE_REPLY, baud, stop_bits)
                + 2 * TURNAROUND)     # the actuator's turnaround, and the host's before the next frame

    def describe(self, frame: bytes) -> str:
        from ..codec import modbus

        return modbus.Request(frame).describe(self.map)

    def _runs(self):
        from .watch import plan_reads

        regs = [self.map.by_name[n] for n in ("hardware-error",) + LOG_NAMES if n in self.map.by_name]
        return [(address, count) for address, count, _ in plan_reads(regs, regmap=self.map)]

    def reads(self) -> list:
        return [(1 + 2 * count, self.READ_REQUEST + self.READ_REPLY + 2 * count) for _, count in self._runs()]

    def read_cost(self, link, ident, latency: float) -> float:
        from ..codec import modbus

        return super().read_cost(link, ident, latency) + len(self.reads()) * modbus.silence(link.baud)

    def read_sample(self, link, ident, *, window=None, optional=False, retries=None):
        """The map's runs of hardware-error .. present-voltage, one Read Holding Registers each;
        ``window``: the whole read's (shared by its transactions); None where an ``optional``
        read got no reply."""
        kw = {}
        if retries is not None:
            kw["retries"] = retries
        if optional:
            kw["optional"] = True
        deadline = None if window is None else link.now() + window
        values = {}
        reply = None
        for address, count in self._runs():
            if deadline is not None:
                kw["window"] = max(TURNAROUND, deadline - link.now() - link.wire(self.READ_REQUEST + 2 * count))
            reply, regs = self._read(link, ident, address, count, kw)
            if reply is None:
                return None
            for reg, raw in regs:
                values[reg.name] = raw
        raw = values.get("present-voltage")
        errors = self.map.by_name.get("hardware-error")
        return Sample(values.get("present-position"), values.get("present-current"),
                      _volts(self.map.by_name.get("present-voltage"), raw), raw,
                      errors.bit_names(values.get("hardware-error", 0)) if errors is not None else [], reply)

    def _read(self, link, ident, address, count, kw):
        from ..codec import modbus

        reply = link.command(modbus.read_registers(ident, address, count), **kw)
        if reply is None:
            return None, []
        return reply, [(self.map.by_address[address + i], v) for i, v in enumerate(reply.values)
                       if address + i in self.map.by_address]

    def read_margin(self, link, ident) -> int:
        return link.read(ident, self.reg("end-compliance-margin"))

    def write_all(self, link, name, values) -> list:
        """One Write Multiple Registers per actuator, each tried whatever another's did."""
        from ..codec import modbus

        failed = []
        reg = self.reg(name)
        frames = [(i, modbus.write_frames(i, {reg.name: v}, self.map)) for i, v in sorted(values.items())]
        for ident, fs in frames:
            try:
                for f in fs:
                    link.command(f)
            except ZkzapError:
                failed.append(ident)
        return failed


def wire_for(protocol: str = "ir", regmap=None) -> IrWire:
    """The :class:`IrWire` or :class:`ModbusWire` of ``protocol`` on ``regmap`` (None: the
    protocol's shipped map)."""
    return ModbusWire(regmap) if protocol == "modbus" else IrWire(regmap)


def wire_of(bus) -> IrWire:
    """The wire of an open bus (a :class:`zkzap.api.zap.Bus` or its link)."""
    link = getattr(bus, "link", bus)
    family = getattr(link, "family", None)
    if getattr(family, "name", "ir") == "modbus":
        return ModbusWire(link.regmap)
    return IrWire()
