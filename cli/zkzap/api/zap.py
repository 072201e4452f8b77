"""mightyZAP actuators from Python: :class:`Bus` (one port, every instruction and procedure)
and :class:`Actuator` (one ID, registers as attributes).

>>> from zkzap import Bus
>>> with Bus("sim://zap?ids=1,2") as bus:          # doctest: +SKIP
...     bus[1].goal_position = 2000
...     print(bus[1].present_voltage)               # 12.0 V

Registers are named as in ``zap registers`` (``goal-position``), with underscores
(``goal_position``), or by address (``0x86``).

Writes keep the command line's rules, decided on the typed packet
(:meth:`zkzap.codec.zap.Command.needs`): a stored setting, a factory reset or system write need
:attr:`Permission.STORED <zkzap.codec.permissions.Permission>` / ``FACTORY`` on a real port (a
simulator waives them); the id, baud-rate and protocol-type registers ``IDENTITY``; addresses and
values the map does not document ``UNDOCUMENTED``; part of a multi-byte register ``PARTIAL``; such
writes to every actuator ``BROADCAST``. Give them to the bus (``Bus(port, allow=Permission.STORED)``)
or to one call (``bus.store(1, "id", 7, allow=Permission.IDENTITY)``; ``force=True`` gives every
FORCE permission); a write without them raises :class:`~zkzap.errors.PermissionNeeded` and sends
nothing. :meth:`Bus.set_id` and :meth:`Bus.set_baud` are the checked ways to change an identity:
they need only ``STORED``. Values are raw integers in the register's
units; a register with a unit (present-voltage, 0.1 V) reads through :meth:`Bus.read` and
:class:`Actuator` attributes as a :class:`Reading`, a float that knows its unit and raw value.

The procedures the ``zap`` commands run live here: :meth:`Bus.scan`, :meth:`Bus.identify`,
:meth:`Bus.dump`, :meth:`Bus.move` (with waiting), :meth:`Bus.set_id` and :meth:`Bus.set_baud`
(both verified by reading back). Failures raise :mod:`zkzap.errors` exceptions carrying the
facts (ID, baud rate, timeout, tries). Nothing here imports click or rich; pyserial is
imported when the port opens.
"""

from __future__ import annotations

TYPE_CHECKING = False

if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Callable, Iterable, Iterator, Literal, Mapping, Optional, Union, overload

    from typing_extensions import Self, TypeAlias

    from ..codec.permissions import AllowSpec
    from ..link.zap_bus import Reply, ZapBus
    from ..sim.launch import Simulator
    from ._registers import RegisterAttributes as _Registers
    from .records import Identity, Latency, MoveRecord, RegisterRow, RegisterValue, ScanRecord
else:
    _Registers = object

from ..codec import zap
from ..codec.permissions import FORCE, Permission, as_permission
from ..errors import BadReply, CheckFailed, IdTaken, NoReply, UsageError, did_you_mean

__all__ = ["Bus", "Actuator", "Reading", "Moved", "Permission", "ALL_BAUDS", "register_records", "map_blocks"]

#: Baud rates an actuator can talk at, in the order a scan over all of them tries: the factory
#: default first, then the others fastest first.
from ..link.zap_scan import ALL_BAUDS  # noqa: E402 - the order 'scan --baud all' tries

#: The block :meth:`Bus.identify` reads: model-number .. feedback-return-mode.
INFO_FIRST = zap.REGISTER_BY_NAME["model-number"]
INFO_LAST = zap.REGISTER_BY_NAME["feedback-return-mode"]
#: present-position .. moving, read in one Load Data while waiting for a move.
WATCH_FIRST = zap.REGISTER_BY_NAME["present-position"]
WATCH_LAST = zap.REGISTER_BY_NAME["moving"]
POSITION = zap.REGISTER_BY_NAME["goal-position"]
SPEED = zap.REGISTER_BY_NAME["goal-speed"]
ID_REG = zap.REGISTER_BY_NAME["id"]
BAUD_REG = zap.REGISTER_BY_NAME["baud-rate"]

if TYPE_CHECKING:
    #: A register: its name, its address or the Register itself.
    RegisterSpec: TypeAlias = Union[str, int, zap.Register]
    #: A record: a dict of JSON-ready values.
    Record: TypeAlias = dict[str, Any]
else:
    #: A register: its name, its address or the Register itself.
    RegisterSpec = "str | int | zap.Register"


class Reading(float):
    """A register value in its unit: a float (``12.0``) with ``unit`` (``"V"``), ``raw`` (the
    integer on the wire, ``120``) and ``register`` (the :class:`zkzap.codec.zap.Register`)."""

    __slots__ = ("unit", "raw", "register")
    unit: str
    raw: int
    register: zap.Register

    def __new__(cls, register: zap.Register, raw: int) -> Self:
        self = super().__new__(cls, register.physical(raw))
        self.unit = register.unit
        self.raw = raw
        self.register = register
        return self

    def __repr__(self) -> str:
        return f"{float(self)!r} {self.unit}".rstrip()

    __str__ = __repr__


