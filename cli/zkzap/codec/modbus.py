"""mightyZAP over Modbus RTU (the 17Lf): frames, exception replies and the typed request.

A frame is ``ID | function | data ... | CRC lo | CRC hi`` (CRC-16/MODBUS over everything before
it, low byte first), at most 256 bytes. ID 0 is broadcast (never answered), 1..247 unicast. The
actuator knows three functions: 0x03 Read Holding Registers (1..125 registers), 0x06 Write Single
Register (answered by an echo of the request) and 0x10 Write Multiple Registers (1..123,
answered by ``ID 10 start quantity``). Every register is 16 bits, big-endian. A request the
actuator refuses is answered ``ID function+0x80 code``: an :class:`ExceptionReply`, a named
error (code and meaning), never a value.

What a frame means and what it needs is answered once, on :class:`Request` (which reply it
expects, its length, the permissions sending it needs against a register map), and a reply is
judged against the request it answers by :func:`parse_reply`: another ID, another function, a
short frame or a bad CRC are named (:class:`ReplyMismatch`), never a value.
"""

from __future__ import annotations

from ..errors import CHECK_FAILED, USAGE, BadReply, CheckFailed, DeviceError, ZkzapError
from .crc import crc16_modbus
from .fields import FieldValueError

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Iterable, Mapping, Optional, Sequence, Union

    from .permissions import Permission
    from .regmap import Register, RegisterMap

READ_HOLDING = 0x03
WRITE_SINGLE = 0x06
WRITE_MULTIPLE = 0x10
BROADCAST = 0
MAX_ID = 247
#: The 17Lf control table's text gives unicast IDs 1..243; Modbus allows up to 247.
TABLE_MAX_ID = 243
MAX_READ = 125
MAX_WRITE = 123
MAX_FRAME = 256
EXCEPTION_BIT = 0x80

#: Bits of one character on the line, as Modbus RTU counts it (start, 8 data, parity or a second
#: stop bit, stop).
CHAR_BITS = 11


def silence(baud: int) -> float:
    """The silence that separates two frames (seconds): 3.5 characters of 11 bits, and 1.75 ms
    above 19200 baud (the Modbus serial line guide's fixed value for fast lines)."""
    return 0.00175 if baud > 19200 else 3.5 * CHAR_BITS / baud


#: Function code -> (name on the command line, Modbus name).
FUNCTIONS = {
    READ_HOLDING: ("read", "Read Holding Registers"),
    WRITE_SINGLE: ("write", "Write Single Register"),
    WRITE_MULTIPLE: ("write-multiple", "Write Multiple Registers"),
}

#: Exception code -> (name, meaning). The mightyZAP manual's readings are in brackets.
EXCEPTIONS = {
    0x01: ("illegal-function", "illegal function: the actuator does not know this function code"),
    0x02: ("illegal-data-address", "illegal data address: no such register, or a block past the table"),
    0x03: ("illegal-data-value", "illegal data value: a value or register count it does not take"),
    0x04: ("slave-device-failure", "slave device failure (the manual: a parameter out of range)"),
    0x05: ("acknowledge", "acknowledge (the manual: data not ready)"),
    0x06: ("slave-device-busy", "slave device busy (the manual: parameters locked)"),
}


def exception_name(code: int) -> str:
    """The name of exception ``code`` (``undocumented-0x0b`` for a code the list lacks)."""
    return EXCEPTIONS[code][0] if code in EXCEPTIONS else f"undocumented-0x{code:02x}"


def exception_meaning(code: int) -> str:
    return EXCEPTIONS[code][1] if code in EXCEPTIONS else f"exception code 0x{code:02X} (not documented)"


# --- errors --------------------------------------------------------------------------------------

class ModbusFrameError(ZkzapError, ValueError):
    """A malformed Modbus RTU frame: bad input (exit 2), also a ``ValueError``."""

    code = USAGE


