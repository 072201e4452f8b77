"""Register maps as data: one description a model and protocol family, one loader for all.

A map file (``codec/maps/*.map``, or a user's ``--map FILE``) is UTF-8 text. Lines starting
``#`` and blank lines are comments. Header lines ``key: value`` come first: ``model`` (the
model's name, like ``17Lf``) and ``protocol`` (``ir`` or ``modbus``). Then one register a
line, ten cells separated by ``|``::

    address | name | width | memory | access | range | unit | default | permissions | help

- address: decimal or ``0x..``; on ``ir`` a byte address (0..255), on ``modbus`` a 16-bit
  register address (0..65535);
- name: kebab-case, unique in the map;
- width: bits, 8, 16 or 32 on ``ir`` (whole bytes), 16 only on ``modbus``;
- memory: ``NV`` (stored: survives power-off), ``V`` (volatile) or ``-`` (read-only, memory not
  given);
- access: ``R`` or ``RW``;
- range: empty (what the width holds), ``LO..HI``, choices ``0=Modbus RTU; 1=IR`` or bits
  ``bits 0=input voltage; 5=overload``;
- unit: empty, a unit (``mA``) or a scale and a unit (``0.1 V``: raw tenths, shown in volts);
- default: empty or a value inside the range;
- permissions: empty, or words among ``identity`` (changes where or how the actuator answers),
  ``undocumented`` (an address the maker's documentation does not give) and ``silences=V``
  (``silences=0``, several as ``silences=0/3``: writing one of these values makes the actuator
  stop answering, or answer Echo only; such a write needs the SILENCING permission, a force);
- help: the rest of the line.

Every fault is a :class:`MapError` (exit 2) naming ``FILE:LINE``: overlapping registers, a
width the protocol cannot carry, an unknown memory kind, a range or default that does not fit
the width, a duplicate name, a missing header. The maps zkzap ships go through the same
loader (and a test loads each).
"""

from __future__ import annotations

import os

from ..errors import USAGE, InvalidValue
from .fields import FieldValueError

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Mapping, Optional, Sequence, Union

#: The protocol families a map can describe, and their address spaces and widths (bits).
PROTOCOLS = {"ir": (0xFF, (8, 16, 32), "little"), "modbus": (0xFFFF, (16,), "big")}
MEMORY_KINDS = ("NV", "V", "-")
ACCESS_KINDS = ("R", "RW")
PERMISSION_WORDS = ("identity", "undocumented", "silences=V")
#: The directory of the maps zkzap ships.
MAPS_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "maps")
#: Shipped maps by (model, protocol) key: the file in :data:`MAPS_DIR`.
BUILTIN = {"12lf-ir": "12lf-ir.map", "17lf-modbus": "17lf-modbus.map"}
COLUMNS = ("address", "name", "width", "memory", "access", "range", "unit", "default", "permissions", "help")


class MapError(InvalidValue):
    """A register map file that cannot be used: exit 2, the message starts ``FILE:LINE:``.
    Facts: ``path`` and ``line``."""

    code = USAGE


