"""pcapng captures of serial traffic: every chunk read or written, with its time and direction.

Layout (pcapng, little-endian, as written here):

- one Section Header Block (``shb_userappl`` = ``zkzap VERSION``);
- one Interface Description Block per port opened, with a user link type that names the
  protocol: :data:`LINKTYPE_ZK` = 147 (``DLT_USER0``) for the ZK ECU protocol,
  :data:`LINKTYPE_ZAP` = 148 (``DLT_USER1``) for mightyZAP; ``if_name`` is the port, and
  ``if_description`` says ``zkzap ZK 115200 baud``; timestamps in microseconds (the default
  ``if_tsresol``);
- one Enhanced Packet Block per chunk, its direction in ``epb_flags`` bits 0-1: 1 inbound
  (device -> host, what the host read), 2 outbound (host -> device, what it wrote), 0 unknown
  (a sniffer on a half-duplex bus sees both on one line).

Each block is written with one ``write`` loop that SIGINT/SIGTERM cannot cut and flushed at
once, so a killed process leaves a whole capture; when a write fails (disk full) a regular file
is cut back to its last whole block and :class:`~zkzap.errors.OutputError` is raised. The
reader stops at the last whole block of a truncated file and says so (:attr:`Reader.truncated`).
"""

from __future__ import annotations

import os
import stat
import struct
import threading

from ..errors import OutputError, UsageError
from ..signals import held

MAGIC = b"\x0a\x0d\x0d\x0a"
_BOM = 0x1A2B3C4D
SHB, IDB, EPB, SPB = 0x0A0D0D0A, 1, 6, 3

LINKTYPE_ZK = 147     # DLT_USER0
LINKTYPE_ZAP = 148    # DLT_USER1
LINKTYPES = {"zk": LINKTYPE_ZK, "zap": LINKTYPE_ZAP}
PROTOCOL_BY_LINKTYPE = {v: k for k, v in LINKTYPES.items()}
PROTOCOL_NAMES = {"zk": "ZK", "zap": "mightyZAP"}

#: Directions: epb_flags values and the short names records carry in ``dir``.
UNKNOWN, INBOUND, OUTBOUND = 0, 1, 2
DIR_NAMES = {INBOUND: "d2h", OUTBOUND: "h2d", UNKNOWN: None}

_OPT_END, _OPT_COMMENT = 0, 1
_IF_NAME, _IF_DESCRIPTION, _IF_TSRESOL = 2, 3, 9
_SHB_USERAPPL = 4
_EPB_FLAGS = 2

