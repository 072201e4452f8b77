"""mightyZAP IR protocol: instructions, the 12Lf register map and the payload codec.

Packets: ``FF FF FF ID SIZE CMD P1..Pn CHK`` (command) and ``FF FF FF ID SIZE ERR P1..Pn CHK``
(feedback); SIZE = n + 2; CHK = 0xFF - ((ID + SIZE + CMD/ERR + P1..Pn) & 0xFF). ID 0..253,
254 is broadcast (never answered). Framing (header, SIZE, checksum) lives in
:mod:`zkzap.codec.framing`; this module knows what the bytes between SIZE and CHK mean.
The register map is :data:`REGISTERS`, declared once; names, CLI choices, ranges, help and
the ``zap registers`` table come from it.
"""

from __future__ import annotations

from ..errors import CHECK_FAILED, USAGE, CheckFailed, ZkzapError, unknown_name

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Iterable, Mapping, Optional, Sequence, Union

    from typing_extensions import TypeAlias

    from .permissions import Permission

    #: Bytes of a packet: bytes, a bytearray, a memoryview or a list of ints.
    Bytes: TypeAlias = Union[bytes, bytearray, memoryview, "list[int]"]
    #: A register: its name (``goal-position`` or ``goal_position``), its address or itself.
    RegisterSpec: TypeAlias = Union[str, int, "Register"]
    #: An actuator ID: 0..253, 254 or ``"broadcast"`` where a broadcast is allowed.
    Ident: TypeAlias = Union[int, str]
    #: A decoded record: a dict of JSON-ready values.
    Record: TypeAlias = dict[str, Any]
from .crc import zap_checksum
from .fields import FieldValueError
from .ids import id_ranges  # noqa: F401 - part of this module's interface
from .regmap import Register as Register, builtin  # Register: part of this module's interface

HEADER = b"\xff\xff\xff"
BROADCAST = 0xFE
MAX_ID = 253
MAX_SIZE = 255

ERROR_BITS = {5: "overload", 0: "input-voltage"}
ERROR_TEXT = {
    "overload": "overload: the load could not be held at the maximum force; force is cut until "
                "restart or power cycle",
    "input-voltage": "input voltage out of the operating range",
}


class Instruction:
    """One instruction. ``reply`` says when a non-broadcast command is answered:
    ``"always"`` (Echo), ``"load"`` (Load Data: return modes 1 and 2), ``"all"`` (mode 2 only),
    ``"unknown"`` (an undocumented vendor instruction: a reply may or may not come)."""

    def __init__(self, code: int, name: str, cli: str, help: str, reply: str, params_help: str = "",
                 documented: bool = True) -> None:
        self.code, self.name, self.cli, self.help, self.reply = code, name, cli, help, reply
        self.params_help = params_help
        self.documented = documented

    def answered(self, return_mode: int, target_id: int) -> bool:
        """Whether an actuator in ``return_mode`` replies to this instruction sent to ``target_id``
        (False for an undocumented one: nobody can promise a reply)."""
        if target_id == BROADCAST or self.reply == "unknown":
            return False
        if self.reply == "always":
            return True
        if self.reply == "load":
            return return_mode >= 1
        return return_mode >= 2


#: Instruction codes by name (the byte after SIZE in a command packet).
ECHO = 0xF1
LOAD_DATA = 0xF2
STORE_DATA = 0xF3
SEND_DATA = 0xF4
EXECUTION = 0xF5
FACTORY_RESET = 0xF6
RESTART = 0xF8
SYMMETRIC_STORE = 0x73
#: IR Robot's undocumented system write (their Python library's factory reset) and bulk write.
SYSTEM_WRITE = 0xF9
BULK_WRITE = 0x93
#: Instructions that write a register block: ``address, data...``.
WRITE_CODES = frozenset((STORE_DATA, SEND_DATA))
#: Instructions after which the actuator restarts (and is deaf for a moment).
RESTART_CODES = frozenset((FACTORY_RESET, RESTART))

