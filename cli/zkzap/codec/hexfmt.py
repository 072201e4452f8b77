"""Hex text in and out.

Accepted input notations: ``FF 14 64``, ``ff1464``, ``0xFF,0x14,0x64``, ``FF:14:64``,
``FF-14-64``, ``\\xff\\x14``, ``#`` comments, logic-analyser CSV exports (their ``0x..``
byte cells; a row that mixes ``0x..`` cells with others, such as a time column
``1e-05,0x1D`` or ``10,0xFF``, gives only its ``0x..`` cells), and dump lines from ``xxd``
(``00000010: ff14 ...`` and its ASCII column), ``hexdump -C`` (offset, ``|ascii|`` gutter),
``od -t x1`` (a 7-digit offset) and ``od -A x -t x1`` (a 6-digit offset before single bytes:
``000000`` on the first line, any on the lines of a dump after it), with od's ``z`` column
(``-t x1z``: ``>ascii<`` after two spaces) too. An offset is dropped only where it cannot be
data: it ends in a colon, is followed by a ``|...|`` or ``>...<`` gutter, has an odd number of
digits, or is od's 6-digit form.
The ``*`` lines of ``hexdump``/``od``/``xxd -a`` (the line before repeats up to the next
offset) are expanded, in blocks, whatever the length they stand for; the radix of od's
offsets (hex, octal, decimal) is read from two consecutive offsets, else hex for 6 or 8
digits and octal (od's default) for 7. Text with control characters or invalid UTF-8 is
binary: refused with a pointer to ``--binary``. A stream is read in pieces of at most
64 Ki characters, so one line of any length decodes in constant memory; once it has given
bytes, a line that is not hex is damage, skipped and counted (:class:`HexSkips`).
Output is uppercase hex bytes separated by single spaces.
"""

from __future__ import annotations

import re

from ..errors import InvalidValue

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Iterable, Iterator, Optional, TextIO, Union

_HEX_DIGITS = frozenset("0123456789abcdefABCDEF")
_PATTERNS = {
    "colon_offset": r"^\s*(?:0[xX])?[0-9A-Fa-f]{1,16}:(?=\s)",
    # hexdump -C's |ascii| and od -t x1z's >ascii< column after two spaces (the hex part holds
    # neither character, so the first such start is the column's)
    "gutter": r"\s\s(?:\|.*\||>.*<)\s*$",
    "hexdump_offset": r"^\s*[0-9A-Fa-f]{4,16}\s",
    "odd_offset": r"^\s*[0-9A-Fa-f]{5}(?:[0-9A-Fa-f]{2})*\s",
    "end_offset": r"^\s*([0-9A-Fa-f]{6,8})\s*$",
    "od6_offset": r"^\s*([0-9A-Fa-f]{6})(?= [0-9A-Fa-f]{2}(?: [0-9A-Fa-f]{2})*\s*$)",
    "csv_cell_byte": r'"?0[xX]([0-9A-Fa-f]{1,2})"?',
    # control characters, and what is not UTF-8 (U+FFFD, or surrogate escapes of raw bytes)
    "binary": "[\x00-\x08\x0e-\x1f\x7f\ufffd\udc80-\udcff]",
    "separator": r"[\s,:;\-\\]",
    "split": r"[\s,:;\-]+",
    "wide_gap": r"\s{2,}",
    "csv_byte": r"(?<![0-9A-Za-z.])0[xX]([0-9A-Fa-f]{1,2})(?![0-9A-Za-z.])",
}


class _Patterns:
    """The patterns above, compiled on first use: composing a frame only formats hex."""

    def __getattr__(self, name):
        if name not in _PATTERNS:
            raise AttributeError(name)
        rx = re.compile(_PATTERNS[name])
        setattr(self, name, rx)
        return rx


_rx = _Patterns()


class HexError(InvalidValue):
    """Malformed hex text (a :class:`zkzap.errors.InvalidValue`, so also a ``ValueError``)."""


def format_hex(data: Union[bytes, bytearray, memoryview, Iterable[int]]) -> str:
    """``b"\\xff\\x1d"`` -> ``"FF 1D"``."""
    return bytes(data).hex(" ").upper()


#: The largest block a ``*`` repeat line is expanded in.
BLOCK = 1 << 16


def _strip_dump(line: str, state=None):
    """(line without offset and gutter, offset text or None, whether it was a dump line)."""
    m = _rx.colon_offset.match(line)
    if m:
        rest = line[m.end():].strip()
        off = m.group(0).strip().rstrip(":")
        off = off[2:] if off[:2] in ("0x", "0X") else off
        # xxd: hex groups, then two or more spaces, then the ASCII column
        return _rx.wide_gap.split(rest, maxsplit=1)[0], off, True
    g = _rx.gutter.search(line)
    if g:
        line = line[:g.start()]
        m = _rx.hexdump_offset.match(line)
        return (line[m.end():], m.group(0).strip(), True) if m else (line, None, True)
    m = _rx.odd_offset.match(line)
    if m:
        return line[m.end():], m.group(0).strip(), True
    m = _rx.od6_offset.match(line)
    if m and (m.group(1) == "000000" or (state is not None and state.get("dump"))):
        return line[m.end():], m.group(1), True
    return line, None, False