class ModbusCrcError(ModbusFrameError, CheckFailed):
    """A frame whose CRC-16 does not match (exit 1): facts ``expected`` and ``found`` (the
    16-bit CRC values, low byte first on the wire)."""

    code = CHECK_FAILED

    def __init__(self, message: str, expected: int, found: int) -> None:
        super().__init__(message, expected=expected, found=found)


class ExceptionReply(DeviceError):
    """The actuator refused a request with a Modbus exception reply (exit 5). Facts: ``id``,
    ``function`` (the request's), ``exception`` (the code), ``name`` and ``meaning``."""

    def __init__(self, ident: int, function: int, code: int) -> None:
        super().__init__(f"actuator {ident}: exception {code} ({exception_name(code)}) to "
                         f"{FUNCTIONS.get(function, ('function 0x%02X' % function,))[0]}: {exception_meaning(code)}",
                         id=ident, function=function, exception=code, name=exception_name(code),
                         meaning=exception_meaning(code))


class ReplyMismatch(BadReply):
    """A frame that is not the reply to the request (exit 6): ``kind`` names why, one of
    :data:`MISMATCH_KINDS` (``crc``, ``short``, ``other-id``, ``wrong-function``, ``length``,
    ``echo-differs``)."""

    def __init__(self, kind: str, message: str, **facts: Any) -> None:
        super().__init__(message, kind=kind, **facts)


MISMATCH_KINDS = ("crc", "short", "other-id", "wrong-function", "length", "echo-differs")


# --- frames --------------------------------------------------------------------------------------

def frame(ident: int, pdu: Union[bytes, bytearray, Sequence[int]]) -> bytes:
    """``ID pdu CRC`` (CRC-16/MODBUS, low byte first)."""
    body = bytes((ident,)) + bytes(pdu)
    if len(body) + 2 > MAX_FRAME:
        raise FieldValueError(f"frame: {len(body) + 2} bytes; a Modbus RTU frame has at most {MAX_FRAME}")
    return body + crc16_modbus(body).to_bytes(2, "little")


def crc_ok(data: Union[bytes, bytearray, memoryview]) -> bool:
    """Whether the last two bytes of ``data`` are the CRC of the bytes before them."""
    return len(data) >= 4 and crc16_modbus(data[:-2]) == int.from_bytes(data[-2:], "little")


def check_frame(data: Union[bytes, bytearray, memoryview]) -> None:
    """Raise :class:`ModbusFrameError`/:class:`ModbusCrcError` unless ``data`` is one whole frame."""
    n = len(data)
    if n < 4:
        raise ModbusFrameError(f"Modbus RTU frame: {n} bytes; a frame has at least 4 (ID, function, CRC)")
    if n > MAX_FRAME:
        raise ModbusFrameError(f"Modbus RTU frame: {n} bytes; at most {MAX_FRAME}")
    expected = crc16_modbus(data[:-2])
    found = int.from_bytes(data[-2:], "little")
    if expected != found:
        raise ModbusCrcError(f"Modbus RTU frame: CRC mismatch: expected {expected & 0xFF:02X} {expected >> 8:02X}, "
                       f"found {found & 0xFF:02X} {found >> 8:02X}", expected, found)


def check_id(value: Union[int, str], *, allow_broadcast: bool = True) -> int:
    """A Modbus unit ID (``"broadcast"`` is 0 where allowed); FieldValueError otherwise."""
    allowed = "1..247" + (", 0 or broadcast" if allow_broadcast else "")
    if isinstance(value, str):
        v = value.strip().lower()
        if v in ("broadcast", "all", "bc"):
            value = BROADCAST
        else:
            try:
                value = int(v, 0)
            except ValueError:
                raise FieldValueError(f"id: {value!r} is not a number; allowed {allowed}") from None
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_ID:
        raise FieldValueError(f"id: {value} is out of range; allowed {allowed}")
    if value == BROADCAST and not allow_broadcast:
        raise FieldValueError(f"id: broadcast (0) is not allowed here; allowed {allowed}")
    return value