INSTRUCTIONS = (
    Instruction(ECHO, "Echo", "echo", "Ask for a feedback packet (connection check).", "always"),
    Instruction(LOAD_DATA, "Load Data", "load", "Read LENGTH bytes from ADDRESS.", "load", "address, length"),
    Instruction(STORE_DATA, "Store Data", "store", "Write data at ADDRESS.", "all", "address, data..."),
    Instruction(SEND_DATA, "Send Data", "send", "Stage data at ADDRESS, applied by Execution.", "all",
                "address, data..."),
    Instruction(EXECUTION, "Execution", "execute", "Apply the data staged by Send Data.", "all"),
    Instruction(FACTORY_RESET, "Factory Reset", "factory-reset", "Restore factory settings.", "all",
                "option (bit0 ID, bit1 baud rate)"),
    Instruction(RESTART, "Restart", "restart", "Restart the actuator.", "all"),
    Instruction(SYMMETRIC_STORE, "Symmetric Store", "sync-move", "Write the same address of several actuators.",
                "all", "address, length, {id, data x length}..."),
)
#: Instruction codes IR Robot's own Arduino header (utility/IR_Protocol_format.h, Dynamixel
#: heritage) defines beyond the eight documented ones. None is documented for the 12Lf: they are
#: decoded by these names (never as feedback error bits) and sent only raw (``zap raw``).
VENDOR_INSTRUCTIONS = (
    Instruction(0xF9, "System Write", "system-write",
                "CMD_SYSTEM_WRITE / CMD_FACTORY_MODE; IR Robot's Python library sends FF FF FF ID 03 F9 01 "
                "as its factory reset.", "unknown", "option", documented=False),
    Instruction(0x55, "Status", "status", "Dynamixel-style status (undocumented).", "unknown", documented=False),
    Instruction(0x82, "Sync Read", "sync-read", "Dynamixel-style sync read (undocumented).", "unknown",
                documented=False),
    Instruction(0x92, "Bulk Read", "bulk-read", "Dynamixel-style bulk read (undocumented).", "unknown",
                documented=False),
    Instruction(0x93, "Bulk Write", "bulk-write", "Dynamixel-style bulk write (undocumented).", "unknown",
                documented=False),
)
INSTRUCTION_BY_CODE = {i.code: i for i in INSTRUCTIONS + VENDOR_INSTRUCTIONS}
INSTRUCTION_BY_NAME = {i.cli: i for i in INSTRUCTIONS + VENDOR_INSTRUCTIONS}
INSTRUCTION_BY_NAME.update({i.name.lower().replace(" ", "-"): i for i in INSTRUCTIONS})
INSTRUCTION_BY_NAME["symmetric-store"] = INSTRUCTION_BY_NAME["sync-move"]
INSTRUCTION_BY_NAME["send-data"] = INSTRUCTION_BY_NAME["send"]
INSTRUCTION_BY_NAME["execution"] = INSTRUCTION_BY_NAME["execute"]
INSTRUCTION_BY_NAME["factory-mode"] = INSTRUCTION_BY_NAME["system-write"]




#: The alarm bits of alarm-led and alarm-shutdown: the error bits of a feedback packet.
ALARM_BITS = {0: "input voltage", 5: "overload"}
#: The 12Lf data map (firmware >= 2.0), read from its description (``maps/12lf-ir.map``, the
#: format of :mod:`zkzap.codec.regmap`). NV = stored, survives power off; V = volatile.
MAP = builtin("12lf-ir")
REGISTERS = MAP.registers
REGISTER_BY_NAME = {r.name: r for r in REGISTERS}
REGISTER_BY_ADDRESS = {r.address: r for r in REGISTERS}
#: Baud-rate codes (the baud-rate register's choices) -> bit/s.
BAUD_CODES = MAP.baud_codes
BAUD_TO_CODE = {v: k for k, v in BAUD_CODES.items()}

#: Addresses IR Robot's Arduino header names but the 12Lf map does not document: readable by
#: name or address, shown raw (no unit, no range), never part of the map (``zap dump``).
UNDOCUMENTED_REGISTERS = (
    Register(0x93, "present-temperature", 1, "R", help="undocumented (IR Robot's Arduino header); raw value",
             documented=False),
    Register(0x94, "registered-instruction", 1, "R", help="undocumented (IR Robot's Arduino header); raw value",
             documented=False),
    # IR Robot's Arduino library writes it (Lock()): writable, with the UNDOCUMENTED permission
    Register(0x97, "lock", 1, "RW V", help="undocumented (IR Robot's Arduino header: Lock() writes it); raw value",
             documented=False),
)
UNDOCUMENTED_BY_NAME = {r.name: r for r in UNDOCUMENTED_REGISTERS}
UNDOCUMENTED_BY_ADDRESS = {r.address: r for r in UNDOCUMENTED_REGISTERS}
#: The register each address belongs to (every byte of a multi-byte register), named or not.
OWNER = {a: r for r in REGISTERS + UNDOCUMENTED_REGISTERS for a in range(r.address, r.address + r.size)}
#: The stored (EEPROM) part of the address space: every NV register of the map lies below 0x80
#: and every volatile one from 0x80 (the Dynamixel layout IR Robot's header follows), so an
#: undocumented address below 0x80 is taken to be stored memory.
STORED_RANGE = range(0x00, 0x80)
#: Registers that decide where or how an actuator answers (the IDENTITY permission).
IDENTITY_REGISTERS = MAP.identity


