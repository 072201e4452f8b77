"""mightyZAP actuators over Modbus RTU from Python: ``Bus(port, protocol="modbus")``.

The same :class:`~zkzap.api.zap.Bus` and :class:`~zkzap.api.zap.Actuator`, on a
:class:`~zkzap.link.modbus_bus.ModbusBus` and a Modbus register map (the 17Lf's, or
``regmap=``, a :class:`~zkzap.codec.regmap.RegisterMap` from :func:`~zkzap.codec.regmap.load_map`):
registers by the same names (``bus[1].goal_position = 5000``), the same permissions (a stored
setting needs ``STORED`` on a real port, the id and baud-rate registers ``IDENTITY``, a write the
map does not document ``UNDOCUMENTED``, such a write to ID 0 ``BROADCAST``), the same scan,
identify, move, set-id. What differs: IDs are 1..247 (0 is broadcast); every unicast request is
answered (there is no feedback-return-mode); an exception reply raises
:class:`~zkzap.codec.modbus.ExceptionReply` (a DeviceError, exit 5) naming its code; writes go as
Write Multiple Registers, one frame for adjacent registers (:meth:`ModbusBus.write`); the IR
instructions without a Modbus counterpart (Send Data, Execution, Restart, Factory Reset) raise
UsageError.
"""

from __future__ import annotations

import time

from ..codec import modbus
from ..codec.permissions import Permission
from ..errors import CheckFailed, UsageError
from .zap import Actuator, Bus, _given, _value

TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, Iterable, Iterator, Mapping, Optional, Union

    from ..codec.regmap import RegisterMap
    from .records import RegisterRow, ScanRecord
    from .zap import Reading

__all__ = ["ModbusBus", "ModbusActuator"]