class Moved(int):
    """What a move that waited returns: an int, the final position (as ever), that also says
    what became of the goal. ``requested``: the goal-position sent (the library sends it as
    given); ``goal``: the goal the actuator holds, read back after the write (it clamps a goal to
    its stroke limits); ``clamped``: whether they differ (then :class:`~zkzap.errors.GoalClamped`
    was warned too); ``ident``: the actuator. :meth:`as_dict` is the record the command line
    renders."""

    ident: int
    requested: int
    goal: int

    def __new__(cls, position: int, *, ident: int, requested: int, goal: int) -> Self:
        self = super().__new__(cls, position)
        self.ident, self.requested, self.goal = ident, requested, goal
        return self

    @property
    def position(self) -> int:
        """The final position (the int itself)."""
        return int(self)

    @property
    def clamped(self) -> bool:
        """Whether the actuator holds another goal than the one sent (its stroke limits)."""
        return self.goal != self.requested

    def as_dict(self) -> MoveRecord:
        """``{"id", "requested", "goal", "clamped", "position"}``."""
        return {"id": self.ident, "requested": self.requested, "goal": self.goal, "clamped": self.clamped,
                "position": int(self)}

    __str__ = int.__repr__                 # printed as the position it is

    def __repr__(self) -> str:
        return (f"Moved({int(self)}, ident={self.ident}, requested={self.requested}, goal={self.goal}"
                + (", clamped" if self.clamped else "") + ")")


def _value(reg: zap.Register, raw: int) -> Union[Reading, int]:
    return Reading(reg, raw) if reg.unit else raw


def register_records(ident: int, values: Iterable[tuple[zap.Register, int]],
                     errors: Iterable[str] = ()) -> list[RegisterValue]:
    """Records (id, register, address, value, physical/unit where scaled, meaning where the
    register has named values, errors) for ``[(Register, raw), ...]``."""
    out: list[Any] = []
    for reg, raw in values:
        rec: dict[str, Any] = {"id": ident, "register": reg.name, "address": reg.address, "value": raw}
        if reg.scale != 1:
            rec["physical"] = reg.physical(raw)
            rec["unit"] = reg.unit
        elif reg.unit:
            rec["unit"] = reg.unit
        if reg.choices and raw in reg.choices:
            rec["meaning"] = reg.choices[raw]
        rec["errors"] = list(errors)
        out.append(rec)
    return out


def map_blocks(gap: int = 8) -> list[tuple[int, int]]:
    """Contiguous runs of the register map, as ``(address, length)``: few, efficient Load Data
    reads (gaps of at most ``gap`` unmapped bytes are read through)."""
    blocks = []
    for reg in sorted(zap.REGISTERS, key=lambda r: r.address):
        end = reg.address + reg.size
        if blocks and reg.address - (blocks[-1][0] + blocks[-1][1]) <= gap:
            blocks[-1][1] = end - blocks[-1][0]
        else:
            blocks.append([reg.address, reg.size])
    return [tuple(b) for b in blocks]


def _span(first: zap.Register, last: zap.Register) -> int:
    return last.address + last.size - first.address