def register(spec: RegisterSpec) -> Register:
    """A register by kebab-case name, or by address (``0x86``, ``134``). An address outside the
    map gives an anonymous one-byte read/write register so raw access stays possible."""
    if isinstance(spec, Register):
        return spec
    if isinstance(spec, str):
        key = spec.strip().lower().replace("_", "-")
        if key in REGISTER_BY_NAME:
            return REGISTER_BY_NAME[key]
        if key in UNDOCUMENTED_BY_NAME:
            return UNDOCUMENTED_BY_NAME[key]
        try:
            addr = int(key, 0)
        except ValueError:
            raise unknown_name("register", spec, [*REGISTER_BY_NAME, *UNDOCUMENTED_BY_NAME], otherwise="",
                               cls=FieldValueError, field="register") from None
    else:
        addr = spec
    if not 0 <= addr <= 0xFF:
        raise FieldValueError(f"register: address {addr} is out of range; allowed 0x00..0xFF")
    reg = REGISTER_BY_ADDRESS.get(addr) or UNDOCUMENTED_BY_ADDRESS.get(addr)
    if reg is None:
        owner = OWNER.get(addr)
        if owner is not None:          # inside a multi-byte register: one of its bytes, raw
            reg = Register(addr, f"0x{addr:02x}", 1, "RW " + (owner.memory or "V"),
                           help=f"byte {addr - owner.address} of {owner.name}", documented=False)
        else:
            reg = Register(addr, f"0x{addr:02x}", 1, "RW NV" if addr in STORED_RANGE else "RW V",
                           help="not in the 12Lf map", documented=False)
    return reg


def check_id(value: Ident, *, allow_broadcast: bool = True) -> int:
    """An actuator ID as an int (``"broadcast"`` is 254 where allowed); FieldValueError otherwise."""
    if isinstance(value, str):
        v = value.strip().lower()
        if v in ("broadcast", "all", "bc"):
            if allow_broadcast:
                return BROADCAST
            raise FieldValueError("id: broadcast is not allowed here; allowed 0..253")
        try:
            value = int(v, 0)
        except ValueError:
            raise FieldValueError(f"id: {value!r} is not a number; allowed 0..253"
                                  f"{', 254 or broadcast' if allow_broadcast else ''}") from None
    top = BROADCAST if allow_broadcast else MAX_ID
    if not isinstance(value, int) or not 0 <= value <= top:
        raise FieldValueError(f"id: {value} is out of range; allowed 0..253"
                              f"{', 254 or broadcast' if allow_broadcast else ''}")
    return value


# --- packets -----------------------------------------------------------------------------------

def packet(ident: int, code: int, params: Bytes = b"") -> bytes:
    """``FF FF FF ID SIZE CODE params CHK`` for a command (CODE = instruction) or feedback (error)."""
    params = bytes(params)
    size = len(params) + 2
    if size > MAX_SIZE:
        raise FieldValueError(f"params: {len(params)} bytes do not fit one packet; at most {MAX_SIZE - 2}")
    body = bytes((ident, size, code)) + params
    return HEADER + body + bytes((zap_checksum(body),))


def _id(ident):
    return check_id(ident)


def echo(ident: Ident = 0) -> bytes:
    """Echo: ask an actuator to answer (any return mode)."""
    return packet(_id(ident), ECHO)


def load(ident: Ident, reg: RegisterSpec, length: Optional[int] = None) -> bytes:
    """Load Data: read ``length`` bytes (default: the register's size) from ``reg``."""
    reg = register(reg)
    length = reg.size if length is None else length
    if not isinstance(length, int) or not 1 <= length <= 0xFF:
        raise FieldValueError(f"length: {length} is out of range; allowed 1..255")
    return packet(_id(ident), LOAD_DATA, bytes((reg.address, length)))


def _write(code, ident, reg, value, *, force=False):
    reg = register(reg)
    if not reg.writable and not force:
        raise FieldValueError(f"{reg.name}: read-only register (0x{reg.address:02X}); it cannot be written")
    reg.check(value)
    return packet(_id(ident), code, bytes((reg.address,)) + reg.to_bytes(value))


def store(ident: Ident, reg: RegisterSpec, value: int, *, force: bool = False) -> bytes:
    """Store Data: write ``value`` (raw, in the register's units) little-endian in its size."""
    return _write(STORE_DATA, ident, reg, value, force=force)


