"""Hex text in and out.

Accepted input notations: ``FF 14 64``, ``ff1464``, ``0xFF,0x14,0x64``, ``FF:14:64``,
``FF-14-64``, ``\\xff\\x14``, ``#`` comments, logic-analyser CSV exports (their ``0x..``
byte column), and dump lines from ``xxd`` (``00000010: ff14 ...`` and its ASCII column),
``hexdump -C`` (offset, ``|ascii|`` gutter) and ``od -A x -t x1`` (an odd-length offset).
An offset is dropped only where it cannot be data: it ends in a colon, is followed by a
``|...|`` gutter, or has an odd number of digits.
Output is uppercase hex bytes separated by single spaces.
"""

from __future__ import annotations

import re

_HEX_DIGITS = frozenset("0123456789abcdefABCDEF")
_PATTERNS = {
    "colon_offset": r"^\s*(?:0[xX])?[0-9A-Fa-f]{1,16}:(?=\s)",
    "gutter": r"\s\s\|.*\|\s*$",
    "hexdump_offset": r"^\s*[0-9A-Fa-f]{4,16}\s",
    "odd_offset": r"^\s*[0-9A-Fa-f]{5}(?:[0-9A-Fa-f]{2})*\s",
    "end_offset": r"^\s*[0-9A-Fa-f]{7,8}\s*$",
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


class HexError(ValueError):
    """Malformed hex text."""


def format_hex(data) -> str:
    """``b"\\xff\\x1d"`` -> ``"FF 1D"``."""
    return bytes(data).hex(" ").upper()


def _strip_dump(line: str):
    """(line without offset and gutter, whether it was a dump line)."""
    m = _rx.colon_offset.match(line)
    if m:
        rest = line[m.end():].strip()
        # xxd: hex groups, then two or more spaces, then the ASCII column
        return _rx.wide_gap.split(rest, maxsplit=1)[0], True
    g = _rx.gutter.search(line)
    if g:
        line = line[:g.start()]
        m = _rx.hexdump_offset.match(line)
        return (line[m.end():] if m else line), True
    m = _rx.odd_offset.match(line)
    if m:
        return line[m.end():], True
    return line, False


def parse_hex_line(line: str, *, what: str = "hex input", lineno: int = 0, state=None) -> bytes:
    """Parse one line of hex text (dump offsets and gutters dropped). Raises :class:`HexError`.

    ``state`` (a dict kept across the lines of one input) lets the lone final-offset line that
    ``hexdump`` and ``od`` print after a dump be recognised as such, and the header line of a
    logic analyser's CSV export be skipped.

    A logic analyser's CSV export (``0.000086800,0x14,,`` or
    ``"Async Serial","data",0.0011,8.68e-05,0x14``) gives its ``0x..`` byte fields; the
    timestamps and names beside them are not data.
    """
    line = line.split("#", 1)[0]
    if not line.strip():
        return b""
    first = state is not None and not state.get("seen")
    if state is not None:
        state["seen"] = True
    try:
        return _parse_tokens(line, what, lineno, state)
    except HexError:
        if "," not in line:
            raise
        found = _rx.csv_byte.findall(line)
        if found:
            return bytes(int(b, 16) for b in found)
        if first:
            return b""              # the header row of a CSV export: "Time [s],Value,..."
        raise


def _parse_tokens(line, what, lineno, state) -> bytes:
    line, dump = _strip_dump(line)
    if state is not None:
        if not dump and state.get("dump") and _rx.end_offset.match(line):
            return b""
        state["dump"] = dump
    line = line.replace("\\x", " ").replace("\\X", " ")
    out = bytearray()
    where = f" (line {lineno})" if lineno else ""
    for token in _rx.split.split(line):
        if not token:
            continue
        prefixed = token[:2] in ("0x", "0X")
        if prefixed:
            token = token[2:]
        if not token or not _HEX_DIGITS.issuperset(token):
            raise HexError(f"{what}: {token!r} is not hex{where}; expected bytes such as 'FF 14 64' or '0xFF,0x14'")
        if len(token) % 2:
            if prefixed and len(token) == 1:
                token = "0" + token
            else:
                raise HexError(f"{what}: {token!r} has an odd number of hex digits{where}; every byte needs two")
        out += bytes.fromhex(token)
    return bytes(out)


def parse_hex(text: str, *, what: str = "hex input") -> bytes:
    """Parse hex text of one or more lines. Raises :class:`HexError`."""
    lines = text.splitlines()
    if len(lines) <= 1:
        return parse_hex_line(text, what=what)
    state = {}
    return b"".join(parse_hex_line(line, what=what, lineno=i, state=state) for i, line in enumerate(lines, 1))


def iter_hex_stream(stream, *, what: str = "stdin"):
    """Yield the bytes of each line of a text stream, one line at a time (constant memory)."""
    state = {}
    for i, line in enumerate(stream, 1):
        data = parse_hex_line(line, what=what, lineno=i, state=state)
        if data:
            yield data