def _address(address: int, count: int = 1) -> None:
    if not 0 <= address <= 0xFFFF or address + count - 1 > 0xFFFF:
        raise FieldValueError(f"address: {address}..{address + count - 1} is outside 0..65535")


def _word(value: int, what: str = "value") -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFF:
        raise FieldValueError(f"{what}: {value!r} is out of range; a register holds 0..65535")
    return value


def read_registers(ident: int, address: int, count: int = 1) -> bytes:
    """0x03 Read Holding Registers: ``count`` (1..125) registers from ``address``."""
    ident = check_id(ident, allow_broadcast=False)
    if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_READ:
        raise FieldValueError(f"count: {count} is out of range; allowed 1..{MAX_READ}")
    _address(address, count)
    return frame(ident, bytes((READ_HOLDING,)) + address.to_bytes(2, "big") + count.to_bytes(2, "big"))


def write_register(ident: int, address: int, value: int) -> bytes:
    """0x06 Write Single Register."""
    ident = check_id(ident)
    _address(address)
    return frame(ident, bytes((WRITE_SINGLE,)) + address.to_bytes(2, "big") + _word(value).to_bytes(2, "big"))


def write_registers(ident: int, address: int, values: Sequence[int]) -> bytes:
    """0x10 Write Multiple Registers: ``values`` (1..123) from ``address``."""
    ident = check_id(ident)
    values = list(values)
    if not 1 <= len(values) <= MAX_WRITE:
        raise FieldValueError(f"values: {len(values)} registers; one write carries 1..{MAX_WRITE}")
    _address(address, len(values))
    data = b"".join(_word(v).to_bytes(2, "big") for v in values)
    return frame(ident, bytes((WRITE_MULTIPLE,)) + address.to_bytes(2, "big") + len(values).to_bytes(2, "big")
                 + bytes((len(data),)) + data)


def read_reply(ident: int, values: Sequence[int]) -> bytes:
    """The reply to a read: ``ID 03 bytecount data...``."""
    data = b"".join(_word(v).to_bytes(2, "big") for v in values)
    return frame(ident, bytes((READ_HOLDING, len(data))) + data)


def write_multiple_reply(ident: int, address: int, count: int) -> bytes:
    """The reply to a write multiple: ``ID 10 start quantity``."""
    return frame(ident, bytes((WRITE_MULTIPLE,)) + address.to_bytes(2, "big") + count.to_bytes(2, "big"))


def exception_reply(ident: int, function: int, code: int) -> bytes:
    """``ID function+0x80 code``."""
    return frame(ident, bytes((function | EXCEPTION_BIT, code)))


# --- requests by register ------------------------------------------------------------------------

def _map(regmap):
    if regmap is None:
        from .regmap import default_map

        return default_map("modbus")
    return regmap


def read(ident: int, reg: Union[str, int, Register], count: Optional[int] = None,
         regmap: Optional[RegisterMap] = None) -> bytes:
    """Read ``reg`` (a name or address of ``regmap``, the 17Lf's by default), ``count``
    registers from it (default 1)."""
    r = _map(regmap).register(reg)
    return read_registers(ident, r.address, 1 if count is None else count)


def write(ident: int, reg: Union[str, int, Register], value: int, regmap: Optional[RegisterMap] = None, *,
          force: bool = False) -> bytes:
    """Write one register, checked against the map: a read-only one is refused (unless
    ``force``), a value outside its range is a FieldValueError."""
    r = _map(regmap).register(reg)
    if not r.writable and not force:
        raise FieldValueError(f"{r.name}: read-only register ({r.address}); it cannot be written")
    r.check(value)
    return write_register(ident, r.address, value)


