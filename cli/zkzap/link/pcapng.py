"""pcapng captures of serial traffic: every chunk read or written, with its time and direction.

Layout (pcapng, little-endian, as written here):

- one Section Header Block (``shb_userappl`` = ``zkzap VERSION``);
- one Interface Description Block per port opened, with a user link type that names the
  protocol: :data:`LINKTYPE_ZK` = 147 (``DLT_USER0``) for the ZK ECU protocol,
  :data:`LINKTYPE_ZAP` = 148 (``DLT_USER1``) for mightyZAP's IR protocol, :data:`LINKTYPE_MODBUS`
  = 149 (``DLT_USER2``) for mightyZAP over Modbus RTU (the 17Lf); ``if_name`` is the port, and
  ``if_description`` says ``zkzap ZK 115200 baud``; timestamps in microseconds (the default
  ``if_tsresol``);
- one Enhanced Packet Block per chunk, its direction in ``epb_flags`` bits 0-1: 1 inbound
  (device -> host, what the host read), 2 outbound (host -> device, what it wrote), 0 unknown
  (a sniffer on a half-duplex bus sees both on one line).

Each block is written with one ``write`` loop that SIGINT/SIGTERM cannot cut and flushed at
once, so a killed process leaves a whole capture; when a write fails (disk full) a regular file
is cut back to its last whole block and :class:`~zkzap.errors.OutputError` is raised.

The reader trusts no length field: it stops at the last whole block of a truncated file, at a
block whose framing is broken, and skips blocks whose bodies are shorter than their fields,
saying so (:meth:`Reader.problems`); memory stays one block, whatever a length claims.
"""

from __future__ import annotations

import os
import stat
import struct
import threading

from ..errors import OutputError, UsageError
from ..infile import open_input
from ..signals import held

MAGIC = b"\x0a\x0d\x0d\x0a"
_BOM = 0x1A2B3C4D
SHB, IDB, EPB, SPB = 0x0A0D0D0A, 1, 6, 3

LINKTYPE_ZK = 147     # DLT_USER0
LINKTYPE_ZAP = 148    # DLT_USER1
LINKTYPE_MODBUS = 149  # DLT_USER2
LINKTYPES = {"zk": LINKTYPE_ZK, "zap": LINKTYPE_ZAP, "modbus": LINKTYPE_MODBUS}
PROTOCOL_BY_LINKTYPE = {v: k for k, v in LINKTYPES.items()}
PROTOCOL_NAMES = {"zk": "ZK", "zap": "mightyZAP", "modbus": "mightyZAP Modbus RTU"}

#: Directions: epb_flags values and the short names records carry in ``dir``.
UNKNOWN, INBOUND, OUTBOUND = 0, 1, 2
DIR_NAMES = {INBOUND: "d2h", OUTBOUND: "h2d", UNKNOWN: None}

_OPT_END, _OPT_COMMENT = 0, 1
_IF_NAME, _IF_DESCRIPTION, _IF_TSRESOL = 2, 3, 9
_SHB_USERAPPL = 4
_EPB_FLAGS = 2

#: A few link types by name, for the message refusing a capture of something else.
_KNOWN_LINKTYPES = {0: "NULL", 1: "ETHERNET", 101: "RAW", 113: "LINUX_SLL", 127: "IEEE802_11_RADIOTAP",
                    147: "USER0", 148: "USER1", 149: "USER2", 189: "USB_LINUX_MMAPPED", 220: "USB_LINUX_MMAPPED",
                    249: "USBPCAP", 276: "LINUX_SLL2"}


def _pad(n: int) -> int:
    return (4 - n % 4) % 4


def _option(code: int, value: bytes) -> bytes:
    return struct.pack("<HH", code, len(value)) + value + b"\0" * _pad(len(value))


def _block(btype: int, body: bytes) -> bytes:
    length = 12 + len(body)
    return struct.pack("<II", btype, length) + body + struct.pack("<I", length)


def _options(items) -> bytes:
    out = b"".join(_option(c, v) for c, v in items if v is not None)
    return out + struct.pack("<HH", _OPT_END, 0) if out else b""