class ModbusBus(Bus):
    """A mightyZAP bus speaking Modbus RTU (made by ``Bus(port, protocol="modbus")``; see the
    module's description). ``regmap``: the actuators' register map (default the 17Lf's)."""

    protocol = "modbus"

    def __init__(self, port: Any = None, *, baud: int = 57600, timeout: Optional[float] = None,
                 retries: int = 2, latency: Optional[float] = None, low_latency: bool = False,
                 allow: Any = None, regmap: Optional[RegisterMap] = None, protocol: str = "modbus",
                 return_mode: Any = None, _link: Any = None) -> None:
        if _link is None:
            from ..link.zap_bus import open_bus

            url = getattr(port, "url", port)
            if not url:
                raise UsageError("no port given", baud=baud)
            if regmap is not None and regmap.protocol != "modbus":
                raise UsageError(f"regmap: {regmap.path or regmap.model} describes the {regmap.protocol} protocol")
            _link = open_bus(url, baud, timeout=timeout, retries=retries, latency=latency, protocol="modbus",
                             low_latency=low_latency, regmap=regmap)
            if getattr(port, "kind", None) == "zap" and getattr(port, "device", None) is not None:
                _link.simulated = True
        super().__init__(_link=_link, allow=allow)

    @property
    def map(self) -> RegisterMap:
        """The actuators' register map."""
        return self.link.regmap

    def __getitem__(self, ident: int) -> ModbusActuator:
        return ModbusActuator(self, modbus.check_id(ident, allow_broadcast=False))

    def return_mode_of(self, ident: int) -> int:
        """2: a Modbus actuator answers every unicast request."""
        modbus.check_id(ident, allow_broadcast=False)
        return 2

    def detect_return_mode(self, ident: int) -> int:
        return self.return_mode_of(ident)

    def _mode_for(self, ident: int) -> None:
        return None

    # -- registers ------------------------------------------------------------------------------

    def echo(self, ident: int, *, check: bool = True) -> Any:
        """A one-register read of the model number: the actuator's reply (``rtt``)."""
        return self.link.echo(modbus.check_id(ident, allow_broadcast=False))

    def ping(self, ident: int, *, retries: int = 0) -> Any:
        return self.link.ping(modbus.check_id(ident, allow_broadcast=False), retries=retries)

    def load_reply(self, ident: int, reg: Any, length: Optional[int] = None, *, check: bool = True) -> Any:
        """``(reply, [(Register, raw), ...])`` for ``length`` registers (default 1) from ``reg``."""
        ident = modbus.check_id(ident, allow_broadcast=False)
        r = self.map.register(reg)
        return self.link.read_registers(ident, r.address, 1 if length is None else length, check=check)

    def read(self, ident: int, reg: Any) -> Union[Reading, int]:
        r = self.map.register(reg)
        return _value(r, self.load(ident, r))

    def write(self, ident: int, values: Mapping[Any, int], *, force: bool = False, allow: Any = None) -> list:
        """Write ``{register: value}``: one Write Multiple Registers per run of adjacent
        registers, every frame checked before the first goes out. Returns the replies (None for
        broadcast ID 0)."""
        ident = modbus.check_id(ident)
        raw = {self.map.register(k).name: getattr(v, "raw", v) for k, v in values.items()}
        return self.link.write(ident, raw, force=force, allow=_given(allow, force))

    def store(self, ident: int, reg: Any, value: Any, *, force: bool = False, allow: Any = None) -> Any:
        """Write one register (as :meth:`write`); returns its reply (None for broadcast)."""
        return self.write(ident, {reg: value}, force=force, allow=allow)[0]

    def sync_move(self, targets: Mapping[int, int], register: Any = "goal-position", *,
                  force: bool = False, allow: Any = None) -> None:
        """Write one register of several actuators: ``{id: value}``, one Write Multiple Registers
        each (Modbus has no symmetric store; every frame is checked before the first goes out)."""
        reg = self.map.register(register)
        frames = []
        for ident, value in targets.items():
            frames += self.link.write_frames(modbus.check_id(ident, allow_broadcast=False), {reg.name: value},
                                             force=force)
        for f in frames:
            self.link.authorize(f, _given(allow, force))
        for f in frames:
            self.link.command(f, allow=_given(allow, force))

    def send(self, *a: Any, **kw: Any) -> Any:
        return self.link.send_data(*a, **kw)

    def execute(self, *a: Any, **kw: Any) -> Any:
        return self.link.execute(*a, **kw)

    def restart(self, ident: int) -> Any:
        return self.link.restart(ident)

    def factory_reset(self, *a: Any, **kw: Any) -> Any:
        return self.link.factory_reset(*a, **kw)

    # -- procedures -----------------------------------------------------------------------------

    def scan(self, ids: Iterable[int] = range(1, modbus.MAX_ID + 1), bauds: Iterable[int] = (57600,),
             **kw: Any) -> Iterator[ScanRecord]:
        """Find the actuators (IDs 1..247) at each baud rate: the IR scan's procedure (quick first
        pass, rounds over the IDs in doubt, collisions named), probing with a one-register read.
        Records as :meth:`Bus.scan`'s (``return_mode`` null)."""
        ids = [modbus.check_id(i, allow_broadcast=False) for i in ids]
        return super().scan(ids, bauds, **kw)

    def dump_records(self, ident: int) -> tuple[list[RegisterRow], Any]:
        """Every register of the map, read in as few reads as it has runs of adjacent registers."""
        from .zap import register_records

        ident = modbus.check_id(ident, allow_broadcast=False)
        records: list[Any] = []
        for address, count in runs(self.map):
            reply, values = self.link.read_registers(ident, address, count)
            for rec in register_records(ident, values, []):
                reg = self.map.by_address[rec["address"]]
                rec.pop("errors", None)
                rec["access"] = reg.access
                rec["memory"] = reg.memory
                records.append(rec)
        return records, None

    def _position_moving(self, ident: int) -> tuple[int, int]:
        """present-position and moving. The 17Lf's table has a gap between them (212), so they are
        two reads: moving first, then the position. A rod that reads "stopped" has stopped, and
        the position read after it is where (the other order pairs a position from during the
        move with "stopped" read after it: a wrong final position)."""
        m = self.map
        moving = self.link.read_values(ident, m.by_name["moving"].address, 1)[0]
        return self.link.read_values(ident, m.by_name["present-position"].address, 1)[0], moving

    def move(self, ident: int, position: int, *, wait: bool = True, speed: Optional[int] = None,
             timeout: float = 10.0, poll: float = 0.01, on_progress: Any = None, notify: Any = None,
             stop: bool = True) -> Optional[int]:
        """Move to ``position`` (the map's goal-position range), writing goal-speed in the same
        frame when given (see :meth:`Bus.move`)."""
        m = self.map
        m.by_name["goal-position"].check(position)
        ident = modbus.check_id(ident)
        if wait and ident == modbus.BROADCAST:
            raise UsageError("wait: a broadcast is never answered; give one actuator's ID to wait for it")
        values = {"goal-position": position}
        if speed is not None:
            m.by_name["goal-speed"].check(speed)
            values["goal-speed"] = speed
        self.write(ident, values)
        if not wait:
            return None
        from ..link.zap_safety import interrupted_move

        with interrupted_move(self.link, ident, stop=stop, notify=notify):
            return self.wait_stopped(ident, position, timeout=timeout, poll=poll, on_progress=on_progress,
                                     notify=notify)

    def set_id(self, ident: int, new: int, *, force: bool = False, ready_timeout: float = 2.0) -> int:
        """As :meth:`Bus.set_id`, with Modbus IDs (1..247)."""
        modbus.check_id(ident, allow_broadcast=False)
        modbus.check_id(new, allow_broadcast=False)
        return super().set_id(ident, new, force=force, ready_timeout=ready_timeout)

    def set_baud(self, ident: int, baud: int, *, restart: bool = True, ready_timeout: float = 2.0) -> int:
        """Change actuator ``ident``'s baud rate (its map's code for ``baud``), switch the port
        and read the code back there (the 17Lf answers at the new rate after the reply; there is
        no restart)."""
        ident = modbus.check_id(ident, allow_broadcast=False)
        codes = {rate: code for code, rate in self.map.baud_codes.items()}
        if baud not in codes:
            raise UsageError(f"baud: {baud} is not a baud rate of the {self.map.model} map; allowed "
                             f"{', '.join(str(b) for b in sorted(codes))}", baud=baud)
        self.link.echo(ident)
        self.link.store(ident, "baud-rate", codes[baud], allow=Permission.IDENTITY)
        self.link.set_baud(baud)
        value = self._read_back(ident, self.map.by_name["baud-rate"], ready_timeout,
                                f"set-baud: ID {ident} does not answer at {baud} baud after the change", "baud")
        if value != codes[baud]:
            raise CheckFailed(f"set-baud: ID {ident} reads back baud-rate code {value}, expected {codes[baud]}",
                              ident=ident, value=value)
        return baud