def write_block(ident: int, values: Mapping[Union[str, int], int], regmap: Optional[RegisterMap] = None, *,
                force: bool = False) -> list[bytes]:
    """Frames writing ``values`` ({register: value}): one Write Multiple Registers per run of
    adjacent registers, a Write Single Register for a register alone."""
    m = _map(regmap)
    regs = []
    for spec, value in values.items():
        r = m.register(spec)
        if not r.writable and not force:
            raise FieldValueError(f"{r.name}: read-only register ({r.address}); it cannot be written")
        r.check(value)
        regs.append((r.address, value))
    regs.sort()
    out = []
    run: list = []
    for addr, value in regs + [(None, None)]:
        if run and (addr is None or addr != run[-1][0] + 1 or len(run) == MAX_WRITE):
            if len(run) == 1:
                out.append(write_register(ident, run[0][0], run[0][1]))
            else:
                out.append(write_registers(ident, run[0][0], [v for _, v in run]))
            run = []
        if addr is not None:
            run.append((addr, value))
    return out


def write_frames(ident: int, values: Mapping[Union[str, int], int], regmap: Optional[RegisterMap] = None, *,
                 force: bool = False) -> list[bytes]:
    """The frames a bus sends to write ``values``: :func:`write_block`'s runs, each as Write
    Multiple Registers (one register too: its reply cannot be mistaken for an adapter's echo)."""
    out = []
    for f in write_block(ident, values, regmap, force=force):
        r = Request(f)
        out.append(write_registers(ident, r.address, r.values) if r.function == WRITE_SINGLE else f)
    return out


def sync_frames(reg: Union[str, int, Register], targets: Union[Mapping[int, int], Iterable[tuple[int, int]]],
                regmap: Optional[RegisterMap] = None, *, force: bool = False) -> list[bytes]:
    """The frames that write one register of several actuators (``targets``: ID -> value, or
    pairs): Modbus RTU has no multi-actuator write, so one Write Multiple Registers per ID, in
    the given order. ID 0 (broadcast: every actuator, answered by none) is one frame that serves
    them all, given alone."""
    m = _map(regmap)
    r = m.register(reg)
    items = list(targets.items() if hasattr(targets, "items") else targets)
    if not items:
        raise FieldValueError("targets: none given; expected ID:VALUE pairs")
    seen: set = set()
    for ident, _ in items:
        check_id(ident)
        if ident in seen:
            raise FieldValueError(f"id: {ident} is given twice")
        seen.add(ident)
    if BROADCAST in seen and len(items) > 1:
        raise FieldValueError("id: 0 (broadcast) reaches every actuator; give it alone, not beside other IDs")
    out = []
    for ident, value in items:
        out += write_frames(ident, {r.name: value}, m, force=force)
    return out


# --- typed frames --------------------------------------------------------------------------------

