"""Text inputs named on the command line or in the API: a file, or ``-`` for standard input.

Every text zkzap reads comes from somewhere it does not control (a schedule someone edited, a
fleet file saved by another tool, a CSV copied from the field), so this is the one place that
turns bytes into text, with one set of messages:

- :func:`read_text` reads a whole document (schedules, limits, batches, fleet and summary
  files) of at most :data:`MAX_DOCUMENT` bytes;
- :func:`iter_lines` reads a file line by line (telemetry CSV and JSON Lines of any size), each
  line at most :data:`MAX_LINE` bytes, in constant memory.

Both take UTF-8 with or without a byte order mark (spreadsheets write one; it is dropped). Text
that is not UTF-8 — a UTF-16 file (its byte order mark says so), a binary file, a stray byte —
is a :class:`~zkzap.errors.UsageError` naming the input, the line and the byte offset of the
first bad byte: ``schedule: run.csv:3: not UTF-8 text (byte 0xFF at byte 41)``.
"""

from __future__ import annotations

from ..errors import UsageError
from ..infile import open_input

#: The largest document read whole (bytes): far above any schedule, limits, batch, fleet or
#: summary file (a backup of 254 actuators is about 0.5 MB); /dev/zero is refused, not read.
MAX_DOCUMENT = 32 << 20
#: The longest line :func:`iter_lines` takes (bytes): a telemetry CSV row is under 1 KB.
MAX_LINE = 1 << 20

_BOMS = ((b"\xef\xbb\xbf", None), (b"\x00\x00\xfe\xff", "UTF-32"), (b"\xff\xfe\x00\x00", "UTF-32"),
         (b"\xfe\xff", "UTF-16"), (b"\xff\xfe", "UTF-16"))


def _mib(n: int) -> str:
    return f"{n / (1 << 20):g} MiB"


def _drop_bom(data: bytes, what: str, name: str) -> bytes:
    """``data`` without a UTF-8 byte order mark; another encoding's mark is refused by name."""
    for bom, encoding in _BOMS:
        if data.startswith(bom):
            if encoding is None:
                return data[len(bom):]
            raise UsageError(f"{what}: {name}: {encoding} text (it starts with a {encoding} byte order mark); "
                             "save it as UTF-8")
    return data


def decode(data: bytes, what: str, name: str, expected: str = "", *, line: int = 1, offset: int = 0) -> str:
    """``data`` as UTF-8 text; UsageError naming the line (counted from ``line``) and the byte
    offset (from ``offset``) of the first byte that is not UTF-8."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        at = line + data.count(b"\n", 0, e.start)
        more = f"; expected {expected}" if expected else ""
        raise UsageError(f"{what}: {name}:{at}: not UTF-8 text (byte 0x{data[e.start]:02X} at byte "
                         f"{offset + e.start}){more}") from None


def _stdin_binary():
    import sys

    if sys.stdin is None:
        return None, None
    return getattr(sys.stdin, "buffer", None), sys.stdin


def read_bytes(path, what: str, limit: int = MAX_DOCUMENT) -> tuple:
    """``(data, name)``: at most ``limit`` bytes of ``path`` (``-``: standard input, named
    ``stdin``); more is a UsageError (the input is not what ``what`` names)."""
    if str(path) == "-":
        binary, text = _stdin_binary()
        if text is None:
            raise UsageError(f"{what}: no standard input")
        name = "stdin"
        if binary is None:                      # a text stream without bytes underneath (a test's StringIO)
            data = text.read(limit + 1).encode("utf-8", "surrogateescape")
        else:
            data = _read_limited(binary, limit, what, name)
    else:
        name = str(path)
        try:
            with open_input(path) as f:
                data = _read_limited(f, limit, what, name)
        except OSError as e:
            raise UsageError(f"{what}: cannot read {path}: {e.strerror or e}") from None
    if len(data) > limit:
        raise UsageError(f"{what}: {name}: more than {_mib(limit)}: too large for a {what} file")
    return data, name


def _read_limited(stream, limit, what, name) -> bytes:
    parts, size = [], 0
    while size <= limit:
        try:
            block = stream.read(min(1 << 20, limit + 1 - size))
        except OSError as e:
            raise UsageError(f"{what}: cannot read {name}: {e.strerror or e}") from None
        if not block:
            break
        parts.append(block)
        size += len(block)
    return b"".join(parts)


def read_text(path, what: str, expected: str = "", limit: int = MAX_DOCUMENT) -> tuple:
    """``(text, name)`` of the UTF-8 file ``path`` (a byte order mark is dropped) or of
    standard input (``-``; its name is ``stdin``). A file that cannot be read, is larger than
    ``limit`` bytes or is not UTF-8 is a UsageError naming ``what`` (``schedule``, ``limits``,
    ``batch``), the file and, when given, what was ``expected`` in it."""
    data, name = read_bytes(path, what, limit)
    data = _drop_bom(data, what, name)
    return decode(data, what, name, expected), name


#: A line of text and what ends it: the line boundaries of :meth:`str.splitlines`.
_ENDS = "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
_LINE = None


def lines_of(text: str):
    """The lines of ``text`` as :meth:`str.splitlines` gives them, one at a time: a document of
    a million lines is parsed without a list of a million strings beside it."""
    global _LINE
    if _LINE is None:
        import re

        _LINE = re.compile(f"[^{_ENDS}]*(?:\r\n|[{_ENDS}]|\\Z)")
    match, pos, end = _LINE.match, 0, len(text)
    while pos < end:
        m = match(text, pos)
        pos = m.end()
        line = m.group()
        yield line.rstrip(_ENDS) if line[-1:] in _ENDS else line


def iter_lines(path, what: str, expected: str = "", max_line: int = MAX_LINE):
    """``(line number, text)`` for every line of the UTF-8 file ``path`` (``-``: standard
    input), with its line ending (as a text file's lines are), read in constant memory; the first line loses a byte order
    mark. A line longer than ``max_line`` bytes or one that is not UTF-8 is a UsageError naming
    the file and the line."""
    if str(path) == "-":
        stream, text = _stdin_binary()
        if text is None:
            raise UsageError(f"{what}: no standard input")
        if stream is None:
            import io

            stream = io.BytesIO(text.read().encode("utf-8", "surrogateescape"))
        name, close = "stdin", False
    else:
        name = str(path)
        try:
            stream = open_input(path)
        except OSError as e:
            raise UsageError(f"{what}: cannot read {path}: {e.strerror or e}") from None
        close = True
    try:
        yield from _lines(stream, what, name, expected, max_line)
    finally:
        if close:
            stream.close()


def _lines(stream, what, name, expected, max_line):
    lineno, offset = 0, 0
    while True:
        try:
            raw = stream.readline(max_line + 1)
        except OSError as e:
            raise UsageError(f"{what}: cannot read {name}: {e.strerror or e}") from None
        if not raw:
            return
        lineno += 1
        if len(raw) > max_line and not raw.endswith(b"\n"):
            raise UsageError(f"{what}: {name}:{lineno}: a line longer than {_mib(max_line)}: "
                             f"too long for a {what} file")
        start = offset
        offset += len(raw)
        if lineno == 1:
            body = _drop_bom(raw, what, name)
            start += len(raw) - len(body)
            raw = body
        text = decode(raw, what, name, expected, line=lineno, offset=start)
        yield lineno, text