class Bus:
    """A mightyZAP bus on one port: a context manager (the port closes on exit).

    ``port`` is a device path, any pyserial URL, ``sim://zap?ids=1,2`` or a simulator started
    with :func:`zkzap.sim.start`; ``baud`` the line speed; ``return_mode`` the feedback-return-mode
    assumed of an actuator until its own is learned (0 answers Echo only, 1 Load Data and Echo, 2
    every command; ``"auto"`` asks each actuator its own the first time it is addressed; see
    :meth:`return_mode_of`); ``timeout`` (seconds) is the late window, how long after
    a request its reply may still begin (default 0.15: nothing is sent before it has closed, see
    :mod:`zkzap.link.zap_timing`); ``retries`` after a failed attempt; ``latency`` (seconds) what
    the actuators are known to take before any reply is measured; ``low_latency`` asks the serial
    driver for its low-latency mode; ``allow`` the permissions every write is given (a
    :class:`~zkzap.codec.permissions.Permission`, names like ``["stored"]``, or True for all; see
    the module's description). A started simulator (:func:`zkzap.sim.start_zap`), whatever its
    transport, or a ``sim://``/``loop://`` URL waives the consent permissions. Every Bus on one
    port in this process shares what was learned of the actuators' latencies (:attr:`latencies`).
    """

    #: The protocol family: ``ir`` here, ``modbus`` on a :class:`zkzap.api.zap_modbus.ModbusBus`.
    protocol = "ir"

    def __new__(cls, *args: Any, protocol: Literal["ir", "modbus"] = "ir", **kw: Any) -> Self:
        if protocol not in ("ir", "modbus"):
            raise UsageError(f"protocol: {protocol!r}; allowed ir, modbus", protocol=protocol)
        if protocol == "modbus" and cls is Bus:
            from .zap_modbus import ModbusBus

            return object.__new__(ModbusBus)
        return object.__new__(cls)

    def __init__(self, port: Union[str, Simulator, None] = None, *, baud: int = 57600,
                 return_mode: Union[int, Literal["auto"]] = 1, timeout: Optional[float] = None,
                 retries: int = 2, latency: Optional[float] = None, low_latency: bool = False,
                 allow: AllowSpec = None, protocol: Literal["ir", "modbus"] = "ir",
                 _link: Optional[ZapBus] = None) -> None:
        """``protocol="modbus"``: actuators speaking Modbus RTU (the 17Lf; the Bus is then a
        :class:`zkzap.api.zap_modbus.ModbusBus`, which also takes ``regmap=``)."""
        if _link is None:
            from ..link.zap_bus import RETRIES, open_bus

            url = getattr(port, "url", port)
            if not url:
                raise UsageError("no port given", baud=baud)
            mode = 1 if return_mode == "auto" else int(return_mode)
            _link = open_bus(url, baud, timeout=timeout, return_mode=mode,
                             retries=RETRIES if retries is None else retries, latency=latency,
                             low_latency=low_latency)
            if getattr(port, "kind", None) == "zap" and getattr(port, "device", None) is not None:
                _link.simulated = True             # a simulator started here, over a pty or TCP too
            self._auto = return_mode == "auto"
        else:
            self._auto = False
        if allow is not None:
            _link.allow = as_permission(allow)
        self.link = _link
        """The :class:`zkzap.link.zap_bus.ZapBus` doing the transactions."""

    @classmethod
    def over(cls, link: ZapBus) -> Self:
        """A Bus over an open :class:`~zkzap.link.zap_bus.ZapBus` (closing the Bus closes it);
        over a Modbus RTU link (:class:`~zkzap.link.modbus_bus.ModbusBus`) a
        :class:`~zkzap.api.zap_modbus.ModbusBus`."""
        if cls is Bus and link.family.name == "modbus":
            from .zap_modbus import ModbusBus

            return ModbusBus(_link=link)  # type: ignore[return-value]
        return cls(_link=link)

    # -- the line ------------------------------------------------------------------------------

    @property
    def baud(self) -> int:
        """The port's line speed."""
        return self.link.baud

    @baud.setter
    def baud(self, value: int) -> None:
        self.link.set_baud(value)

    @property
    def return_mode(self) -> int:
        """The feedback-return-mode (0, 1 or 2) assumed of an actuator whose own the bus has not
        learned (see :meth:`return_mode_of`). Setting it changes what is assumed, not what was
        learned of an actuator."""
        return self.link.return_mode

    @return_mode.setter
    def return_mode(self, value: int) -> None:
        self.link.return_mode = int(value)

    @property
    def url(self) -> str:
        """The port's device path or URL."""
        return self.link.url

    @property
    def allow(self) -> Permission:
        """The permissions every write on this bus is given (see the module's description)."""
        return self.link.allow

    @allow.setter
    def allow(self, value: AllowSpec) -> None:
        self.link.allow = as_permission(value)

    @property
    def latencies(self) -> dict[int, Latency]:
        """What was learned of each actuator's latency on this port: ``{ID: {"latency_ms",
        "variation_ms", "samples", "late"}}`` (the time from a request's last byte to the first
        reply byte, smoothed; its variation; answers measured; answers after the learned
        timeout)."""
        return self.link.latencies()

    def close(self) -> None:
        """Close the port."""
        self.link.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __getitem__(self, ident: int) -> Actuator:
        return Actuator(self, zap.check_id(ident))

    def return_mode_of(self, ident: int) -> int:
        """The feedback-return-mode of actuator ``ident``: the one learned of it (a scan's
        identification, :meth:`detect_return_mode`, a write of feedback-return-mode through this
        bus), else :attr:`return_mode`. Each actuator has its own: one told to answer every
        command changes nothing of how the others are waited for."""
        return self.link.mode_of(zap.check_id(ident, allow_broadcast=False))

    def _mode_for(self, ident: int) -> None:
        if self._auto and ident != zap.BROADCAST:
            dev = self.link.devices.get(ident)
            if dev is None or dev.return_mode is None:
                self.link.detect_return_mode(ident)

    def detect_return_mode(self, ident: int) -> int:
        """Ask actuator ``ident`` its feedback-return-mode; the bus assumes it of that actuator
        from now on (see :meth:`return_mode_of`)."""
        return self.link.detect_return_mode(zap.check_id(ident, allow_broadcast=False))

    # -- instructions --------------------------------------------------------------------------

    def echo(self, ident: int, *, check: bool = True) -> Reply:
        """Echo: the actuator's feedback (a :class:`~zkzap.link.zap_bus.Reply` with ``rtt``).
        Error bits raise DeviceError unless ``check=False``."""
        ident = zap.check_id(ident, allow_broadcast=False)
        return self.link.echo(ident, check=check)

    def ping(self, ident: int, *, retries: int = 0) -> Optional[Reply]:
        """Echo that returns None when nothing answers (a corrupted reply raises BadReply)."""
        return self.link.ping(zap.check_id(ident, allow_broadcast=False), retries=retries)

    def load_reply(self, ident: int, reg: RegisterSpec, length: Optional[int] = None, *,
                   check: bool = True) -> tuple[Reply, list[tuple[zap.Register, int]]]:
        """Load Data: ``(reply, [(Register, raw), ...])`` for ``length`` bytes from ``reg``."""
        ident = zap.check_id(ident, allow_broadcast=False)
        reg = zap.register(reg)
        length = reg.size if length is None else length
        self._mode_for(ident)
        if self.link.mode_of(ident) == 0:
            raise UsageError(f"ID {ident} is in feedback-return-mode 0: it answers Echo only, never Load Data",
                             ident=ident)
        return self.link.read_registers(ident, reg.address, length, check=check)

    if TYPE_CHECKING:
        @overload
        def load(self, ident: int, reg: RegisterSpec, length: None = None) -> int: ...
        @overload
        def load(self, ident: int, reg: RegisterSpec, length: int) -> Union[int, dict[str, int]]: ...

    def load(self, ident: int, reg: RegisterSpec, length: Optional[int] = None) -> Union[int, dict[str, int]]:
        """Load Data: the raw value of ``reg``; with a ``length`` spanning several registers a
        dict ``{name: raw}``."""
        _, values = self.load_reply(ident, reg, length)
        if len(values) == 1:
            return values[0][1]
        return {r.name: raw for r, raw in values}

    def read(self, ident: int, reg: RegisterSpec) -> Union[Reading, int]:
        """One register's value: a :class:`Reading` for a register with a unit, else an int."""
        reg = zap.register(reg)
        return _value(reg, self.load(ident, reg))

    def _write(self, builder: Callable[..., bytes], ident: int, reg: RegisterSpec, value: Union[int, Reading],
               force: bool, allow: AllowSpec) -> Optional[Reply]:
        ident = zap.check_id(ident)
        reg = zap.register(reg)
        raw = getattr(value, "raw", value)
        pkt = builder(ident, reg, raw, force=force)
        self._mode_for(ident)
        return self.link.command(pkt, allow=_given(allow, force))

    def store(self, ident: int, reg: RegisterSpec, value: Union[int, Reading], *,
              force: bool = False, allow: AllowSpec = None) -> Optional[Reply]:
        """Store Data: write ``value`` (raw) to ``reg``. Returns the acknowledgement (return
        mode 2) or None. ``allow``: permissions for this write besides the bus's; ``force``:
        every FORCE permission (and a read-only register may be written)."""
        return self._write(zap.store, ident, reg, value, force, allow)

    def send(self, ident: int, reg: RegisterSpec, value: Union[int, Reading], *,
             force: bool = False, allow: AllowSpec = None) -> Optional[Reply]:
        """Send Data: stage ``value`` for ``reg``; :meth:`execute` applies it (permissions as
        :meth:`store`)."""
        return self._write(zap.send_data, ident, reg, value, force, allow)

    def execute(self, ident: int = zap.BROADCAST) -> Optional[Reply]:
        """Execution: apply the writes staged by :meth:`send` (default: every actuator)."""
        return self.link.command(zap.execute(zap.check_id(ident)))

    def sync_move(self, targets: Mapping[int, int], register: RegisterSpec = "goal-position", *,
                  force: bool = False, allow: AllowSpec = None) -> None:
        """Symmetric Store to broadcast: ``{id: value}`` of one register (default
        goal-position), split over as many packets as needed (every one checked before the
        first goes out; permissions as :meth:`store`). Never answered."""
        self.link.symmetric_store(register, targets, allow=_given(allow, force))

    def factory_reset(self, ident: int, *, reset_id: bool = False, reset_baud: bool = False,
                      allow: AllowSpec = None) -> Optional[Reply]:
        """Factory Reset: restore factory settings (also the ID and/or baud rate if asked).
        Needs the FACTORY permission on a real port (BROADCAST too for ID 254)."""
        return self.link.command(zap.factory_reset(zap.check_id(ident), reset_id, reset_baud), allow=allow)

    def restart(self, ident: int) -> Optional[Reply]:
        """Restart the actuator (a stored baud-rate change takes effect)."""
        return self.link.command(zap.restart(zap.check_id(ident)))

    def command(self, packet: bytes, *, check: bool = True, allow: AllowSpec = None) -> Optional[Reply]:
        """Send any command packet; returns the reply it gets (inferred from the packet), or
        None. The packet needs what :meth:`zkzap.codec.zap.Command.needs` says (``allow``)."""
        return self.link.command(bytes(packet), check=check, allow=allow)

    # -- procedures ----------------------------------------------------------------------------

    def identify(self, ident: int, *, retries: int = 2) -> Identity:
        """``{"model", "firmware", "return_mode", "status", "errors"}`` of an actuator that answers
        Echo, from one Load Data. An actuator that answers Echo but not Load Data (after a full
        wait) is in return mode 0; a read that fails leaves the fields None with status
        ``unidentified`` (``duplicate`` when the reply is garbled), never a guess."""
        from ..link.zap_scan import identify

        rec: Any = {"id": ident, "model": None, "firmware": None, "return_mode": None, "status": "ok", "errors": []}
        identify(self.link, rec, retries)
        rec.pop("id")
        return rec  # type: ignore[no-any-return]

    def scan(self, ids: Iterable[int] = range(254), bauds: Iterable[int] = (57600,), *, retries: int = 2,
             on_probe: Optional[Callable[[int, int, int], None]] = None,
             on_warning: Optional[Callable[[str], None]] = None,
             include_garbled: bool = True,
             on_note: Optional[Callable[[str], None]] = None) -> Iterator[ScanRecord]:
        """Find actuators at each baud rate in ``bauds``: a quick Echo to every ID, quick rounds
        and then full waits for the IDs near a late or garbled reply, then the model, firmware and return mode of
        each actuator found (see :mod:`zkzap.link.zap_scan` for the policy). Yields records in ID
        order: ``id``, ``baud``, ``model``, ``firmware``, ``return_mode``, ``status`` (``ok``,
        ``error``, ``garbled``, ``duplicate``, ``unidentified``) and ``errors``.
        ``on_probe(baud, id, found)`` is called before each first probe (for progress) and
        ``on_warning(text)`` for what a scan should say (duplicate IDs, garbled replies), and
        ``on_note(text)`` for what is worth knowing where nothing went wrong (actuators that
        answer after the scan's quick wait, all identified: once per bus and rate, with their
        latency). The port is left at the last baud rate scanned."""
        from ..link.zap_scan import scan as scan_bus

        ids, bauds = list(ids), list(bauds)
        for baud in bauds:
            if baud not in zap.BAUD_TO_CODE:
                raise UsageError(f"baud: {baud} is not an actuator baud rate; allowed "
                                 f"{', '.join(str(b) for b in ALL_BAUDS)}", baud=baud)
        for event in scan_bus(self.link, ids, bauds, retries=retries):
            if event[0] == "probe":
                _, baud, ident, found, phase = event
                if on_probe is not None and phase == "first":
                    on_probe(baud, ident, found)
            elif event[0] == "record":
                if include_garbled or event[1]["status"] != "garbled":
                    yield event[1]
            elif event[0] == "note":
                if on_note is not None:
                    on_note(event[1])
            elif on_warning is not None:
                on_warning(event[1])

    def dump_records(self, ident: int) -> tuple[list[RegisterRow], Optional[Reply]]:
        """``(records, reply with error bits or None)``: the whole register map of one actuator,
        read in as few Load Data reads as it has contiguous blocks (see :meth:`dump`)."""
        ident = zap.check_id(ident, allow_broadcast=False)
        records: list[Any] = []
        worst = None
        for address, length in map_blocks():
            reply, values = self.load_reply(ident, address, length, check=False)
            if reply.error and worst is None:
                worst = reply
            mapped = [(reg, raw) for reg, raw in values if zap.REGISTER_BY_ADDRESS.get(reg.address) is reg]
            for rec in register_records(ident, mapped, reply.errors):
                reg = zap.REGISTER_BY_ADDRESS[rec["address"]]
                rec.pop("errors", None)  # type: ignore[misc]
                rec["access"] = reg.access
                rec["memory"] = reg.memory
                records.append(rec)
        return records, worst

    def dump(self, ident: int) -> list[RegisterRow]:
        """The whole register map of one actuator as records: id, register, address, value,
        physical and unit (scaled registers), meaning (coded ones), access (R/RW) and memory
        (NV stored, V volatile). Error bits in a reply raise DeviceError."""
        from ..link.zap_bus import device_error

        records, worst = self.dump_records(ident)
        if worst is not None:
            raise device_error(worst)
        return records

    if TYPE_CHECKING:
        @overload
        def move(self, ident: int, position: int, *, wait: Literal[True] = True, speed: Optional[int] = None,
                 timeout: float = 10.0, poll: float = 0.01,
                 on_progress: Optional[Callable[[int, int, int], None]] = None,
                 notify: Optional[Callable[[str], None]] = None, stop: bool = True) -> Moved: ...
        @overload
        def move(self, ident: int, position: int, *, wait: Literal[False], speed: Optional[int] = None,
                 timeout: float = 10.0, poll: float = 0.01,
                 on_progress: Optional[Callable[[int, int, int], None]] = None,
                 notify: Optional[Callable[[str], None]] = None, stop: bool = True) -> None: ...
        @overload
        def move(self, ident: int, position: int, *, wait: bool, speed: Optional[int] = None,
                 timeout: float = 10.0, poll: float = 0.01,
                 on_progress: Optional[Callable[[int, int, int], None]] = None,
                 notify: Optional[Callable[[str], None]] = None, stop: bool = True) -> Optional[Moved]: ...

    def move(self, ident: int, position: int, *, wait: bool = True, speed: Optional[int] = None,
             timeout: float = 10.0, poll: float = 0.01,
             on_progress: Optional[Callable[[int, int, int], None]] = None,
             notify: Optional[Callable[[str], None]] = None, stop: bool = True) -> Optional[Moved]:
        """Move to ``position`` (0..4095), writing goal-speed first when ``speed`` is given.

        With ``wait`` (the default) it reads the goal back (the actuator clamps it to its stroke
        limits: then :class:`~zkzap.errors.GoalClamped` is warned through :mod:`warnings`), then
        polls present-position and moving every ``poll`` s until the actuator stops, and returns
        the final position as a :class:`Moved` (an int that also says ``requested``, ``goal`` and
        ``clamped``). Raises NoReply when it is
        still moving after ``timeout`` s, CheckFailed when it stopped away from the goal (beyond
        end-compliance-margin), DeviceError on error bits (overload cuts the force).
        ``on_progress(position, goal, first_position)`` is called on every read. A
        KeyboardInterrupt while waiting (Ctrl-C, or SIGTERM in the CLI) first stops the rod where
        it is (goal-position = present position; not with ``stop=False``; ``notify`` is told
        where), then goes on. Without ``wait`` it returns None at once."""
        POSITION.check(position)
        if speed is not None:
            SPEED.check(speed)
        ident = zap.check_id(ident)
        if wait and ident == zap.BROADCAST:
            raise UsageError("wait: a broadcast is never answered; give one actuator's ID to wait for it")
        if wait:
            self._mode_for(ident)
        if speed is not None:
            self.store(ident, SPEED, speed)
        self.store(ident, POSITION, position)
        if not wait:
            return None
        if self.link.mode_of(ident) == 0:
            raise UsageError(f"wait: ID {ident} is in feedback-return-mode 0 and never answers Load Data",
                             ident=ident)
        from ..link.zap_safety import interrupted_move

        with interrupted_move(self.link, ident, stop=stop, notify=notify):
            return self.wait_stopped(ident, position, timeout=timeout, poll=poll, on_progress=on_progress,
                                     notify=notify)

    def play(self, path: Any, *, unit: str = "counts", scales: Optional[Mapping[int, Any]] = None,
             interpolate: Optional[str] = None, rate: Optional[float] = None, loops: int = 1, log: bool = True,
             limit: Optional[float] = None, stop_mode: str = "hold",
             on_row: Optional[Callable[[Record], None]] = None,
             on_progress: Optional[Callable[[int, int], None]] = None) -> Any:
        """Play a timed path file (CSV, JSON or JSON Lines rows of t, id, position, speed,
        current) on this bus, as ``zap play`` does: rows of one time are one sync move (on
        Modbus RTU one answered write per actuator); with
        ``interpolate="linear"`` goals every 1/``rate`` s; a plan the line cannot carry raises
        UsageError before anything moves. ``on_row(row)`` gets each log row (goal vs present,
        current, voltage), ``on_progress(done, total)`` each step sent. A hardware error bit, a
        current over ``limit`` mA or Ctrl-C stops every actuator (``stop_mode`` ``hold``: goal
        := present position; ``off``: force off). Returns the
        :class:`~zkzap.api.motion.Player`: its ``summary()`` (lateness p50/p99/max) and
        ``stopped`` (None when the path ran to its end). See :mod:`zkzap.api.motion`."""
        from .motion import play

        return play(self, path, unit=unit, scales=scales, interpolate=interpolate, rate=rate, loops=loops, log=log,
                    limit=limit, stop_mode=stop_mode, on_row=on_row, on_progress=on_progress)

    def stop(self, ident: int) -> int:
        """Stop actuator ``ident`` where it is: its present position becomes its goal position.
        Returns that position."""
        from ..link.zap_safety import stop_where_it_is

        return stop_where_it_is(self.link, zap.check_id(ident, allow_broadcast=False))

    def wait_stopped(self, ident: int, position: int, *, timeout: float = 10.0, poll: float = 0.01,
                     on_progress: Optional[Callable[[int, int, int], None]] = None,
                     notify: Optional[Callable[[str], None]] = None) -> Moved:
        """Wait until actuator ``ident``, sent to ``position``, stops; its final position, a
        :class:`Moved` (see :meth:`move`; a clamped goal is warned, :class:`~zkzap.errors.GoalClamped`)."""
        goal = self.load(ident, POSITION)
        margin = self.load(ident, "end-compliance-margin")
        if goal != position:
            import warnings

            from ..errors import GoalClamped

            import os
            import sys

            # said at the caller's line (outside zkzap, where Python can tell)
            where: Any = {"skip_file_prefixes": (os.path.dirname(os.path.dirname(__file__)),)} \
                if sys.version_info >= (3, 12) else {"stacklevel": 3}
            warnings.warn(GoalClamped(f"ID {ident}: goal {position} clamped to {goal} by the stroke limits",
                                      ident=ident, requested=position, goal=goal), **where)
        start = self.link.now()
        first = None
        while True:
            pos, moving = self._position_moving(ident)
            if first is None:
                first = pos
            if on_progress is not None:
                on_progress(pos, goal, first)
            if not moving:
                if abs(pos - goal) <= max(margin, 1):
                    return Moved(pos, ident=ident, requested=position, goal=goal)
                force = self.load(ident, "force-on-off")
                why = "; the force is off" if not force else ""
                raise CheckFailed(f"ID {ident} stopped at {pos}, {abs(pos - goal)} away from the goal {goal}{why}",
                                  ident=ident, position=pos, goal=goal)
            if self.link.now() - start >= timeout:
                raise NoReply(f"ID {ident} still moving after {timeout:g} s (position {pos}, goal {goal})",
                              ident=ident, position=pos, goal=goal, timeout=timeout)
            if poll:
                self.link.sleep(poll)

    def _position_moving(self, ident: int) -> tuple[int, int]:
        """present-position and moving, read in one Load Data (present-position .. moving)."""
        _, values = self.link.read_registers(ident, WATCH_FIRST.address, _span(WATCH_FIRST, WATCH_LAST))
        v = {reg.name: raw for reg, raw in values}
        return v["present-position"], v["moving"]

    def _read_back(self, ident: int, reg: zap.Register, within: float, message: str, change: str) -> int:
        try:
            self.link.wait_ready(ident, within=within)
            return self.link.read(ident, reg)
        except NoReply:
            raise CheckFailed(message, ident=ident, baud=self.baud, timeout=within, after_change=change) from None

    def _single(self, what: str, ident: int, free: Iterable[int] = ()) -> None:
        """Before an identity change: exactly one actuator answers to ``ident`` and none to
        any of ``free``, at the bus's baud rate, as far as the line can tell
        (:meth:`zkzap.link.zap_bus.ZapBus.census`: one horizon in all). Raises NoReply,
        CheckFailed (``duplicate``: two replies where one was due, or replies that stay
        garbled) or IdTaken; nothing is written."""
        free = [i for i in free if i != ident]
        seen = self.link.census([ident, *free])
        if seen[ident] == "none":
            raise NoReply(f"{what}: no reply from ID {ident} at {self.baud} baud", ident=ident, baud=self.baud,
                          protocol="zap")
        if seen[ident] == "shared":
            raise CheckFailed(f"{what}: replies from ID {ident} at {self.baud} baud collide or come twice where "
                              "one was due: two actuators seem to answer to it (or the line is faulty); nothing "
                              "was written",
                              ident=ident, duplicate=True, baud=self.baud)
        taken = [i for i in free if seen[i] != "none"]
        if taken:
            raise IdTaken(f"ID {taken[0]} is already taken by another actuator at {self.baud} baud",
                          ident=taken[0], taken=True, baud=self.baud)
        for i in free:
            # not on this line, but heard at another rate on this port: the same ID once the
            # rates are made one
            elsewhere = [b for b in self.link.bauds_of(i) if b != self.baud]
            if elsewhere:
                raise IdTaken(f"ID {i} is already taken by an actuator at {elsewhere[0]} baud (heard on this port)",
                              ident=i, taken=True, baud=elsewhere[0])

    def set_id(self, ident: int, new: int, *, force: bool = False, ready_timeout: float = 2.0) -> int:
        """Give the actuator at ``ident`` the ID ``new``, verified by reading it back from
        ``new``. Checks first that ``ident`` answers and that ``new`` is free (two actuators with
        one ID garble every reply; ``force`` skips that). Raises CheckFailed when ``new`` is
        taken, does not answer afterwards or reads back another ID. Returns ``new``. Needs the
        STORED permission on a real port (the id register is a stored setting)."""
        ident = zap.check_id(ident, allow_broadcast=False)
        new = zap.check_id(new, allow_broadcast=False)
        if new == ident:
            return new
        from ..link.zap_scan import collides

        self._single("set-id", ident, [] if force else [new])
        if self.link.mode_of(ident) and collides(self.link, ident):
            raise CheckFailed(f"set-id: replies from ID {ident} collide: two actuators seem to answer to it",
                              ident=ident, duplicate=True)
        self.link.store(ident, ID_REG, new, allow=Permission.IDENTITY)   # the checked way: set_id itself
        value = self._read_back(new, ID_REG, ready_timeout,
                                f"set-id: ID {new} does not answer after the change", "id")
        # (the census found one actuator at the old ID: an Echo with the whole window, not a
        # second horizon, says that it is gone from there)
        if value == new and (self.link.answers(ident, tries=2, listen_out=False) or collides(self.link, new)):
            raise CheckFailed(f"set-id: ID {ident} still answers after the change (ID {new} reads back {value}): "
                              f"two actuators may have had ID {ident}", ident=ident, duplicate=True)
        if value != new:
            raise CheckFailed(f"set-id: ID {new} reads back its ID as {value}", ident=new, value=value)
        self.link.moved_id(ident, new)          # what is known of it goes along
        if not force:
            # the one actuator the census found at ``ident`` is the one at ``new`` (found free)
            self.link.heard_out({(self.baud, new): "one", (self.baud, ident): "none"})
        return new

    def set_baud(self, ident: int, baud: int, *, restart: bool = True, ready_timeout: float = 2.0) -> int:
        """Change actuator ``ident``'s baud rate to ``baud``, verified: store baud-rate, restart
        the actuator (unless ``restart=False``: then the rate takes effect at the next power-up),
        switch this port to ``baud``, wait for the actuator there and read baud-rate back.
        Raises CheckFailed when it does not answer at ``baud`` or reads back another rate.
        Needs the STORED permission on a real port."""
        ident = zap.check_id(ident, allow_broadcast=False)
        if baud not in zap.BAUD_TO_CODE:
            raise UsageError(f"baud: {baud} is not an actuator baud rate; allowed "
                             f"{', '.join(str(b) for b in ALL_BAUDS)}", baud=baud)
        code = zap.BAUD_TO_CODE[baud]
        was = self.baud
        self._single("set-baud", ident)
        if restart and baud != was:
            # an actuator that already has this ID at the new rate is heard only there
            self.link.set_baud(baud)
            try:
                taken = self.link.census([ident])[ident] != "none"
            finally:
                self.link.set_baud(was)
            if taken:
                raise IdTaken(f"set-baud: ID {ident} is already taken by another actuator at {baud} baud; "
                              "nothing was written", ident=ident, taken=True, baud=baud)
        try:
            self.link.store(ident, BAUD_REG, code, allow=Permission.IDENTITY)   # the checked way: set_baud itself
        except NoReply as e:
            # its acknowledgement did not come, but the write may have been heard (an actuator in
            # another return mode than was assumed): the old rate is written back, unanswered or not
            self.link.store(ident, BAUD_REG, zap.BAUD_TO_CODE[was], allow=Permission.IDENTITY, optional=True)
            e.facts["rolled_back"] = e.rolled_back = True
            raise
        if not restart:
            value = self.link.read(ident, BAUD_REG)
            if value != code:
                raise CheckFailed(f"set-baud: ID {ident} reads back baud-rate {value}, expected {code}",
                                  ident=ident, value=value)
            return baud
        self.link.restart(ident)
        self.link.moved_to(ident, baud)       # what is known of it goes along
        self.link.set_baud(baud)
        try:
            value = self._read_back(ident, BAUD_REG, ready_timeout,
                                    f"set-baud: ID {ident} does not answer at {baud} baud after the restart", "baud")
        except (CheckFailed, UsageError) as e:     # (UsageError: return mode 0 never answers a read)
            if isinstance(e, CheckFailed) or self.link.ping(ident, retries=1) is None:
                failed = e if isinstance(e, CheckFailed) else CheckFailed(
                    f"set-baud: ID {ident} cannot be read back at {baud} baud: {e}", ident=ident, baud=baud,
                    after_change="baud")
                self._roll_back_baud(ident, was, failed)
                raise failed from None
            raise
        if value != code:
            raise CheckFailed(f"set-baud: ID {ident} reads back baud-rate code {value}, expected {code} ({baud})",
                              ident=ident, value=value)
        if baud != was:
            # the one actuator the census found with ``ident`` at ``was`` is the one at ``baud``
            # (found free there)
            self.link.heard_out({(baud, ident): "one", (was, ident): "none"})
        return baud


    def _roll_back_baud(self, ident: int, was: int, failed: CheckFailed) -> None:
        """A baud change whose actuator does not answer at the new rate: back at ``was``, where
        it answers still (its restart did not take), its stored baud-rate is written back, so it
        does not vanish at its next power-up. ``failed`` is told what was done
        (``rolled_back``: True, False where it does not answer at the old rate either)."""
        self.link.moved_to(ident, was)
        self.link.set_baud(was)
        failed.facts["rolled_back"] = failed.rolled_back = False
        try:
            if self.link.ping(ident, retries=2) is None:
                return
            self.link.store(ident, BAUD_REG, zap.BAUD_TO_CODE[was], allow=Permission.IDENTITY)
            if self.link.mode_of(ident) == 0 or self.link.read(ident, BAUD_REG) == zap.BAUD_TO_CODE[was]:
                failed.facts["rolled_back"] = failed.rolled_back = True
                failed.args = (f"{failed.args[0]}; it still answers at {was} baud: its baud-rate was set back "
                               f"to {was}",) + failed.args[1:]
        except (NoReply, BadReply):
            pass


    def baud_state(self, ident: int, rates: Iterable[int], *, ready_timeout: float = 1.0) -> dict[str, Any]:
        """Where actuator ``ident`` answers among ``rates`` (tried in order; after a baud change
        that failed: the old rate, then the new) and the rate it stores, read back, never
        assumed: ``{"answers_at": baud or None (at none of them), "stored_baud": the rate its
        baud-rate register names, "code": that raw code (both None when unread: return mode 0
        answers no read)}``. The port is left at the rate it answers at (else the first)."""
        ident = zap.check_id(ident, allow_broadcast=False)
        rates = list(dict.fromkeys(rates))
        for rate in rates:
            self.baud = rate
            try:
                self.link.wait_ready(ident, within=ready_timeout)
            except (NoReply, BadReply):
                continue
            try:
                code: Optional[int] = self.link.read(ident, BAUD_REG)
            except (NoReply, BadReply, UsageError):
                code = None
            return {"answers_at": rate, "stored_baud": zap.BAUD_CODES.get(code) if code is not None else None,
                    "code": code}
        if rates:
            self.baud = rates[0]
        return {"answers_at": None, "stored_baud": None, "code": None}