class Request:
    """A request frame (host -> actuator) and what it means, answered here once.

    ``ident``, ``function``, ``address`` (None when the frame is malformed), ``count``
    (registers read or written), ``values`` (the values written), ``frame`` (the bytes).
    """

    __slots__ = ("frame", "ident", "function", "address", "count", "values", "malformed")

    def __init__(self, data: Union[bytes, bytearray, memoryview]) -> None:
        data = bytes(data)
        self.frame = data
        self.ident = data[0]
        self.function = data[1]
        self.address = self.count = self.values = None
        self.malformed = ""
        body = data[2:-2]
        fn = self.function
        if fn in (READ_HOLDING, WRITE_SINGLE) and len(body) == 4:
            self.address = int.from_bytes(body[:2], "big")
            word = int.from_bytes(body[2:], "big")
            if fn == READ_HOLDING:
                self.count = word
            else:
                self.count, self.values = 1, [word]
        elif fn == WRITE_MULTIPLE and len(body) >= 5 and body[4] == len(body) - 5 and body[4] % 2 == 0:
            self.address = int.from_bytes(body[:2], "big")
            self.count = int.from_bytes(body[2:4], "big")
            self.values = [int.from_bytes(body[5 + i:7 + i], "big") for i in range(0, body[4], 2)]
            if len(self.values) != self.count:
                self.malformed = f"quantity {self.count} but {len(self.values)} registers of data"
        elif fn in FUNCTIONS:
            self.malformed = f"{len(body)} data bytes do not make a {FUNCTIONS[fn][1]} request"
        else:
            self.malformed = f"function 0x{fn:02X} is not one the actuator knows"

    def __repr__(self) -> str:
        return f"Request({FUNCTIONS.get(self.function, ('0x%02X' % self.function,))[0]}, id={self.ident}, " \
               f"address={self.address}, count={self.count})"

    @property
    def broadcast(self) -> bool:
        """Sent to every actuator (ID 0): never answered."""
        return self.ident == BROADCAST

    @property
    def writes(self) -> bool:
        return self.function in (WRITE_SINGLE, WRITE_MULTIPLE)

    def expects_reply(self) -> bool:
        """Whether an actuator answers it: every unicast request (an exception reply counts)."""
        return not self.broadcast

    def reply_length(self) -> Optional[int]:
        """The length of the normal reply (an exception reply has 5 bytes); None when no reply
        comes (broadcast) or the request is malformed (what comes back cannot be foretold)."""
        if self.broadcast or self.malformed or self.address is None:
            return None
        if self.function == READ_HOLDING:
            return 5 + 2 * self.count
        return 8

    def blocks(self) -> list[tuple[int, list[int]]]:
        """``[(address, values)]``: what this request writes (empty for a read)."""
        if self.writes and self.values is not None:
            return [(self.address, list(self.values))]
        return []

    def needs(self, regmap: Optional[RegisterMap] = None) -> dict[Permission, str]:
        """``{Permission: reason}``: what sending this request needs against ``regmap`` (the
        17Lf's by default); ``{}`` for a read or a goal write. The same policy as the IR
        protocol's (:meth:`zkzap.codec.zap.Command.needs`)."""
        from .permissions import Permission as P

        m = _map(regmap)
        out: dict = {}

        def need(p, why):
            out.setdefault(p, why)

        if self.malformed:
            need(P.UNDOCUMENTED, f"a malformed request: {self.malformed}")
        for address, values in self.blocks():
            for i, value in enumerate(values):
                a = address + i
                reg = m.owner.get(a)
                if reg is None:
                    need(P.UNDOCUMENTED, f"writes register {a}, which the {m.model} map does not give")
                    continue
                if not reg.writable:
                    need(P.UNDOCUMENTED, f"writes {reg.name}, a read-only register")
                elif not reg.allows(value):
                    need(P.UNDOCUMENTED, f"{reg.name} {value} is outside its documented values "
                                         f"({reg.describe_range()})")
                if not reg.documented:
                    need(P.UNDOCUMENTED, f"writes {reg.name} ({a}), which the {m.model} map does not document")
                if reg.stored:
                    need(P.STORED, f"writes {reg.name}, a stored setting (it survives power-off)")
                if reg.identity:
                    need(P.IDENTITY, _identity_why(reg, value, m))
                if value in reg.silencing:
                    from .zap import silencing_why

                    need(P.SILENCING, silencing_why(reg, value))
        if self.broadcast and out:
            need(P.BROADCAST, "sent to every actuator at once (broadcast ID 0)")
        return out

    def permissions(self, regmap: Optional[RegisterMap] = None) -> Permission:
        """The union of :meth:`needs`."""
        from .permissions import Permission

        out = Permission.NONE
        for p in self.needs(regmap):
            out |= p
        return out

    @property
    def hazardous(self) -> bool:
        """Whether sending it needs any permission against the 17Lf's map."""
        return bool(self.needs())

    def describe(self, regmap: Optional[RegisterMap] = None) -> str:
        """``read present-position (1 register) from 1``, as messages say it."""
        m = _map(regmap)
        to = "every actuator (broadcast)" if self.broadcast else f"actuator {self.ident}"
        if self.malformed:
            return f"malformed request to {to}: {self.malformed}"
        name = _names(m, self.address, self.count)
        if self.function == READ_HOLDING:
            return f"read {name} ({self.count} register{'s' if self.count != 1 else ''}) from {to}"
        pairs = " ".join(f"{r}={v}" for r, v in _named_values(m, self.address, self.values))
        return f"write {pairs} to {to}"