def section_header(app: str) -> bytes:
    body = struct.pack("<IHHq", _BOM, 1, 0, -1) + _options([(_SHB_USERAPPL, app.encode())])
    return _block(SHB, body)


def interface_block(linktype: int, name: str, description: str) -> bytes:
    body = struct.pack("<HHI", linktype, 0, 0) + _options(
        [(_IF_NAME, name.encode("utf-8", "replace")), (_IF_DESCRIPTION, description.encode("utf-8", "replace")),
         (_IF_TSRESOL, b"\x06")])
    return _block(IDB, body)


def packet_block(if_id: int, ts_us: int, data: bytes, direction: int = UNKNOWN) -> bytes:
    n = len(data)
    body = struct.pack("<IIIII", if_id, (ts_us >> 32) & 0xFFFFFFFF, ts_us & 0xFFFFFFFF, n, n) + bytes(data) \
        + b"\0" * _pad(n) + (_options([(_EPB_FLAGS, struct.pack("<I", direction))]) if direction else b"")
    return _block(EPB, body)


class Writer:
    """A pcapng file being written: :meth:`interface` adds a port, :meth:`packet` a chunk.

    Thread-safe (a sniffer reads two ports in two threads). ``path`` is opened (created or
    truncated in place; ``append`` adds a new section to an existing capture) by the first
    packet, with the section header and the interfaces described so far: a command that never
    sends or receives a byte leaves an existing file as it was (a header is not a record). A
    device or FIFO is written through."""

    def __init__(self, path: str, *, append: bool = False, app: str | None = None):
        self.path = path
        self.append = append
        self.app = app or _app()
        self._fd = None
        self._good = 0
        self._regular = False
        self._lock = threading.Lock()
        self._interfaces = 0
        self._pending = []                 # interface blocks waiting for the first packet
        self.failed = None
        self.packets = 0

    def open(self) -> None:
        """Open the file and write the section header now (the first packet does otherwise)."""
        with self._lock:
            self._open()

    def _open(self):
        if self._fd is not None:
            return
        from .. import checking

        checking.effect("file", path=self.path)
        flags = os.O_WRONLY | os.O_CREAT | (os.O_APPEND if self.append else os.O_TRUNC)
        try:
            self._fd = os.open(self.path, flags, 0o666)
        except OSError as e:
            raise UsageError(f"capture: cannot open {self.path}: {e.strerror}") from None
        try:
            self._regular = stat.S_ISREG(os.fstat(self._fd).st_mode)
            self._good = os.lseek(self._fd, 0, os.SEEK_END) if self._regular else 0
        except OSError:
            self._regular = False
        self._put(section_header(self.app))
        pending, self._pending = self._pending, []
        for block in pending:
            self._put(block)

    def interface(self, protocol: str, name: str, baud=None) -> int:
        """Describe a port; returns its interface ID for :meth:`packet` (written before the
        first packet)."""
        linktype = LINKTYPES[protocol]
        desc = f"zkzap {PROTOCOL_NAMES[protocol]}" + (f" {baud} baud" if baud else "")
        with self._lock:
            block = interface_block(linktype, name, desc)
            if self._fd is None:
                self._pending.append(block)
            else:
                self._put(block)
            n = self._interfaces
            self._interfaces += 1
            return n

    def packet(self, if_id: int, ts: float, data: bytes, direction: int = UNKNOWN) -> None:
        """One chunk, stamped ``ts`` (POSIX seconds), in ``direction`` (INBOUND/OUTBOUND)."""
        if not data:
            return
        block = packet_block(if_id, int(round(ts * 1_000_000)), data, direction)
        with self._lock:
            if self._fd is None:
                self._open()
            self._put(block)
            self.packets += 1

    def _put(self, block: bytes) -> None:
        if self.failed is not None:
            raise self.failed
        fd = self._fd
        data = memoryview(block)
        try:
            with held():
                while data:
                    data = data[os.write(fd, data):]
        except OSError as e:
            if self._regular:
                try:
                    os.ftruncate(fd, self._good)        # back to the last whole block
                except OSError:
                    pass
            self.failed = OutputError(f"capture: cannot write {self.path}: {e.strerror or e}")
            raise self.failed from None
        self._good += len(block)

    def close(self) -> None:
        with self._lock:
            if self._fd is not None:
                try:
                    os.close(self._fd)
                except OSError:
                    pass
                self._fd = None