def runs(regmap: RegisterMap, most: int = modbus.MAX_READ) -> list[tuple[int, int]]:
    """``[(address, count)]``: the map's runs of adjacent registers, each at most ``most`` long."""
    out: list = []
    for reg in regmap.registers:
        if out and reg.address == out[-1][0] + out[-1][1] and out[-1][1] < most:
            out[-1] = (out[-1][0], out[-1][1] + 1)
        else:
            out.append((reg.address, 1))
    return out


class ModbusActuator(Actuator):
    """One actuator of a :class:`ModbusBus`: its map's registers as attributes."""

    __slots__ = ()

    def __dir__(self) -> list[str]:
        return sorted(set(object.__dir__(self)) | {r.name.replace("-", "_") for r in self.bus.map.registers})

    def _reg(self, name: str) -> Any:
        try:
            return self.bus.map.register(name)
        except ValueError:
            raise AttributeError(f"no register {name!r} in the {self.bus.map.model} map", name=name) from None

    if not TYPE_CHECKING:
        def __getattr__(self, name):
            if name.startswith("_"):
                raise AttributeError(name)
            return self.bus.read(self.ident, self._reg(name))

        def __setattr__(self, name, value):
            if name in Actuator.__slots__:
                raise AttributeError(f"{name} is fixed")
            self.bus.store(self.ident, self._reg(name), value)