def _identity_why(reg, value, m):
    if reg.name == "id":
        return f"writes id {value}: the actuator then answers to ID {value} (unchecked: another may have it)"
    if reg.name == "baud-rate":
        return f"writes baud-rate {value}: the actuator then answers at {m.baud_codes.get(value, 'another')} baud only"
    return f"writes {reg.name} {value}: it decides where or how the actuator answers"


def _names(m, address, count):
    first = m.owner.get(address)
    name = first.name if first is not None else str(address)
    if count and count > 1:
        last = m.owner.get(address + count - 1)
        name += ".." + (last.name if last is not None else str(address + count - 1))
    return name


def _named_values(m, address, values):
    """``[(name, value)]`` for registers from ``address`` (unnamed ones by their address)."""
    out = []
    for i, v in enumerate(values or ()):
        reg = m.by_address.get(address + i)
        out.append((reg.name if reg is not None else str(address + i), v))
    return out


# --- replies -------------------------------------------------------------------------------------

def parse_reply(request: Union[Request, bytes], data: Union[bytes, bytearray, memoryview]) -> list[int]:
    """The values a reply to ``request`` carries (the registers read; the values written, for a
    write). Raises :class:`ExceptionReply` for an exception reply and :class:`ReplyMismatch`
    (naming its kind) for anything that is not this request's reply."""
    req = request if isinstance(request, Request) else Request(request)
    data = bytes(data)
    if len(data) < 4:
        raise ReplyMismatch("short", f"a {len(data)}-byte frame; a reply has at least 5 bytes", length=len(data))
    if data[0] != req.ident:
        raise ReplyMismatch("other-id", f"a frame from ID {data[0]}, not {req.ident}", id=data[0],
                            expected_id=req.ident)
    fn = data[1]
    if fn == req.function | EXCEPTION_BIT:
        if len(data) != 5:
            raise ReplyMismatch("length" if len(data) > 5 else "short",
                                f"an exception reply of {len(data)} bytes; it has 5", length=len(data))
        if not crc_ok(data):
            raise ReplyMismatch("crc", "an exception reply with a bad CRC")
        raise ExceptionReply(req.ident, req.function, data[2])
    if fn != req.function:
        raise ReplyMismatch("wrong-function", f"a reply with function 0x{fn:02X} to a request with 0x{req.function:02X}",
                            function=fn, expected_function=req.function)
    want = req.reply_length()
    if want is not None and len(data) < want:
        raise ReplyMismatch("short", f"a {len(data)}-byte reply; {want} expected", length=len(data))
    if want is not None and len(data) > want:
        raise ReplyMismatch("length", f"a {len(data)}-byte reply; {want} expected", length=len(data))
    if not crc_ok(data):
        raise ReplyMismatch("crc", "a reply with a bad CRC")
    if fn == READ_HOLDING:
        if data[2] != 2 * req.count:
            raise ReplyMismatch("length", f"byte count {data[2]}; {2 * req.count} expected")
        return [int.from_bytes(data[3 + i:5 + i], "big") for i in range(0, data[2], 2)]
    if fn == WRITE_SINGLE:
        if data != req.frame:
            raise ReplyMismatch("echo-differs", "the reply to a write single register is not its echo")
        return list(req.values)
    if data[2:6] != req.frame[2:6]:
        raise ReplyMismatch("echo-differs", "the reply to a write multiple names another block")
    return list(req.values)


def is_exception(data: Union[bytes, bytearray]) -> bool:
    return len(data) == 5 and bool(data[1] & EXCEPTION_BIT)