def _binary(what, lineno):
    where = f" (line {lineno})" if lineno else ""
    return HexError(f"{what}: binary input{where}: use --binary for raw bytes")


def parse_hex_line(line: str, *, what: str = "hex input", lineno: int = 0,
                   state: Optional[dict[str, Any]] = None) -> bytes:
    """Parse one line of hex text (dump offsets and gutters dropped). Raises :class:`HexError`.

    ``state`` (a dict kept across the lines of one input) lets the lone final-offset line that
    ``hexdump`` and ``od`` print after a dump be recognised as such, ``*`` repeat lines be
    expanded, and the header line of a logic analyser's CSV export be skipped.

    A logic analyser's CSV export (``0.000086800,0x14,,`` or
    ``"Async Serial","data",0.0011,8.68e-05,0x14``) gives its ``0x..`` byte fields; the
    timestamps and names beside them are not data.
    """
    return b"".join(_line_pieces(line, what, lineno, state))


def _line_pieces(line, what, lineno, state):
    """The bytes of one line, as pieces (a ``*`` line's expansion comes in blocks)."""
    g = _rx.gutter.search(line) if "|" in line or ">" in line else None
    if g is not None and "#" not in line[:g.start()]:
        pass                        # a '#' in a dump's ASCII column is no comment
    else:
        line = line.split("#", 1)[0]
    if not line.strip():
        return
    if _rx.binary.search(line):
        raise _binary(what, lineno)
    first = state is not None and not state.get("seen")
    if state is not None:
        state["seen"] = True
    if "," in line:
        cells = [c.strip() for c in line.split(",")]
        data = [_rx.csv_cell_byte.fullmatch(c) for c in cells]
        if any(data) and any(c and d is None for c, d in zip(cells, data)):
            # an analyser row: a time column, names, flags beside the 0x.. byte cells
            yield bytes(int(d.group(1), 16) for d in data if d is not None)
            return
    try:
        yield from _dump_pieces(line, what, lineno, state)
    except HexError:
        if "," not in line:
            raise
        found = _rx.csv_byte.findall(line)
        if found:
            yield bytes(int(b, 16) for b in found)
            return
        if first:
            return                  # the header row of a CSV export: "Time [s],Value,..."
        raise


def _dump_pieces(line, what, lineno, state):
    rest, off, dump = _strip_dump(line, state)
    if state is None:
        yield _tokens(rest, what, lineno)
        return
    if not dump and state.get("dump"):
        text = line.strip()
        if text == "*":
            if state.get("prev") is None:
                raise HexError(f"{what}: a '*' repeat line{_where(lineno)} before any dump line")
            state["repeat"] = True
            return
        m = _rx.end_offset.match(line)
        if m:                                           # the final offset: the dump's length
            yield from _expand(state, m.group(1), what, lineno)
            state["prev"] = None
            return
    if dump and off is not None:
        data = _tokens(rest, what, lineno)
        yield from _expand(state, off, what, lineno)
        state["prev"] = (off, data)
        state["dump"] = True
        yield data
        return
    if state.get("repeat"):
        raise HexError(f"{what}: a '*' repeat line{_where(lineno)} is not followed by an offset")
    state["dump"] = dump
    yield _tokens(rest, what, lineno)


def _where(lineno):
    return f" (line {lineno})" if lineno else ""


def _radix(state, off):
    """The radix of a dump's offsets: known from two consecutive lines, else guessed."""
    r = state.get("radix")
    if r:
        return r
    if len(off) == 7 and all(c in "01234567" for c in off):
        return 8                                        # od's default
    if len(off) == 7 and off.isdigit():
        return 10
    return 16