def _given(allow: AllowSpec, force: bool) -> Permission:
    """A call's permissions: ``allow``, and every FORCE permission with ``force``."""
    return as_permission(allow) | (FORCE if force else Permission.NONE)


def _attr_register(name: str) -> zap.Register:
    key = name.replace("_", "-")
    reg = zap.REGISTER_BY_NAME.get(key)
    if reg is None:
        names = [r.name.replace("-", "_") for r in zap.REGISTERS]
        raise AttributeError(f"no register {name!r}" + did_you_mean(name, names), name=name)
    return reg


class Actuator(_Registers):
    """One actuator on a :class:`Bus` (``bus[3]``): its registers read and write as attributes
    (``act.goal_position = 2000``; ``act.present_voltage`` -> ``12.0 V``), and the bus's
    instructions and procedures without the ID."""

    __slots__ = ("bus", "ident")

    def __init__(self, bus: Bus, ident: int) -> None:
        object.__setattr__(self, "bus", bus)
        object.__setattr__(self, "ident", ident)

    bus: Bus
    ident: int

    def __repr__(self) -> str:
        return f"Actuator(id={self.ident}, port={self.bus.url!r})"

    def __dir__(self) -> list[str]:
        return sorted(set(super().__dir__()) | {r.name.replace("-", "_") for r in zap.REGISTERS})

    if not TYPE_CHECKING:  # type checkers see the registers as attributes (_registers.pyi)
        def __getattr__(self, name: str) -> Union[Reading, int]:
            if name.startswith("_"):
                raise AttributeError(name)
            return self.bus.read(self.ident, _attr_register(name))

        def __setattr__(self, name: str, value: Union[int, Reading]) -> None:
            if name in Actuator.__slots__:
                raise AttributeError(f"{name} is fixed")
            self.bus.store(self.ident, _attr_register(name), value)

    def __getitem__(self, reg: RegisterSpec) -> Union[Reading, int]:
        return self.bus.read(self.ident, reg)

    def __setitem__(self, reg: RegisterSpec, value: Union[int, Reading]) -> None:
        self.bus.store(self.ident, reg, value)

    def echo(self) -> Reply:
        """Echo (see :meth:`Bus.echo`)."""
        return self.bus.echo(self.ident)

    if TYPE_CHECKING:
        @overload
        def load(self, reg: RegisterSpec, length: None = None) -> int: ...
        @overload
        def load(self, reg: RegisterSpec, length: int) -> Union[int, dict[str, int]]: ...

    def load(self, reg: RegisterSpec, length: Optional[int] = None) -> Union[int, dict[str, int]]:
        """Load Data (see :meth:`Bus.load`)."""
        return self.bus.load(self.ident, reg, length)

    def read(self, reg: RegisterSpec) -> Union[Reading, int]:
        """One register's value (see :meth:`Bus.read`)."""
        return self.bus.read(self.ident, reg)

    def store(self, reg: RegisterSpec, value: Union[int, Reading], *, force: bool = False,
              allow: AllowSpec = None) -> Optional[Reply]:
        """Store Data (see :meth:`Bus.store`)."""
        return self.bus.store(self.ident, reg, value, force=force, allow=allow)

    def send(self, reg: RegisterSpec, value: Union[int, Reading], *, force: bool = False,
             allow: AllowSpec = None) -> Optional[Reply]:
        """Send Data (see :meth:`Bus.send`)."""
        return self.bus.send(self.ident, reg, value, force=force, allow=allow)

    if TYPE_CHECKING:
        @overload
        def move(self, position: int, *, wait: Literal[True] = True, speed: Optional[int] = None,
                 timeout: float = 10.0, poll: float = 0.01,
                 on_progress: Optional[Callable[[int, int, int], None]] = None,
                 notify: Optional[Callable[[str], None]] = None, stop: bool = True) -> Moved: ...
        @overload
        def move(self, position: int, *, wait: Literal[False], speed: Optional[int] = None,
                 timeout: float = 10.0, poll: float = 0.01,
                 on_progress: Optional[Callable[[int, int, int], None]] = None,
                 notify: Optional[Callable[[str], None]] = None, stop: bool = True) -> None: ...
        @overload
        def move(self, position: int, *, wait: bool, speed: Optional[int] = None,
                 timeout: float = 10.0, poll: float = 0.01,
                 on_progress: Optional[Callable[[int, int, int], None]] = None,
                 notify: Optional[Callable[[str], None]] = None, stop: bool = True) -> Optional[Moved]: ...

    def move(self, position: int, **kw: Any) -> Optional[Moved]:
        """Move, waiting by default (see :meth:`Bus.move`)."""
        return self.bus.move(self.ident, position, **kw)

    def identify(self) -> Identity:
        """Model, firmware and return mode (see :meth:`Bus.identify`)."""
        return self.bus.identify(self.ident)

    def dump(self) -> list[RegisterRow]:
        """The whole register map (see :meth:`Bus.dump`)."""
        return self.bus.dump(self.ident)

    def restart(self) -> Optional[Reply]:
        """Restart (see :meth:`Bus.restart`)."""
        return self.bus.restart(self.ident)