def frame_kind(data: Union[bytes, bytearray], direction: Optional[str] = None) -> str:
    """``request``, ``reply`` or ``exception`` for a checked frame. A 0x03 frame of 8 bytes is a
    request, else a reply; 0x06 frames are the same both ways (``direction`` decides, else
    ``request``); 0x10 of 8 bytes is a reply."""
    fn = data[1]
    if fn & EXCEPTION_BIT:
        return "exception"
    if direction == "h2d":
        return "request"
    if direction == "d2h":
        return "reply"
    if fn == READ_HOLDING:
        return "request" if len(data) == 8 and (len(data) - 5) != data[2] else "reply"
    if fn == WRITE_MULTIPLE:
        return "reply" if len(data) == 8 else "request"
    return "request"


def decode_frame(data: Union[bytes, bytearray], request: Optional[Union[bytes, Request]] = None,
                 regmap: Optional[RegisterMap] = None, direction: Optional[str] = None) -> dict:
    """A checked frame as a record; a reply is named by the ``request`` it answers when known."""
    m = _map(regmap)
    data = bytes(data)
    kind = frame_kind(data, direction)
    if request is not None and kind != "exception":
        kind = "reply"
    fn = data[1] & 0x7F
    rec: dict = {"kind": kind, "id": data[0], "function": FUNCTIONS.get(fn, (f"0x{fn:02x}",))[0], "code": data[1]}
    if kind == "exception":
        rec["exception"] = data[2]
        rec["name"] = exception_name(data[2])
        rec["meaning"] = exception_meaning(data[2])
        return rec
    if kind == "request":
        req = Request(data)
        if req.malformed:
            rec["malformed"] = req.malformed
            rec["params"] = data[2:-2].hex(" ").upper()
            return rec
        rec["address"] = req.address
        rec["register"] = _names(m, req.address, req.count)
        rec["count"] = req.count
        if req.values is not None:
            _values(rec, m, req.address, req.values)
        return rec
    # a reply
    if fn == READ_HOLDING:
        values = [int.from_bytes(data[3 + i:5 + i], "big") for i in range(0, len(data) - 5, 2)]
        req = None if request is None else (request if isinstance(request, Request) else Request(request))
        if req is not None and req.function == READ_HOLDING and req.count == len(values):
            rec["address"] = req.address
            rec["register"] = _names(m, req.address, req.count)
            _values(rec, m, req.address, values)
        else:
            rec["count"] = len(values)
            rec["values"] = values if len(values) != 1 else None
            if len(values) == 1:
                rec.pop("values")
                rec["value"] = values[0]
        return rec
    rec["address"] = int.from_bytes(data[2:4], "big")
    if fn == WRITE_SINGLE:
        rec["register"] = _names(m, rec["address"], 1)
        _values(rec, m, rec["address"], [int.from_bytes(data[4:6], "big")])
    else:
        rec["count"] = int.from_bytes(data[4:6], "big")
        rec["register"] = _names(m, rec["address"], rec["count"])
    return rec


def _values(rec, m, address, values):
    named = _named_values(m, address, values)
    if len(named) == 1:
        rec["value"] = named[0][1]
        reg = m.by_address.get(address)
        if reg is not None and reg.scale != 1:
            rec["physical"] = reg.physical(named[0][1])
            rec["unit"] = reg.unit
    else:
        rec["values"] = dict(named)


class ModbusDecoder:
    """Stateful record decoder of a stream of both directions: each reply is paired with the
    last request to its ID (so a read's values are named by register)."""

    def __init__(self, regmap: Optional[RegisterMap] = None) -> None:
        self.regmap = _map(regmap)
        self.pending: dict[int, bytes] = {}

    def decode(self, data: Union[bytes, bytearray], direction: Optional[str] = None) -> dict:
        data = bytes(data)
        kind = frame_kind(data, direction)
        ident = data[0]
        req = self.pending.get(ident)
        if kind == "request" and req is not None and data[1] == WRITE_SINGLE and data == req \
                and direction is None:
            kind = "reply"                 # the echo of the write just seen
        if kind == "request":
            self.pending[ident] = data
            return decode_frame(data, None, self.regmap, "h2d")
        self.pending.pop(ident, None)
        if kind == "exception":
            return decode_frame(data, None, self.regmap)
        return decode_frame(data, req, self.regmap, "d2h")