def _app() -> str:
    from .. import __version__

    return f"zkzap {__version__}"


# --- reading -----------------------------------------------------------------------------------

class Packet:
    """One chunk of a capture: ``ts`` (POSIX seconds), ``data``, ``direction``, ``interface``."""

    __slots__ = ("interface", "ts", "data", "direction", "protocol", "name")

    def __init__(self, interface, ts, data, direction, protocol, name):
        self.interface, self.ts, self.data, self.direction = interface, ts, data, direction
        self.protocol, self.name = protocol, name

    @property
    def dir(self):
        return DIR_NAMES.get(self.direction)

    def __repr__(self):
        return f"Packet(if={self.interface}, ts={self.ts:.6f}, dir={self.dir}, data={self.data.hex(' ')})"


class CaptureError(UsageError):
    """Not a pcapng capture, or not one of zkzap's link types (exit 2)."""


def is_pcapng(path: str) -> bool:
    """Whether the file at ``path`` starts with a pcapng section header ('-' is never)."""
    if not path or path == "-":
        return False
    try:
        with open_input(path) as f:
            return f.read(4) == MAGIC
    except OSError:
        return False


def describe_start(head: bytes) -> str:
    """What a file that is not pcapng seems to be, from its first bytes."""
    if not head:
        return "an empty file"
    if head[:4] in (b"\xd4\xc3\xb2\xa1", b"\xa1\xb2\xc3\xd4", b"\x4d\x3c\xb2\xa1", b"\xa1\xb2\x3c\x4d"):
        return "a pcap (libpcap) file, not pcapng"
    shown = " ".join(f"{b:02X}" for b in head[:4])
    if all(32 <= b < 127 or b in (9, 10, 13) for b in head[:64]):
        return f"text (starts with {shown})"
    return f"data starting with {shown}"


#: The longest block read (bytes; Wireshark's own bound): a longer length field is damage.
MAX_BLOCK = 16 << 20
#: Pieces in which a block body is read, so memory follows the bytes that are really there.
_PIECE = 1 << 16
#: The latest time a packet may carry (9999-12-31T23:59:59Z): later is a damaged timestamp.
MAX_TS = 253402300799.0