#: A few link types by name, for the message refusing a capture of something else.
_KNOWN_LINKTYPES = {0: "NULL", 1: "ETHERNET", 101: "RAW", 113: "LINUX_SLL", 127: "IEEE802_11_RADIOTAP",
                    147: "USER0", 148: "USER1", 189: "USB_LINUX_MMAPPED", 220: "USB_LINUX_MMAPPED",
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
        with open(path, "rb") as f:
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


class Reader:
    """Iterate the packets of a pcapng file in file order.

    ``protocol`` ('zk'/'zap'/None) refuses interfaces of another link type (CaptureError naming
    the file and what was found). After iterating, :attr:`truncated` tells whether the file
    ended inside a block (everything before it was read) and :attr:`packets` how many there
    were. Memory is constant: one block at a time."""

    def __init__(self, path: str, protocol: str | None = None):
        self.path = path
        self.protocol = protocol
        self.truncated = False
        self.packets = 0
        self.interfaces = []          # (protocol, name, tsresol divisor)
        try:
            self._f = open(path, "rb")
        except OSError as e:
            raise UsageError(f"capture: cannot read {path}: {e.strerror}") from None
        head = self._f.read(12)
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

    def __iter__(self):
        f = self._f
        endian = "<"
        while True:
            head = f.read(8)
            if not head:
                return
            if len(head) < 8:
                self.truncated = True
                return
            if head[:4] == MAGIC:
                # a new section: its byte order comes from the byte-order magic
                bom = f.read(4)
                if len(bom) < 4:
                    self.truncated = True
                    return
                endian = "<" if struct.unpack("<I", bom)[0] == _BOM else ">"
                btype, length = SHB, struct.unpack(endian + "I", head[4:])[0]
                body = bom + f.read(max(0, length - 16))
                self.interfaces = []
            else:
                btype, length = struct.unpack(endian + "II", head)
                body = f.read(max(0, length - 12))
            if length < 12 or length % 4:
                raise CaptureError(f"{self.path}: not a pcapng capture: a block of length {length} "
                                   f"at byte {f.tell() - len(body) - 8}")
            tail = f.read(4)
            if len(body) < length - 12 or len(tail) < 4:
                self.truncated = True
                return
            if btype == IDB:
                self._interface(body, endian)
            elif btype == EPB:
                pkt = self._packet(body, endian)
                if pkt is not None:
                    self.packets += 1
                    yield pkt
            elif btype == SPB and self.interfaces:
                n = struct.unpack(endian + "I", body[:4])[0]
                proto, name, div = self.interfaces[0]
                self.packets += 1
                yield Packet(0, 0.0, bytes(body[4:4 + n]), UNKNOWN, proto, name)

    def _interface(self, body, endian):
        linktype = struct.unpack(endian + "H", body[:2])[0]
        proto = PROTOCOL_BY_LINKTYPE.get(linktype)
        n = len(self.interfaces)
        if proto is None:
            shown = _KNOWN_LINKTYPES.get(linktype)
            raise CaptureError(f"{self.path}: interface {n} has link type {linktype}"
                               f"{f' ({shown})' if shown else ''}; zkzap captures use {LINKTYPE_ZK} "
                               f"(USER0, ZK) and {LINKTYPE_ZAP} (USER1, mightyZAP)")
        if self.protocol is not None and proto != self.protocol:
            raise CaptureError(f"{self.path}: a {PROTOCOL_NAMES[proto]} capture (link type {linktype}); "
                               f"expected {PROTOCOL_NAMES[self.protocol]} "
                               f"(link type {LINKTYPES[self.protocol]})")
        name, div = "", 1_000_000
        for code, value in _iter_options(body[8:], endian):
            if code == _IF_NAME:
                name = value.decode("utf-8", "replace")
            elif code == _IF_TSRESOL and value:
                r = value[0]
                div = 2 ** (r & 0x7F) if r & 0x80 else 10 ** r
        self.interfaces.append((proto, name, div))

    def _packet(self, body, endian):
        if_id, hi, lo, caplen = struct.unpack(endian + "IIII", body[:16])
        if if_id >= len(self.interfaces):
            raise CaptureError(f"{self.path}: a packet of interface {if_id}, which was never described")
        proto, name, div = self.interfaces[if_id]
        data = bytes(body[20:20 + caplen])
        direction = UNKNOWN
        for code, value in _iter_options(body[20 + caplen + _pad(caplen):], endian):
            if code == _EPB_FLAGS and len(value) >= 4:
                direction = struct.unpack(endian + "I", value[:4])[0] & 3
        return Packet(if_id, ((hi << 32) | lo) / div, data, direction, proto, name)


def _iter_options(buf, endian):
    i = 0
    while i + 4 <= len(buf):
        code, n = struct.unpack(endian + "HH", buf[i:i + 4])
        if code == _OPT_END:
            return
        yield code, bytes(buf[i + 4:i + 4 + n])
        i += 4 + n + _pad(n)


def check_capture(path: str, protocol: str | None = None) -> None:
    """Refuse (CaptureError, exit 2) a file that is not a zkzap capture of ``protocol``, reading
    only its headers up to the first packet: called before any output is written."""
    with Reader(path, protocol) as r:
        for _ in r:
            break