def send_data(ident: Ident, reg: RegisterSpec, value: int, *, force: bool = False) -> bytes:
    """Send Data: stage a write, applied by :func:`execute`."""
    return _write(SEND_DATA, ident, reg, value, force=force)


def execute(ident: Ident = BROADCAST) -> bytes:
    """Execution: apply the writes staged by Send Data (default: every actuator)."""
    return packet(_id(ident), EXECUTION)


def factory_reset(ident: Ident, reset_id: bool = False, reset_baud: bool = False) -> bytes:
    """Factory Reset: restore factory settings, also the ID (to 0) and baud rate (57600) if asked."""
    return packet(_id(ident), FACTORY_RESET, bytes(((1 if reset_id else 0) | (2 if reset_baud else 0),)))


def restart(ident: Ident) -> bytes:
    """Restart the actuator."""
    return packet(_id(ident), RESTART)


def symmetric_store(reg: RegisterSpec, targets: Union[Mapping[int, int], Iterable[tuple[int, int]]]) -> list[bytes]:
    """Symmetric Store to broadcast: ``targets`` maps ID -> value (or is a list of pairs).

    SIZE is one byte, so one packet carries at most ``(255 - 4) // (1 + length)`` actuators;
    more targets are split over as many packets as needed, in the given order.
    """
    reg = register(reg)
    if not reg.writable:
        raise FieldValueError(f"{reg.name}: read-only register (0x{reg.address:02X}); it cannot be written")
    items = list(targets.items() if isinstance(targets, dict) else targets)
    if not items:
        raise FieldValueError("targets: none given; expected ID:VALUE pairs")
    seen = set()
    for ident, value in items:
        check_id(ident, allow_broadcast=False)
        if ident in seen:
            raise FieldValueError(f"id: {ident} is given twice")
        seen.add(ident)
        reg.check(value)
    per = (MAX_SIZE - 4) // (1 + reg.size)
    out = []
    for start in range(0, len(items), per):
        chunk = items[start:start + per]
        params = bytearray((reg.address, reg.size))
        for ident, value in chunk:
            params.append(ident)
            params += reg.to_bytes(value)
        out.append(packet(BROADCAST, SYMMETRIC_STORE, params))
    return out


def max_per_packet(length: int) -> int:
    """Actuators one Symmetric Store packet carries for a register block of ``length`` bytes."""
    return (MAX_SIZE - 4) // (1 + length)


# --- command packets as objects ----------------------------------------------------------------