class Reader:
    """Iterate the packets of a pcapng file in file order.

    ``protocol`` ('zk'/'zap'/None) refuses a capture whose first interface is of another link
    type (CaptureError naming the file and what was found). A capture is read whatever its
    blocks claim: no length field is trusted before it is checked against the file (and
    against :data:`MAX_BLOCK`), and bodies are read in bounded pieces, so memory stays one
    block of what is really there. After iterating:

    - :attr:`truncated`: the file ended inside a block (everything before it was read);
    - :attr:`damaged`: ``(byte offset, what)`` of a block whose framing is broken (a length
      field that cannot be, opening and closing lengths that differ); reading stopped there,
      since nothing after it can be found;
    - :attr:`malformed`: blocks whose framing is sound but whose body is not (shorter than its
      fields, a packet of an interface never described, a time beyond the year 9999), skipped
      (:attr:`first_malformed`: ``(byte offset, what)`` of the first);
    - :attr:`foreign`: packets of a later interface of another link type or protocol, skipped;
    - :attr:`packets`: the packets read.
    """

    def __init__(self, path: str, protocol: str | None = None):
        self.path = path
        self.protocol = protocol
        self.truncated = False
        self.damaged = None
        self.malformed = 0
        self.first_malformed = None
        self.foreign = 0
        self.packets = 0
        self.interfaces = []          # (protocol, name, tsresol divisor), or None: skipped
        try:
            self._f = open_input(path)
        except OSError as e:
            raise UsageError(f"capture: cannot read {path}: {e.strerror}") from None
        try:
            st = os.fstat(self._f.fileno())
            self._size = st.st_size if stat.S_ISREG(st.st_mode) else None
            head = self._f.read(12)
        except OSError as e:
            self._f.close()
            raise UsageError(f"capture: cannot read {path}: {e.strerror or e}") from None
        if head[:4] != MAGIC:
            self._f.close()
            raise CaptureError(f"{path}: not a pcapng capture: {describe_start(head)}")
        self._f.seek(0)

    def close(self):
        self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _read(self, n: int) -> bytes:
        """Up to ``n`` bytes, read in bounded pieces (short only at the end of the file)."""
        f = self._f
        if n <= _PIECE:
            return f.read(n)
        parts, got = [], 0
        while got < n:
            piece = f.read(min(_PIECE, n - got))
            if not piece:
                break
            parts.append(piece)
            got += len(piece)
        return b"".join(parts)

    def _damage(self, offset: int, what: str):
        if offset == 0:
            raise CaptureError(f"{self.path}: not a pcapng capture: {what} at byte 0")
        self.damaged = (offset, what)

    def _skip(self, offset: int, what: str):
        self.malformed += 1
        if self.first_malformed is None:
            self.first_malformed = (offset, what)

    def __iter__(self):
        endian = "<"
        offset = 0
        while True:
            head = self._read(8)
            if not head:
                return
            if len(head) < 8:
                self.truncated = True
                return
            if head[:4] == MAGIC:
                # a new section: its byte order comes from the byte-order magic
                bom = self._read(4)
                if len(bom) < 4:
                    self.truncated = True
                    return
                if struct.unpack("<I", bom)[0] == _BOM:
                    endian = "<"
                elif struct.unpack(">I", bom)[0] == _BOM:
                    endian = ">"
                else:
                    self._damage(offset, f"a section header without the byte-order magic ({bom.hex(' ')})")
                    return
                btype, length = SHB, struct.unpack(endian + "I", head[4:])[0]
                lead = bom
            else:
                btype, length = struct.unpack(endian + "II", head)
                lead = b""
            if length < 12 + len(lead) or length % 4 or length > MAX_BLOCK:
                self._damage(offset, f"a block of length {length}" + (
                    f" (at most {MAX_BLOCK} bytes)" if length > MAX_BLOCK else
                    " (at least 12 and a multiple of 4)"))
                return
            if self._size is not None and offset + length > self._size:
                self.truncated = True          # the file ends inside this block: nothing is read
                return
            rest = self._read(length - 8 - len(lead))
            if len(rest) < length - 8 - len(lead):
                self.truncated = True
                return
            body, tail = lead + rest[:-4], rest[-4:]
            closing = struct.unpack(endian + "I", tail)[0]
            if closing != length:
                self._damage(offset, f"a block whose closing length {closing} differs from its opening "
                                     f"length {length}")
                return
            at, offset = offset, offset + length
            if btype == SHB:
                self.interfaces = []
            elif btype == IDB:
                self._interface(body, endian, at)
            elif btype == EPB:
                pkt = self._packet(body, endian, at)
                if pkt is not None:
                    self.packets += 1
                    yield pkt
            elif btype == SPB and self.interfaces:
                pkt = self._simple(body, endian, at)
                if pkt is not None:
                    self.packets += 1
                    yield pkt

    def _interface(self, body, endian, at):
        n = len(self.interfaces)
        if len(body) < 8:
            self.interfaces.append(None)
            self._skip(at, f"interface {n} described in {len(body)} bytes (8 at least)")
            return
        linktype = struct.unpack(endian + "H", body[:2])[0]
        proto = PROTOCOL_BY_LINKTYPE.get(linktype)
        wrong = None
        if proto is None:
            shown = _KNOWN_LINKTYPES.get(linktype)
            wrong = (f"{self.path}: interface {n} has link type {linktype}"
                     f"{f' ({shown})' if shown else ''}; zkzap captures use {LINKTYPE_ZK} "
                     f"(USER0, ZK), {LINKTYPE_ZAP} (USER1, mightyZAP) and {LINKTYPE_MODBUS} "
                     "(USER2, mightyZAP Modbus RTU)")
        elif self.protocol is not None and proto != self.protocol:
            wrong = (f"{self.path}: a {PROTOCOL_NAMES[proto]} capture (link type {linktype}); "
                     f"expected {PROTOCOL_NAMES[self.protocol]} (link type {LINKTYPES[self.protocol]})")
        if wrong is not None:
            if not self.packets and not any(self.interfaces):
                raise CaptureError(wrong)      # the capture's own first interface: not ours
            self.interfaces.append(None)       # a later one: its packets are skipped and counted
            return
        name, div = "", 1_000_000
        for code, value in _iter_options(body[8:], endian):
            if code == _IF_NAME:
                name = value.decode("utf-8", "replace")
            elif code == _IF_TSRESOL and value:
                r = value[0]
                div = 2 ** (r & 0x7F) if r & 0x80 else 10 ** r
        self.interfaces.append((proto, name, div))

    def _described(self, if_id, at):
        """The interface of a packet: (proto, name, div), or None (the packet is skipped)."""
        if if_id >= len(self.interfaces):
            self._skip(at, f"a packet of interface {if_id}, which was never described")
            return None
        iface = self.interfaces[if_id]
        if iface is None:
            self.foreign += 1
        return iface

    def _packet(self, body, endian, at):
        if len(body) < 20:
            self._skip(at, f"a packet block of {len(body) + 12} bytes (32 at least)")
            return None
        if_id, hi, lo, caplen = struct.unpack(endian + "IIII", body[:16])
        if 20 + caplen > len(body):
            self._skip(at, f"a packet of {caplen} bytes in a block of {len(body) + 12}")
            return None
        iface = self._described(if_id, at)
        if iface is None:
            return None
        proto, name, div = iface
        ts = ((hi << 32) | lo) / div
        if ts > MAX_TS:
            self._skip(at, f"a packet time of {ts:.0f} s, after the year 9999")
            return None
        data = bytes(body[20:20 + caplen])
        direction = UNKNOWN
        for code, value in _iter_options(body[20 + caplen + _pad(caplen):], endian):
            if code == _EPB_FLAGS and len(value) >= 4:
                direction = struct.unpack(endian + "I", value[:4])[0] & 3
        return Packet(if_id, ts, data, direction, proto, name)

    def _simple(self, body, endian, at):
        if len(body) < 4:
            self._skip(at, f"a simple packet block of {len(body) + 12} bytes (16 at least)")
            return None
        iface = self._described(0, at)
        if iface is None:
            return None
        n = struct.unpack(endian + "I", body[:4])[0]
        proto, name, div = iface
        return Packet(0, 0.0, bytes(body[4:4 + n]), UNKNOWN, proto, name)

    def problems(self) -> list:
        """What the capture holds that was not read, as phrases (empty when it was all whole)."""
        out = []
        if self.malformed:
            offset, what = self.first_malformed
            out.append(f"{self.malformed} malformed block{'s' if self.malformed > 1 else ''} skipped "
                       f"(the first at byte {offset}: {what})")
        if self.foreign:
            out.append(f"{self.foreign} chunk{'s' if self.foreign > 1 else ''} of interfaces of another "
                       "link type skipped")
        if self.damaged is not None:
            offset, what = self.damaged
            out.append(f"damaged at byte {offset} ({what}): decoded up to there ({self.packets} chunks)")
        elif self.truncated:
            out.append(f"the capture is truncated: decoded up to its last whole block ({self.packets} chunks)")
        return out


def _iter_options(buf, endian):
    i = 0
    while i + 4 <= len(buf):
        code, n = struct.unpack(endian + "HH", buf[i:i + 4])
        if code == _OPT_END:
            return
        yield code, bytes(buf[i + 4:i + 4 + n])
        i += 4 + n + _pad(n)


def capture_protocol(path: str) -> str | None:
    """The protocol of a zkzap capture's first interface (``zk``, ``zap``, ``modbus``), None
    when it describes none; a file that is no zkzap capture is a CaptureError."""
    with Reader(path) as r:
        for _ in r:
            break
        return next((i[0] for i in r.interfaces if i is not None), None)


def check_capture(path: str, protocol: str | None = None) -> None:
    """Refuse (CaptureError, exit 2) a file that is not a zkzap capture of ``protocol``, reading
    only its headers up to the first packet: called before any output is written."""
    with Reader(path, protocol) as r:
        for _ in r:
            break