class Register:
    """One register of the data map. ``scale`` converts raw to ``unit`` (0.1 V registers).

    The value domain is declared here, checked in one place (:meth:`check`, :meth:`allows`):
    ``lo..hi`` (default: what ``size`` bytes hold), ``choices`` (an enumeration: raw value ->
    meaning) or ``bits`` (a bit set: bit number -> meaning; other bits are outside the domain).
    ``documented`` is False for addresses the 12Lf map does not give (IR Robot's header names
    some; others are anonymous bytes), which are written only with the UNDOCUMENTED permission.

    ``size`` is in bytes. ``byteorder`` is how the value lies on the wire: ``"little"`` on the IR
    protocol (byte addresses), ``"big"`` on Modbus RTU (16-bit registers, one address each:
    :attr:`span` is the number of addresses the register takes). ``identity`` marks a register
    that decides where or how the actuator answers (its ID, baud rate, protocol); ``silencing``
    the values after whose write the actuator stops answering (feedback-return-mode 0: Echo
    only; protocol-type 0: it leaves the IR protocol).
    """

    __slots__ = ("address", "name", "size", "access", "stored", "default", "lo", "hi", "unit",
                 "scale", "choices", "bits", "help", "documented", "byteorder", "identity", "silencing")

    def __init__(self, address: int, name: str, size: int, access: str, default: Optional[int] = None,
                 lo: Optional[int] = None, hi: Optional[int] = None, unit: str = "", scale: float = 1,
                 choices: Optional[Mapping[int, str]] = None, bits: Optional[Mapping[int, str]] = None,
                 help: str = "", documented: bool = True, byteorder: str = "little",
                 identity: bool = False, silencing: Sequence[int] = ()) -> None:
        self.address = address
        self.name = name
        self.size = size
        self.access = access.split()[0]           # "R" or "RW"
        self.stored = "NV" in access.split()[1:] if " " in access else None
        self.default = default
        self.bits = dict(bits) if bits else None  # allowed bits -> meaning
        self.lo = 0 if lo is None else lo
        if hi is None:
            hi = sum(1 << b for b in self.bits) if self.bits else (1 << (8 * size)) - 1
        self.hi = hi
        self.unit = unit
        self.scale = scale
        self.choices = choices                    # allowed raw values -> meaning
        self.help = help
        self.documented = documented
        self.byteorder = byteorder
        self.identity = identity
        self.silencing = frozenset(silencing)

    @property
    def span(self) -> int:
        """Addresses the register takes: its bytes on the IR protocol, its 16-bit words on Modbus."""
        return self.size if self.byteorder == "little" else max(1, self.size // 2)

    @property
    def writable(self) -> bool:
        return self.access == "RW"

    @property
    def memory(self) -> str:
        """``"NV"`` (stored), ``"V"`` (volatile) or ``""`` for read-only registers."""
        if self.stored is None:
            return ""
        return "NV" if self.stored else "V"

    @property
    def mask(self) -> Optional[int]:
        """The bits a bit-set register may hold (None for other registers)."""
        return sum(1 << b for b in self.bits) if self.bits else None

    def bit_names(self, raw: int) -> list:
        """The names of the bits set in ``raw`` (a bit mask register's; ``bit N`` for one it does not name)."""
        bits = self.bits or {}
        return [bits.get(b, f"bit {b}") for b in range(8 * self.size) if raw >> b & 1]

    def describe_range(self) -> str:
        """The allowed raw values, as messages say them (``0..4095``, ``0 (off), 1 (on)``)."""
        if self.choices:
            return ", ".join(f"{k} ({v})" for k, v in self.choices.items())
        if self.bits:
            values = self.values()
            which = f"0..{self.mask}" if len(values) == self.mask + 1 else ", ".join(map(str, values))
            return "bits " + ", ".join(f"{b} ({v})" for b, v in sorted(self.bits.items())) + f": {which}"
        unit = f" {self.unit}" if self.unit and self.scale == 1 else ""
        return f"{self.lo}..{self.hi}{unit}"

    def values(self) -> Sequence[int]:
        """Every raw value of the documented domain (a range, or a list for choices and bits)."""
        if self.choices is not None:
            return sorted(self.choices)
        if self.bits is not None:
            return [v for v in range(self.lo, self.hi + 1) if not v & ~self.mask]
        return range(self.lo, self.hi + 1)

    def allows(self, value: object) -> bool:
        """Whether ``value`` (raw) lies in the register's documented domain."""
        if not isinstance(value, int) or isinstance(value, bool):
            return False
        if self.choices is not None:
            return value in self.choices
        if self.bits is not None and value & ~self.mask:
            return False
        return self.lo <= value <= self.hi

    def check(self, value: int) -> int:
        """``value`` if the register takes it; FieldValueError naming the register otherwise."""
        if not isinstance(value, int) or isinstance(value, bool):
            raise FieldValueError(f"{self.name}: {value!r} is not an integer")
        if self.allows(value):
            return value
        if self.choices is not None or (self.bits is not None and self.lo <= value <= self.hi):
            raise FieldValueError(f"{self.name}: {value} is not allowed; allowed {self.describe_range()}")
        raise FieldValueError(f"{self.name}: {value} is out of range; allowed {self.describe_range()}")

    def to_bytes(self, value: int) -> bytes:
        """``value`` in the register's size and byte order (little-endian on IR, big on Modbus)."""
        return value.to_bytes(self.size, self.byteorder)

    def physical(self, raw: int) -> Union[int, float]:
        """``raw`` in the register's unit (tenths of a volt as volts); unscaled values as they are."""
        if self.scale == 1:
            return raw
        return round(raw * self.scale, 3)



class RegisterMap:
    """A model's register map for one protocol family: ``model``, ``protocol`` (``ir`` or
    ``modbus``), ``registers`` (in address order), ``path`` (the file it came from), and the
    look-ups derived from them once: :attr:`by_name`, :attr:`by_address`, :attr:`owner`
    (every address a register takes -> the register), :attr:`identity` (the names of the
    identity registers) and :attr:`baud_codes` (the baud-rate register's code -> bit/s)."""

    def __init__(self, model: str, protocol: str, registers: Sequence[Register], path: str = "") -> None:
        self.model = model
        self.protocol = protocol
        self.registers = tuple(sorted(registers, key=lambda r: r.address))
        self.path = path
        self.by_name = {r.name: r for r in self.registers}
        self.by_address = {r.address: r for r in self.registers}
        self.owner = {a: r for r in self.registers for a in range(r.address, r.address + r.span)}
        self.identity = tuple(r.name for r in self.registers if r.identity)
        baud = self.by_name.get("baud-rate")
        self.baud_codes = {} if baud is None or not baud.choices else \
            {k: int(v.split()[0]) for k, v in baud.choices.items() if v.split() and v.split()[0].isdigit()}

    @property
    def key(self) -> str:
        """``17lf-modbus``: the model and protocol, as the shipped maps are named."""
        return f"{self.model.lower()}-{self.protocol}"

    def __repr__(self) -> str:
        return f"<RegisterMap {self.model} {self.protocol}: {len(self.registers)} registers>"

    def register(self, spec: Union[str, int, Register]) -> Register:
        """A register of this map by name or address (FieldValueError naming the choices). A
        :class:`Register` of another map stands for this map's register of the same name (the
        same words where the meaning is the same)."""
        if isinstance(spec, Register):
            if self.by_name.get(spec.name) is spec:
                return spec
            spec = spec.name
        if isinstance(spec, str):
            key = spec.strip().lower().replace("_", "-")
            if key in self.by_name:
                return self.by_name[key]
            try:
                spec = int(key, 0)
            except ValueError:
                from ..errors import unknown_name

                raise unknown_name("register", spec, list(self.by_name), otherwise="", cls=FieldValueError,
                                   field="register") from None
        reg = self.by_address.get(spec)
        if reg is None:
            raise FieldValueError(f"register: address {spec} is not in the {self.model} {self.protocol} map")
        return reg


def _int(text, what, where):
    try:
        return int(text, 0)
    except ValueError:
        raise _fault(where, f"{what} {text!r} is not a number") from None


def _pairs(text, what, where):
    out = {}
    for part in text.split(";"):
        key, eq, meaning = part.partition("=")
        if not eq or not meaning.strip():
            raise _fault(where, f"{what} {part.strip()!r}: expected NUMBER=MEANING")
        k = _int(key.strip(), what, where)
        if k in out:
            raise _fault(where, f"{what} {k} is given twice")
        out[k] = meaning.strip()
    return out


def _fault(where, message):
    path, _, line = where.rpartition(":")
    return MapError(f"{where}: {message}", path=path, line=int(line))


def _register(cells, protocol, where):
    top, widths, order = PROTOCOLS[protocol]
    addr_t, name, width_t, memory, access, range_t, unit_t, default_t, perms_t, help_t = cells
    address = _int(addr_t, "address", where)
    if not 0 <= address <= top:
        raise _fault(where, f"address {addr_t} is outside the {protocol} address space 0..{top}")
    if not name or name != name.lower() or " " in name or name.startswith("-"):
        raise _fault(where, f"name {name!r}: expected a kebab-case name like goal-position")
    width = _int(width_t, "width", where)
    if width not in widths:
        allowed = " or ".join(map(str, widths))
        raise _fault(where, f"{name}: width {width} bits is not allowed on {protocol}; allowed {allowed}")
    size = width // 8
    span = size if protocol == "ir" else 1
    if address + span - 1 > top:
        raise _fault(where, f"{name}: {width} bits at {addr_t} run past the address space (0..{top})")
    if memory not in MEMORY_KINDS:
        raise _fault(where, f"{name}: unknown memory kind {memory!r}; allowed NV, V, - (read-only)")
    if access not in ACCESS_KINDS:
        raise _fault(where, f"{name}: unknown access {access!r}; allowed R, RW")
    if access == "RW" and memory == "-":
        raise _fault(where, f"{name}: a writable register needs its memory kind, NV or V")
    lo = hi = None
    choices = bits = None
    full = (1 << width) - 1
    if range_t.startswith("bits "):
        bits = _pairs(range_t[5:], "bit", where)
        bad = [b for b in bits if not 0 <= b < width]
        if bad:
            raise _fault(where, f"{name}: bit {bad[0]} does not fit {width} bits")
    elif "=" in range_t:
        choices = _pairs(range_t, "choice", where)
        bad = [c for c in choices if not 0 <= c <= full]
        if bad:
            raise _fault(where, f"{name}: choice {bad[0]} does not fit {width} bits (0..{full})")
    elif range_t:
        first, dots, last = range_t.partition("..")
        if not dots:
            raise _fault(where, f"{name}: range {range_t!r}: expected LO..HI, N=MEANING; ... or bits N=MEANING; ...")
        lo, hi = _int(first.strip(), "range", where), _int(last.strip(), "range", where)
        if lo > hi:
            raise _fault(where, f"{name}: range {range_t} runs backwards")
        if lo < 0 or hi > full:
            raise _fault(where, f"{name}: range {range_t} does not fit {width} bits (0..{full})")
    scale, unit = 1, unit_t
    if unit_t:
        head, _, rest = unit_t.partition(" ")
        try:
            scale, unit = float(head), rest.strip()
        except ValueError:
            scale, unit = 1, unit_t
        if scale == int(scale):
            scale = int(scale)
    words = perms_t.replace(",", " ").split()
    silencing = []
    for w in words:
        if w.startswith("silences="):
            for v in w[len("silences="):].split("/"):
                silencing.append(_int(v.strip(), "silences", where))
        elif w not in PERMISSION_WORDS:
            raise _fault(where, f"{name}: unknown permission {w!r}; allowed {', '.join(PERMISSION_WORDS)}")
    reg = Register(address, name, size, access if memory == "-" else f"{access} {memory}",
                   None, lo, hi, unit=unit, scale=scale, choices=choices, bits=bits, help=help_t,
                   documented="undocumented" not in words, byteorder=order, identity="identity" in words,
                   silencing=silencing)
    for v in silencing:
        if not reg.allows(v):
            raise _fault(where, f"{name}: silences={v} is outside its range ({reg.describe_range()})")
    if default_t:
        default = _int(default_t, "default", where)
        if not reg.allows(default):
            raise _fault(where, f"{name}: default {default} is outside its range ({reg.describe_range()})")
        reg.default = default
    return reg


def parse_map(text: str, path: str = "<map>") -> RegisterMap:
    """The :class:`RegisterMap` that ``text`` describes; :class:`MapError` naming
    ``path:LINE`` for the first fault."""
    header = {}
    registers = []
    taken = {}
    names = {}
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        where = f"{path}:{n}"
        if not line or line.startswith("#"):
            continue
        if "|" not in line:
            key, colon, value = line.partition(":")
            key = key.strip().lower()
            if not colon or key not in ("model", "protocol"):
                raise _fault(where, f"expected a header line 'model: NAME' or 'protocol: ir|modbus', or a "
                                    f"register line of {len(COLUMNS)} cells separated by |")
            if registers:
                raise _fault(where, f"header line {key!r} after the first register; headers come first")
            if key in header:
                raise _fault(where, f"{key} is given twice")
            value = value.strip()
            if key == "protocol" and value not in PROTOCOLS:
                raise _fault(where, f"unknown protocol {value!r}; allowed {', '.join(PROTOCOLS)}")
            if key == "model" and not value:
                raise _fault(where, "model: no name given")
            header[key] = value
            continue
        for key in ("model", "protocol"):
            if key not in header:
                raise _fault(where, f"a register before the {key!r} header line")
        cells = [c.strip() for c in line.split("|", len(COLUMNS) - 1)]
        if len(cells) != len(COLUMNS):
            raise _fault(where, f"{len(cells)} cells; a register line has {len(COLUMNS)}: {' | '.join(COLUMNS)}")
        reg = _register(cells, header["protocol"], where)
        if reg.name in names:
            raise _fault(where, f"{reg.name}: the name is taken by line {names[reg.name]}")
        for a in range(reg.address, reg.address + reg.span):
            if a in taken:
                other, line_no = taken[a]
                raise _fault(where, f"{reg.name} overlaps {other} (line {line_no}) at address {a}")
        for a in range(reg.address, reg.address + reg.span):
            taken[a] = (reg.name, n)
        names[reg.name] = n
        registers.append(reg)
    if "protocol" not in header or "model" not in header:
        raise MapError(f"{path}:1: not a register map: the header lines 'model: NAME' and 'protocol: ir|modbus' "
                       "are missing", path=path, line=1)
    if not registers:
        raise MapError(f"{path}:1: no register lines", path=path, line=1)
    return RegisterMap(header["model"], header["protocol"], registers, path)


def load_map(path: str) -> RegisterMap:
    """Read and check a map file (``-`` is stdin); :class:`MapError` (exit 2) naming FILE:LINE,
    or FILE alone when it cannot be read."""
    import sys

    try:
        if path == "-":
            text = sys.stdin.read()
        else:
            with open(path, encoding="utf-8") as f:
                text = f.read()
    except UnicodeDecodeError as e:
        raise MapError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})", path=path, line=0) from None
    except OSError as e:
        raise MapError(f"{path}: cannot read: {e.strerror or e}", path=path, line=0) from None
    return parse_map(text, path)


_BUILTIN: dict[str, RegisterMap] = {}


def builtin(key: str) -> RegisterMap:
    """A map zkzap ships, by key (``12lf-ir``, ``17lf-modbus``), read once."""
    m = _BUILTIN.get(key)
    if m is None:
        if key not in BUILTIN:
            from ..errors import unknown_name

            raise unknown_name("map", key, list(BUILTIN), cls=FieldValueError)
        m = _BUILTIN[key] = load_map(os.path.join(MAPS_DIR, BUILTIN[key]))
    return m


def default_map(protocol: str) -> RegisterMap:
    """The map of the model zkzap assumes on a protocol family: the 12Lf on ``ir``, the 17Lf on
    ``modbus``."""
    return builtin("12lf-ir" if protocol == "ir" else "17lf-modbus")