class Command:
    """A command packet (host -> actuators) and what it means, answered here once.

    ``ident`` (the target ID, 254 broadcast), ``code`` (the instruction byte), ``instruction``
    (the :class:`Instruction`, None for an undocumented code), ``params`` (parameter bytes),
    ``packet`` (the whole packet). For Store/Send Data ``address`` and ``data``; for Load Data
    ``address`` and ``length``; for Symmetric Store ``address``, ``length`` and ``targets``
    (``[(id, data bytes), ...]``, the body parsed once; None when malformed).
    """

    __slots__ = ("packet", "ident", "code", "instruction", "params", "address", "length", "data", "targets")
    packet: bytes
    ident: int
    code: int
    instruction: Optional[Instruction]
    params: bytes
    address: Optional[int]
    length: Optional[int]
    data: Optional[bytes]
    targets: Optional[list[tuple[int, bytes]]]

    def __init__(self, pkt: Bytes) -> None:
        pkt = bytes(pkt)
        self.packet = pkt
        self.ident = pkt[3]
        self.code = pkt[5]
        self.instruction = INSTRUCTION_BY_CODE.get(self.code)
        self.params = params = pkt[6:-1]
        self.address = self.length = self.data = self.targets = None
        code = self.code
        if code == LOAD_DATA and len(params) == 2:
            self.address, self.length = params[0], params[1]
        elif code in WRITE_CODES and len(params) >= 2:
            self.address, self.data = params[0], params[1:]
            self.length = len(self.data)
        elif code == SYMMETRIC_STORE and len(params) >= 2:
            self.address, self.length = params[0], params[1]
            body, step = params[2:], 1 + params[1]
            if params[1] and len(body) % step == 0:
                self.targets = [(body[j], body[j + 1:j + step]) for j in range(0, len(body), step)]

    def __repr__(self) -> str:
        name = self.instruction.cli if self.instruction else f"0x{self.code:02X}"
        return f"Command({name}, id={self.ident}, params={self.params.hex(' ')})"

    @property
    def broadcast(self) -> bool:
        """Sent to every actuator (ID 254): never answered."""
        return self.ident == BROADCAST

    @property
    def restarts(self) -> bool:
        """Restart or Factory Reset: the actuator restarts afterwards."""
        return self.code in RESTART_CODES

    def expects_reply(self, return_mode: int) -> bool:
        """Whether an actuator in feedback-return-mode ``return_mode`` answers this command."""
        return self.instruction is not None and self.instruction.answered(return_mode, self.ident)

    @property
    def reply_data_length(self) -> Optional[int]:
        """Data bytes the reply carries: Load Data's length, 0 for other documented
        instructions, None for an undocumented code."""
        if self.code == LOAD_DATA:
            return self.length
        return 0 if self.instruction is not None else None

    def writes(self) -> list[tuple[Optional[int], bytes]]:
        """``[(address, data bytes), ...]``: the register blocks this command writes (one per
        target for Symmetric Store)."""
        if self.code in WRITE_CODES and self.data is not None:
            return [(self.address, self.data)]
        if self.code == SYMMETRIC_STORE and self.targets:
            return [(self.address, d) for _, d in self.targets]
        return []

    @property
    def stored_writes(self) -> list[str]:
        """Names of the stored (NV) settings this command writes (consent, memory pauses)."""
        if self.code in (FACTORY_RESET, SYSTEM_WRITE):
            return ["every stored setting (factory reset)"]
        names = []
        span = None
        if self.code in WRITE_CODES and self.data is not None:
            span = (self.address, len(self.data))
        elif self.code == SYMMETRIC_STORE and self.length is not None:
            span = (self.address, self.length)
        if span:
            for addr in range(span[0], min(span[0] + span[1], 256)):
                reg = OWNER.get(addr)
                if reg is not None and reg.stored:
                    name = reg.name
                elif reg is None and addr in STORED_RANGE:
                    name = f"0x{addr:02x}"
                else:
                    continue
                if name not in names:
                    names.append(name)
        return names

    def written_value(self, reg: RegisterSpec) -> list[int]:
        """The values this command writes to ``reg`` (one per target), or ``[]``."""
        reg = register(reg)
        out = []
        for addr, data in self.writes():
            offset = reg.address - addr
            if 0 <= offset and offset + reg.size <= len(data):
                out.append(int.from_bytes(data[offset:offset + reg.size], "little"))
            elif 0 <= offset < len(data):
                out.append(data[offset])
        return out

    def describe(self) -> str:
        """One human line: ``store goal-position=2047 to ID 1``."""
        to = "every actuator (broadcast)" if self.broadcast else f"ID {self.ident}"
        if self.instruction is None:
            return f"instruction 0x{self.code:02X} ({len(self.params)} parameter bytes) to {to}"
        rec = decode_packet(self.packet)
        what = rec["instruction"]
        if "value" in rec:
            what += f" {rec['register']}={rec['value']}"
        elif "values" in rec:
            what += " " + " ".join(f"{k}={v}" for k, v in rec["values"].items())
        elif "targets" in rec:
            what += f" {rec['register']} " + " ".join(f"{k}:{v}" for k, v in rec["targets"].items())
        elif what == "load" and "register" in rec:
            what += f" {rec['register']} ({rec['length']} bytes)"
        elif what == "factory-reset" and "reset_id" in rec:
            what += (" (ID too)" if rec["reset_id"] else "") + (" (baud rate too)" if rec["reset_baud"] else "")
        elif self.params:
            what += " " + self.params.hex(" ").upper()
        return f"{what} to {to}"

    def blocks(self) -> list[tuple[int, int, bytes]]:
        """``[(ident, address, data bytes), ...]``: what this command writes where (one entry
        per target for Symmetric Store; an empty list for a command that writes no register)."""
        if self.code in WRITE_CODES and self.data is not None:
            return [(self.ident, self.address, self.data)]
        if self.code == SYMMETRIC_STORE and self.targets:
            return [(i, self.address, d) for i, d in self.targets]
        return []

    def needs(self) -> dict[Permission, str]:
        """``{Permission: reason}``: what sending this command needs (see
        :mod:`zkzap.codec.permissions`); ``{}`` for a harmless one (Echo, Load Data, a goal
        position). Decided here once, from the register table and the instruction table."""
        from .permissions import Permission as P

        out = {}

        def need(p, why):
            if p not in out:
                out[p] = why

        code = self.code
        if code == FACTORY_RESET:
            need(P.FACTORY, "factory reset: every stored setting is overwritten")
            flags = self.params[0] if self.params else 0
            if flags & 3:
                moved = " and ".join(w for bit, w in ((1, "to ID 0"), (2, "at 57600 baud")) if flags & bit)
                need(P.IDENTITY, f"factory reset of the {'ID' if flags & 1 else ''}"
                                 f"{' and ' if flags & 3 == 3 else ''}{'baud rate' if flags & 2 else ''}: "
                                 f"the actuator then answers {moved} only")
        elif code == SYSTEM_WRITE:
            need(P.FACTORY, "system write (0xF9): IR Robot's library sends it as a factory reset")
        elif self.instruction is None:
            need(P.UNDOCUMENTED, f"instruction 0x{code:02X} is not a mightyZAP instruction")
        elif not self.instruction.documented:
            need(P.UNDOCUMENTED, f"{self.instruction.cli} (0x{code:02X}) is not documented for the 12Lf")
            if code == BULK_WRITE:
                need(P.STORED, "bulk-write may write stored settings")
        elif code in WRITE_CODES or code == SYMMETRIC_STORE:
            blocks = self.blocks()
            if not blocks:
                need(P.UNDOCUMENTED, "a write whose parameters are not an address and data")
            for _, addr, data in blocks:
                for p, why in _block_needs(addr, data):
                    need(p, why)
        if self.broadcast and code != SYMMETRIC_STORE and out:
            need(P.BROADCAST, "sent to every actuator at once (broadcast ID 254)")
        return out

    @property
    def permissions(self) -> Permission:
        """The :class:`~zkzap.codec.permissions.Permission` flags sending this command needs."""
        from .permissions import Permission

        out = Permission.NONE
        for p in self.needs():
            out |= p
        return out

    @property
    def leaves_protocol(self) -> bool:
        """True when it writes 0 (Modbus RTU) to protocol-type: the actuator would leave this
        protocol and no longer answer it."""
        return 0 in self.written_value(REGISTER_BY_NAME["protocol-type"])

    def target_ids(self) -> list[int]:
        """The actuator IDs this command addresses (Symmetric Store: its targets)."""
        if self.code == SYMMETRIC_STORE and self.targets:
            return [i for i, _ in self.targets]
        return [] if self.broadcast else [self.ident]