MODBUS_KEYS = ("kind", "id", "function", "code", "exception", "name", "meaning", "register", "address",
               "count", "value", "physical", "unit", "values", "malformed", "params")


# --- reading a reply off the line ----------------------------------------------------------------

class ReplyReader:
    """Collects the reply to one request from the bytes that come, and counts what is not it.

    :meth:`feed` takes bytes; :attr:`done` is true once a whole reply (or exception reply) is in,
    :meth:`result` gives its values or raises. Before the reply, the host's own request echoed
    by a half-duplex adapter is skipped (``echoes``). Counters of frames that are not the reply:
    ``crc`` (bad CRC), ``short`` (cut short: :meth:`finish` at the end of the window),
    ``other_id``, ``wrong_function``.
    """

    def __init__(self, request: Union[Request, bytes], echo: Optional[bool] = None) -> None:
        self.request = request if isinstance(request, Request) else Request(request)
        #: Whether the adapter echoes the host's bytes (None: not known). A write single
        #: register's reply is its echo: only a known echo is skipped before it.
        self.echo = echo
        self._echo_pending = echo is not False
        self.buf = b""
        self.frame: Optional[bytes] = None
        self.echoes = 0
        self.crc = self.short = self.other_id = self.wrong_function = 0
        self.error: Optional[ZkzapError] = None

    @property
    def done(self) -> bool:
        return self.frame is not None or self.error is not None

    def _want(self, buf):
        """The length of the frame starting ``buf`` as a reply to the request, or None (unknown yet)."""
        req = self.request
        if len(buf) < 2:
            return None
        if buf[1] == req.function | EXCEPTION_BIT:
            return 5
        if buf[1] == READ_HOLDING:
            return None if len(buf) < 3 else 5 + buf[2]
        return 8

    def feed(self, data: bytes) -> None:
        if self.done:
            return
        self.buf += bytes(data)
        req = self.request.frame
        if self._echo_pending:
            head = self.buf[:len(req)]
            if req.startswith(head):
                if len(head) < len(req):
                    return                   # perhaps the adapter's echo of the request: wait
                if self.request.function != WRITE_SINGLE or self.echo:
                    self.buf = self.buf[len(req):]
                    self.echoes += 1
            self._echo_pending = False
        want = self._want(self.buf)
        if want is None or len(self.buf) < want:
            return
        cand, self.buf = self.buf[:want], self.buf[want:]
        try:
            parse_reply(self.request, cand)
        except ExceptionReply:
            self.frame = cand
            return
        except ReplyMismatch as e:
            self._count(e.kind)
            self.error = e
            return
        self.frame = cand

    def _count(self, kind):
        if kind == "crc":
            self.crc += 1
        elif kind in ("short", "length"):
            self.short += 1
        elif kind == "other-id":
            self.other_id += 1
        elif kind == "wrong-function":
            self.wrong_function += 1

    def finish(self) -> None:
        """The window closed: bytes held are a frame cut short."""
        if not self.done and self.buf:
            self.short += 1
            self.error = ReplyMismatch("short", f"{len(self.buf)} bytes of a reply, cut short", length=len(self.buf))

    def result(self) -> list[int]:
        """The reply's values; raises what the reply was (exception, mismatch), or
        ReplyMismatch ``short`` when nothing whole came."""
        if self.error is not None:
            raise self.error
        if self.frame is None:
            raise ReplyMismatch("short", "no whole reply")
        return parse_reply(self.request, self.frame)