def _expand(state, off, what, lineno):
    """Infer the offsets' radix, and expand a pending ``*``: the previous line's bytes again,
    up to offset ``off``, in blocks of at most :data:`BLOCK` bytes."""
    prev = state.get("prev")
    if prev is None:
        state["repeat"] = False
        return
    p_off, p_data = prev
    if not state.get("repeat"):
        if not state.get("radix"):
            for r in ((16, 8, 10) if len(off) != 7 else (8, 10, 16)):
                try:
                    if int(off, r) - int(p_off, r) == len(p_data):
                        state["radix"] = r
                        break
                except ValueError:
                    continue
        return
    state["repeat"] = False
    r = _radix(state, off)
    try:
        n = int(off, r) - (int(p_off, r) + len(p_data))
    except ValueError:
        raise HexError(f"{what}: offset {off!r}{_where(lineno)} is not a number in the dump's radix "
                       f"({r})") from None
    if n < 0:
        raise HexError(f"{what}: offset {off}{_where(lineno)} is before the repeated line's end")
    if not p_data or not n:
        return
    block = p_data * max(1, BLOCK // len(p_data))
    while n > 0:
        piece = block[:n]
        n -= len(piece)
        yield piece


def _tokens(line, what, lineno) -> bytes:
    """Hex tokens without any dump offset or gutter."""
    line = line.replace("\\x", " ").replace("\\X", " ")
    out = bytearray()
    where = _where(lineno)
    for token in _rx.split.split(line):
        if not token:
            continue
        prefixed = token[:2] in ("0x", "0X")
        if prefixed:
            token = token[2:]
        if not token or not _HEX_DIGITS.issuperset(token):
            raise HexError(f"{what}: {token[:40]!r} is not hex{where}; expected bytes such as 'FF 14 64' "
                           f"or '0xFF,0x14'")
        if len(token) % 2:
            if prefixed and len(token) == 1:
                token = "0" + token
            else:
                raise HexError(f"{what}: {token[:40]!r} has an odd number of hex digits{where}; every byte "
                               f"needs two")
        out += bytes.fromhex(token)
    return bytes(out)


def parse_hex(text: str, *, what: str = "hex input") -> bytes:
    """Parse hex text of one or more lines. Raises :class:`HexError`."""
    lines = text.splitlines()
    if len(lines) <= 1:
        return parse_hex_line(text, what=what)
    state = {}
    return b"".join(parse_hex_line(line, what=what, lineno=i, state=state) for i, line in enumerate(lines, 1))


#: The longest piece of a line held at once by :func:`iter_hex_stream`.
PIECE = 1 << 16


class HexSkips:
    """Lines of a hex stream that were not hex after the stream had given bytes (damage in a
    long dump or capture, not a wrong input): how many, and the first one's message."""

    __slots__ = ("lines", "first")

    def __init__(self):
        self.lines = 0
        self.first = None

    def add(self, error) -> None:
        self.lines += 1
        if self.first is None:
            text = str(error)
            text = text.split(": ", 1)[-1]            # without the input's name: the note gives it
            for tail in ("; expected", "; every byte", ": use --binary"):
                text = text.split(tail, 1)[0]
            self.first = text

    def note(self):
        """One sentence, or None when no line was skipped."""
        if not self.lines:
            return None
        return (f"{self.lines} line{'s' if self.lines > 1 else ''} that {'are' if self.lines > 1 else 'is'} "
                f"not hex skipped (the first: {self.first})")


def iter_hex_stream(stream: TextIO, *, what: str = "stdin",
                    skipped: HexSkips | None = None) -> Iterator[bytes]:
    """Yield the bytes of a text stream's lines as they are read, in constant memory: a line
    longer than :data:`PIECE` characters (one long hex string, as some tools write) is taken
    in pieces cut at a separator or between two hex digits.

    A line that is not hex raises :class:`HexError`; with ``skipped``, once the stream has
    given bytes such a line is counted there and skipped instead (a stream that starts with
    something else is still refused)."""
    state = {}
    lineno = 0
    carry = ""                      # the start of a token cut by a piece boundary
    long_line = False               # inside a line longer than one piece
    comment = False                 # the rest of a long line is a comment (or skipped)
    given = False                   # bytes were yielded: later bad lines are damage

    def bad(e):
        if skipped is None or not given:
            raise e
        skipped.add(e)

    while True:
        try:
            piece = stream.readline(PIECE)
        except UnicodeDecodeError:
            bad(_binary(what, lineno + 1))
            lineno += 1
            continue
        except OSError as e:
            raise HexError(f"{what}: cannot read: {e.strerror or e}") from None
        if not piece:
            if carry and not comment:
                try:
                    data = _tokens(carry, what, lineno)
                except HexError as e:
                    bad(e)
                    return
                yield data
            return
        ends = piece.endswith("\n")
        if not long_line and (ends or len(piece) < PIECE):
            lineno += 1
            pieces = _line_pieces(piece, what, lineno, state)
            while True:
                try:
                    data = next(pieces)
                except StopIteration:
                    break
                except HexError as e:
                    bad(e)
                    break
                if data:
                    given = True
                    yield data
            continue
        if not long_line:
            lineno += 1
            long_line, comment, carry = True, False, ""
        if comment:
            long_line = not ends
            continue
        text = carry + piece
        if "#" in text:
            text, comment = text.split("#", 1)[0], True
        try:
            if _rx.binary.search(text):
                raise _binary(what, lineno)
            if ends or comment:
                head, carry = text, ""
            else:
                head, carry = _cut(text)
            data = _tokens(head, what, lineno)
        except HexError as e:
            bad(e)
            data, carry, comment = b"", "", True       # the rest of this line is skipped
        if data:
            given = True
            yield data
        if ends:
            long_line = False
            comment = False
        elif comment:
            carry = ""


def _cut(text):
    """(whole tokens, the start of the token the piece cut): at the last separator, or, in
    one long run of hex digits, after an even number of them."""
    i = len(text)
    while i > 0 and not _rx.separator.match(text[i - 1]):
        i -= 1
    if i > 0:
        if text[i - 1] == "\\":
            i -= 1                  # keep "\\x" together with its digits
        return text[:i], text[i:]
    prefix = 2 if text[:2] in ("0x", "0X") else 0
    digits = len(text) - prefix
    keep = prefix + digits - digits % 2
    if keep == prefix:
        return "", text             # "0x" or "0xF": wait for the digits
    return text[:keep], text[keep:]