_IDENTITY_WHY = {
    "id": lambda v: f"writes id {v}: the actuator then answers to ID {v} (unchecked: another may have it)",
    "baud-rate": lambda v: f"writes baud-rate {v}: after its next restart the actuator answers at "
                           f"{BAUD_CODES.get(v, 'another')} baud only",
    "protocol-type": lambda v: ("writes protocol-type 0: the actuator switches to Modbus RTU and no longer answers "
                                "this protocol" if v == 0 else f"writes protocol-type {v}: it decides which protocol "
                                                               "the actuator answers"),
}


def silencing_why(reg: Register, value: int) -> str:
    """Why writing ``value`` to ``reg`` (one of its :attr:`~zkzap.codec.regmap.Register.silencing`
    values) needs the SILENCING permission, in words."""
    meaning = reg.choices.get(value) if reg.choices else None
    return (f"writes {reg.name} {value}" + (f" ({meaning})" if meaning else "") +
            ": the actuator then no longer answers a read (nothing can confirm the write, and only a write "
            "back or a factory reset brings its answers back)")


def _block_needs(address: int, data: bytes):
    """``[(Permission, reason)]`` for writing ``data`` at ``address``: stored memory, identity
    registers, bytes the map does not document, registers written in part, values outside a
    register's documented domain."""
    from .permissions import Permission as P

    out = []
    end = address + len(data)
    a = address
    while a < end:
        if a > 0xFF:
            out.append((P.UNDOCUMENTED, "the data runs past address 0xFF"))
            break
        reg = OWNER.get(a)
        if reg is None:
            name = f"0x{a:02X}"
            out.append((P.UNDOCUMENTED, f"writes {name}, which the 12Lf map does not document"))
            if a in STORED_RANGE:
                out.append((P.STORED, f"writes {name}, in the stored (NV) part of the map"))
            a += 1
            continue
        first, last = reg.address, reg.address + reg.size
        if first < address or last > end:
            span = f"0x{first:02X}" if reg.size == 1 else f"0x{first:02X}..0x{last - 1:02X}"
            out.append((P.PARTIAL, f"writes {min(last, end) - max(first, address)} of the {reg.size} bytes of "
                                   f"{reg.name} ({span})"))
        elif not reg.allows(int.from_bytes(data[first - address:last - address], "little")):
            value = int.from_bytes(data[first - address:last - address], "little")
            out.append((P.UNDOCUMENTED, f"{reg.name} {value} is outside its documented values "
                                        f"({reg.describe_range()})"))
        if not reg.documented:
            out.append((P.UNDOCUMENTED, f"writes {reg.name} (0x{first:02X}), which the 12Lf map does not document"))
        elif not reg.writable:
            out.append((P.UNDOCUMENTED, f"writes {reg.name}, a read-only register"))
        if reg.stored or (not reg.documented and first in STORED_RANGE):
            out.append((P.STORED, f"writes {reg.name}, a stored setting (it survives power-off)"))
        if reg.name in IDENTITY_REGISTERS:
            value = int.from_bytes(data[max(first, address) - address:min(last, end) - address], "little")
            out.append((P.IDENTITY, _IDENTITY_WHY[reg.name](value)))
        if reg.silencing and first >= address and last <= end:
            value = int.from_bytes(data[first - address:last - address], "little")
            if value in reg.silencing:
                out.append((P.SILENCING, silencing_why(reg, value)))
        a = last
    return out


# --- decoding ----------------------------------------------------------------------------------

class PacketError(ZkzapError, ValueError):
    """A malformed packet: bad input (exit 2), also a ``ValueError``."""

    code = USAGE


class ChecksumError(PacketError, CheckFailed):
    """A packet whose checksum does not match: a failed check (exit 1), with the ``expected``
    and ``found`` checksum bytes."""

    code = CHECK_FAILED

    def __init__(self, message: str, expected: int, found: int) -> None:
        super().__init__(message, expected=expected, found=found)


def check_packet(pkt: Bytes) -> None:
    """Raise :class:`PacketError`/:class:`ChecksumError` unless ``pkt`` is one whole packet."""
    n = len(pkt)
    if n < 7 or pkt[:3] != HEADER:
        raise PacketError(f"mightyZAP packet: {n} bytes starting {bytes(pkt[:3]).hex(' ').upper() or '(none)'}; "
                          "a packet starts FF FF FF and has at least 7 bytes")
    size = pkt[4]
    if pkt[3] == 0xFF:
        raise PacketError("mightyZAP packet: ID FF is not allowed; allowed 0..254")
    if size < 2 or n != size + 5:
        raise PacketError(f"mightyZAP packet: SIZE {size} says {size + 5} bytes, got {n}")
    expected = zap_checksum(pkt[3:-1])
    if expected != pkt[-1]:
        raise ChecksumError(f"mightyZAP packet: checksum mismatch: expected {expected:02X}, "
                            f"found {pkt[-1]:02X}", expected, pkt[-1])


def is_command(code: int) -> bool:
    """The byte after SIZE tells command from feedback: instruction codes (documented and
    vendor) vs. error bits."""
    return code in INSTRUCTION_BY_CODE


#: Every error bit the protocol documents.
ERROR_MASK = sum(1 << bit for bit in ERROR_BITS)


def packet_kind(code: int) -> str:
    """``command`` (an instruction code), ``feedback`` (documented error bits only) or
    ``unknown`` (neither: an undocumented instruction or undocumented error bits)."""
    if code in INSTRUCTION_BY_CODE:
        return "command"
    return "feedback" if not code & ~ERROR_MASK else "unknown"


def error_names(err: int) -> list[str]:
    """The names of the error bits set in ``err`` (undocumented bits as ``undocumented-0x..``)."""
    names = [name for bit, name in ERROR_BITS.items() if err & (1 << bit)]
    other = err & ~0x21
    if other:
        names.append(f"undocumented-0x{other:02x}")
    return names


def _register_values(address: int, data: bytes) -> list:
    """Split ``data`` read from/written to ``address`` into named register values."""
    out = []
    i = 0
    while i < len(data):
        addr = address + i
        reg = REGISTER_BY_ADDRESS.get(addr) or UNDOCUMENTED_BY_ADDRESS.get(addr)
        if reg is not None and i + reg.size <= len(data):
            raw = int.from_bytes(data[i:i + reg.size], "little")
            out.append((reg, raw))
            i += reg.size
        else:
            # outside the map (or past 0xFF), or a register cut short: one raw byte, named by address
            name = f"0x{addr:02x}" if reg is None else f"{reg.name}(partial)"
            out.append((Register(addr, name, 1, "RW"), data[i]))
            i += 1
    return out


def _with_register(rec, address, data):
    values = _register_values(address, data)
    rec["address"] = address
    if len(values) == 1:
        reg, raw = values[0]
        rec["register"] = reg.name
        rec["value"] = raw
        if reg.scale != 1:
            rec["physical"] = reg.physical(raw)
            rec["unit"] = reg.unit
    else:
        rec["register"] = ",".join(r.name for r, _ in values)
        rec["values"] = {r.name: v for r, v in values}


def decode_packet(pkt: Bytes, request: Optional[Bytes] = None) -> Record:
    """Decode a checked packet into a record.

    ``request`` is the Load Data command this feedback answers (when known, e.g. paired in a
    capture), so its data can be named by register.
    """
    ident, code = pkt[3], pkt[5]
    params = bytes(pkt[6:-1])
    rec = {"kind": packet_kind(code), "id": ident}
    if rec["kind"] == "unknown":
        # neither an instruction nor documented error bits: the byte is shown, not interpreted
        rec["code"] = code
        rec["params"] = params.hex(" ").upper()
    elif rec["kind"] == "command":
        cmd = Command(pkt)
        rec["instruction"] = cmd.instruction.cli
        rec["code"] = code
        rec["params"] = params.hex(" ").upper()
        if not cmd.instruction.documented:
            rec["documented"] = False
        if code == LOAD_DATA and cmd.address is not None:
            reg = REGISTER_BY_ADDRESS.get(cmd.address)
            rec["address"] = cmd.address
            rec["register"] = reg.name if reg else f"0x{cmd.address:02x}"
            rec["length"] = cmd.length
        elif code in WRITE_CODES and cmd.data is not None:
            _with_register(rec, cmd.address, cmd.data)
        elif code == FACTORY_RESET and len(params) == 1:
            rec["reset_id"] = bool(params[0] & 1)
            rec["reset_baud"] = bool(params[0] & 2)
        elif code == SYMMETRIC_STORE and cmd.address is not None:
            reg = REGISTER_BY_ADDRESS.get(cmd.address)
            rec["address"] = cmd.address
            rec["register"] = reg.name if reg else f"0x{cmd.address:02x}"
            rec["length"] = cmd.length
            if cmd.targets is not None:
                rec["targets"] = {str(i): int.from_bytes(d, "little") for i, d in cmd.targets}
            else:
                rec["malformed"] = f"{len(params) - 2} data bytes are not a multiple of {1 + cmd.length}"
    else:
        rec["error"] = code
        rec["errors"] = error_names(code)
        rec["params"] = params.hex(" ").upper()
        if request is not None and params and request[5] == LOAD_DATA and len(request) == 9:
            _with_register(rec, request[6], params)
        elif len(params) in (1, 2) and request is None:
            rec["value"] = int.from_bytes(params, "little")
    return rec


class ZapDecoder:
    """Stateful record decoder: pairs each feedback with the last Load Data sent to its ID, so
    feedback data from a capture of both directions is named by register."""

    def __init__(self) -> None:
        self.pending: dict[int, bytes] = {}

    def decode(self, pkt: Bytes) -> Record:
        """The record of one checked packet (a feedback named by the Load Data it answers)."""
        ident, code = pkt[3], pkt[5]
        if is_command(code):
            if code == LOAD_DATA:
                self.pending[ident] = bytes(pkt)
            else:
                self.pending.pop(ident, None)
            return decode_packet(pkt)
        req = self.pending.pop(ident, None)
        return decode_packet(pkt, req)


ZAP_KEYS = ("kind", "id", "instruction", "code", "documented", "error", "errors", "register", "address",
            "length", "value", "physical", "unit", "values", "targets", "reset_id", "reset_baud", "params")


def parse_id_list(text: "str | int", what: str = "--ids") -> "list[int]":
    """Actuator IDs like ``0-253`` or ``1,2,5-8`` (no broadcast), in the order given, each once.
    FieldValueError names ``what`` and the part that is wrong."""
    out = []
    for part in str(text).replace(" ", ",").split(","):
        if not part:
            continue
        lo, dash, hi = part.partition("-")
        if not lo and hi.isdigit():
            raise FieldValueError(f"{what}: {part} is out of range; allowed 0..253 (a range is written like 1-4)")
        if dash and not (lo and hi):
            raise FieldValueError(f"{what}: {part!r}: a range needs both ends, like 1-4")
        try:
            first = check_id(lo, allow_broadcast=False)
            last = check_id(hi, allow_broadcast=False) if dash else first
        except FieldValueError as e:
            raise FieldValueError(f"{what}: {part!r}: {e}") from None
        if last < first:
            raise FieldValueError(f"{what}: {part!r} runs backwards; write {last}-{first}")
        out.extend(i for i in range(first, last + 1) if i not in out)
    if not out:
        raise FieldValueError(f"{what}: none given; expected a list like 0-253 or 1,2,5-8")
    return out
