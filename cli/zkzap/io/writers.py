"""Record writers by format: ``jsonl``, ``json``, ``csv``, ``influx`` and ``table``.

A writer takes dict records one at a time (:meth:`write`) and is closed at the end
(:meth:`close`). JSON Lines and CSV are flushed record by record (``flush=True``) so a
killed process leaves a whole, parseable file; ``json`` streams one array without holding it
in memory. ``table`` is for people: rich, only on a terminal, imported only when used.

Value rendering in CSV: None -> empty, booleans -> ``true``/``false``, lists joined with
``;``, dicts as ``key=value`` joined with ``;``.

InfluxDB line protocol (``influx``): one line per record, the measurement is the record's
``kind``, ``id`` and ``kind`` are tags, every other key with a value is a field (integers with
``i``, floats, booleans, strings quoted; lists joined with ``;``), and the timestamp is the
record's ``time`` in nanoseconds (none when the record has no time: the server's clock then).

Bulk decoding writes blocks: :meth:`Writer.write_many` (records) and :meth:`Writer.write_lines`
(text already rendered by a dialect: :func:`json_dialect`, :func:`csv_dialect`) hand the
stream many whole records at once and flush after each block, so output is fast and a killed
process still leaves whole lines: on a file or pipe a block goes out in one ``write`` system
call loop with SIGINT/SIGTERM held off until it is complete.

A header (a CSV header row, a JSON array's bracket) is written with the first record. On a
file stream that opens with its first write (:class:`zkzap.outfile.LazyOutput`) a writer
that got no record writes nothing at all, so the file is left as it was; on stdout an empty
run still gives the header (``[]`` for JSON).
"""

from __future__ import annotations

import json
import os
import stat

from ..errors import OutputError
from ..signals import held
from . import FORMATS  # noqa: F401 - re-exported

#: A number no output format holds is written as no value (JSON null, an empty CSV or workbook
#: cell, no line-protocol field): NaN and ±Infinity (``1e400`` read as a float is one) — JSON
#: has neither, CSV readers disagree on them, line protocol and MCAP's JSON refuse them — and an
#: integer too long to write (Python writes none of more than 4300 digits). A format with
#: narrower numbers says so itself: line protocol's integers are 64-bit (a larger one is written
#: as a float), a workbook's cells are doubles (:func:`fits_double`).
_LONGEST = 10 ** 4300
_INF = float("inf")


def holds(v) -> bool:
    """Whether the number ``v`` is one every output format holds (anything else: True)."""
    if isinstance(v, float):
        return v == v and v != _INF and v != -_INF
    if isinstance(v, int):
        return -_LONGEST < v < _LONGEST
    return True


def fits_double(v) -> bool:
    """Whether the number ``v`` is a finite double's (an int within a double's range)."""
    return holds(v) and (not isinstance(v, int) or -(1 << 1024) < v < 1 << 1024)


def plain(v):
    """``v`` (a record, a list, a value) with every number no format holds replaced by None."""
    if isinstance(v, dict):
        return {k: plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    return v if holds(v) else None


_strict = json.JSONEncoder(ensure_ascii=False, separators=(",", ":"), allow_nan=False).encode


def dumps(value, **options) -> str:
    """``value`` as JSON text (compact unless ``options`` say otherwise, as :func:`json.dumps`
    takes them), every number JSON cannot hold written as null (see :func:`holds`). Records of
    finite numbers, nearly all, are encoded once."""
    encode = json.JSONEncoder(ensure_ascii=False, allow_nan=False, **options).encode if options else _strict
    try:
        return encode(value)
    except ValueError:                # NaN or an infinity (or an int of more than 4300 digits)
        return encode(plain(value))


_dumps = dumps


def csv_cell(v) -> str:
    if v is None:
        return ""
    if v is True:
        return "true"
    if v is False:
        return "false"
    if isinstance(v, float):
        return repr(v) if holds(v) else ""
    if isinstance(v, int) and not holds(v):
        return ""
    if isinstance(v, (list, tuple)):
        return ";".join(csv_cell(x) for x in v)
    if isinstance(v, dict):
        return ";".join(f"{k}={csv_cell(x)}" for k, x in v.items())
    return str(v)


def _csv_quote(s: str) -> str:
    if any(c in s for c in ',"\n\r'):
        return '"' + s.replace('"', '""') + '"'
    return s


class JsonDialect:
    """Records as compact JSON objects (the ``jsonl``/``json`` formats), for text encoders."""

    str_piece = '"%s"'
    key = ("json",)
    value = staticmethod(_dumps)
    #: The text of an int or a finite float: what ``value`` gives for one, without the
    #: encoder's dispatch.
    number_value = staticmethod(repr)
    record = staticmethod(_dumps)

    @staticmethod
    def template(cells):
        return ("{" + ",".join(f"{_dumps(k)}:{piece}" for k, piece, _ in cells) + "}",
                [arg for _, _, arg in cells if arg is not None])


class CsvDialect:
    """Records as rows of a fixed column set (the ``csv`` format), for text encoders."""

    str_piece = "%s"
    #: The text of an int or a finite float: what ``value`` gives for one (needs no quoting).
    number_value = staticmethod(repr)

    def __init__(self, columns):
        self.columns = list(columns)
        self.key = ("csv",) + tuple(self.columns)

    @staticmethod
    def value(v):
        return _csv_quote(csv_cell(v))

    def record(self, rec):
        get = rec.get
        return ",".join(_csv_quote(csv_cell(get(c))) for c in self.columns)

    def template(self, cells):
        by_key = {k: (piece, arg) for k, piece, arg in cells}
        pieces, args = [], []
        for c in self.columns:
            piece, arg = by_key.get(c, ("", None))
            pieces.append(piece)
            if arg is not None:
                args.append(arg)
        return ",".join(pieces), args


def json_dialect():
    return JsonDialect()


def csv_dialect(columns):
    return CsvDialect(columns)


def _unopened(stream) -> bool:
    """A file stream that opens with its first write, and has not been written to."""
    return getattr(stream, "lazy", False) and not stream.opened


def _raw_fd(stream):
    """The file descriptor under a UTF-8 text stream, or None (then blocks go through it)."""
    try:
        fd = stream.fileno()
    except (AttributeError, OSError, ValueError):
        return None
    enc = (getattr(stream, "encoding", None) or "").lower().replace("-", "").replace("_", "")
    if enc != "utf8" or getattr(stream, "errors", "strict") not in ("strict", "surrogateescape") \
            or os.linesep != "\n":
        return None
    return fd


class Writer:
    def __init__(self, stream, flush=True):
        self.stream = stream
        self.flush = flush
        self.count = 0
        self._fd = False
        self._good = None
        self._failed = False

    def write(self, rec: dict) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def write_many(self, recs) -> None:
        """Several records as one block (flushed once)."""
        for rec in recs:
            self.write(rec)

    def close(self) -> None:
        if _unopened(self.stream):
            return                       # no record: the file was never opened, nothing to flush
        try:
            self.stream.flush()
        except (BrokenPipeError, ValueError):
            pass
        except OSError as e:
            self._fail(e)

    def _put(self, text: str) -> None:
        """One record: flushed at once (``flush``), else left to the stream's buffering."""
        if self.flush:
            self._emit(text)
        else:
            try:
                self.stream.write(text)
            except BrokenPipeError:
                raise
            except OSError as e:
                self._fail(e)

    def _emit(self, text: str) -> None:
        """Write a block of whole records and flush it: on a file descriptor in one write loop
        that SIGINT/SIGTERM cannot cut (they are handled right after it). When the write
        fails (disk full), a regular file is cut back to the last whole record."""
        if self._failed:
            return
        if self._fd is False:
            self._fd = fd = _raw_fd(self.stream)
            if fd is not None:
                try:
                    if stat.S_ISREG(os.fstat(fd).st_mode):
                        self._good = os.lseek(fd, 0, os.SEEK_CUR)     # after the last raw write
                except OSError:
                    self._good = None
        fd = self._fd
        try:
            if fd is None:
                self.stream.write(text)
                self.stream.flush()
                return
            self.stream.flush()
            if self._good is not None:
                self._good = os.lseek(fd, 0, os.SEEK_CUR)
        except BrokenPipeError:
            raise
        except OSError as e:
            self._fail(e)
        raw = text.encode("utf-8")
        data = memoryview(raw)
        try:
            with held():
                while data:
                    data = data[os.write(fd, data):]
        except BrokenPipeError:
            raise
        except OSError as e:
            if self._good is not None:
                # keep the whole lines of this block that did reach the file
                done = len(raw) - len(data)
                self._good += raw.rfind(b"\n", 0, done) + 1
            self._fail(e)
        if self._good is not None:
            self._good += len(raw)

    def _fail(self, e):
        """Leave whole records behind, make later writes and the caller's close() quiet, and
        raise a clear :class:`OutputError`."""
        self._failed = True
        fd = self._fd if self._fd is not False else _raw_fd(self.stream)
        if fd is not None:
            if self._good is not None:
                try:
                    os.ftruncate(fd, self._good)
                except OSError:
                    pass
            try:
                null = os.open(os.devnull, os.O_WRONLY)
                os.dup2(null, fd)
                os.close(null)
            except OSError:
                pass
        name = getattr(self.stream, "name", None)
        name = "stdout" if not isinstance(name, str) or name == "<stdout>" else name
        raise OutputError(f"output: cannot write {name}: {e.strerror or e}") from None


class LineWriter(Writer):
    """A record per line (JSON Lines, CSV rows)."""

    def write_lines(self, lines):
        """Records already rendered by the format's dialect (:class:`JsonDialect`,
        :class:`CsvDialect` for this column set), without newlines, as one block."""
        if lines:
            lines.append("")
            self._emit("\n".join(lines))
            self.count += len(lines) - 1


class JsonlWriter(LineWriter):
    def write(self, rec):
        self._put(_dumps(rec) + "\n")
        self.count += 1

    def write_many(self, recs):
        self.write_lines([_dumps(rec) for rec in recs])


class JsonWriter(Writer):
    """One JSON array, written incrementally; ``[]`` when there are no records. ``header=False``
    continues an array whose closing bracket the caller removed (``--append``)."""

    def __init__(self, stream, flush=True, header=True):
        super().__init__(stream, flush)
        self._open = not header

    def _lead(self):
        return ",\n" if self.count or self._open else "[\n"

    def write(self, rec):
        self._put(self._lead() + _dumps(rec))
        self.count += 1

    def write_many(self, recs):
        self.write_lines([_dumps(rec) for rec in recs])

    def write_lines(self, lines):
        if lines:
            self._emit(self._lead() + ",\n".join(lines))
            self.count += len(lines)

    def close(self):
        if not _unopened(self.stream):
            self._put("\n]\n" if self.count or self._open else "[]\n")
        super().close()


class CsvWriter(LineWriter):
    """CSV with one header and a fixed column set. ``header=False`` when appending to a file
    that already has one. Keys not in ``columns`` are dropped; missing ones are empty."""

    def __init__(self, stream, columns, flush=True, header=True):
        super().__init__(stream, flush)
        self.columns = list(columns)
        self._header = header           # written with the first record (or by close, on stdout)

    def _head(self) -> str:
        if not self._header:
            return ""
        self._header = False
        return ",".join(self.columns) + "\n"

    def write(self, rec):
        get = rec.get
        self._put(self._head() + ",".join(_csv_quote(csv_cell(get(c))) for c in self.columns) + "\n")
        self.count += 1

    def write_many(self, recs):
        columns = self.columns
        lines = []
        for rec in recs:
            get = rec.get
            lines.append(",".join(_csv_quote(csv_cell(get(c))) for c in columns))
        self.write_lines(lines)

    def write_lines(self, lines):
        if lines and self._header:
            lines.insert(0, self._head().rstrip("\n"))
            super().write_lines(lines)
            self.count -= 1              # the header is not a record
            return
        super().write_lines(lines)

    def close(self):
        if self._header and not _unopened(self.stream):
            self._put(self._head())      # stdout (or an opened file): a run without records has its header
        super().close()


class TableWriter(Writer):
    """A rich table for a terminal. Rows are buffered and printed in blocks of ``block`` rows
    so a long stream still shows progress; ``columns`` is a list of (key, heading) or (key,
    heading, priority: default 0). A table wider than the terminal is laid out by
    :func:`~zkzap.io.term.column_layout`: values wrap, none is cut, and the columns of the lowest
    priority (the last of equal ones first) are left out, named under the table, until the rest fit."""

    def __init__(self, stream, columns, title=None, block=500, console=None):
        super().__init__(stream, True)
        self.columns = [(c, c) if isinstance(c, str) else tuple(c) for c in columns]
        self.priority = [c[2] if len(c) > 2 else 0 for c in self.columns]
        self.title = title
        self.block = block
        self.rows = []
        self._console = console

    def write(self, rec):
        self.rows.append(rec)
        self.count += 1
        if len(self.rows) >= self.block:
            self._emit()

    def _emit(self):
        if not self.rows:
            return
        from .term import console_for, fitted_table

        console = self._console or console_for(self.stream)
        rows = [[csv_cell(rec.get(k)) for k, *_ in self.columns] for rec in self.rows]
        console.print(fitted_table([c[1] for c in self.columns], rows, console.width, title=self.title,
                                   priority=self.priority))
        self.rows = []
        self.title = None

    def close(self):
        self._emit()
        super().close()


def _lp_escaper(chars):
    table = str.maketrans({c: "\\" + c for c in chars})
    return lambda s: s.translate(table)


#: Line protocol escaping: measurements escape commas and spaces; tag keys, tag values and
#: field keys also equals signs; string field values backslashes and double quotes.
lp_measurement = _lp_escaper(", ")
lp_key = _lp_escaper(",= ")
_lp_string = _lp_escaper('\\"')
_LP_TAGS = ("id", "kind")


def lp_field_value(v):
    """A field value in line protocol, or None when it has no representation (None, NaN, inf)."""
    if v is None:
        return None
    if v is True:
        return "true"
    if v is False:
        return "false"
    if isinstance(v, int):
        if -(1 << 63) <= v < 1 << 63:
            return f"{v}i"
        return repr(float(v)) if fits_double(v) else None      # beyond line protocol's 64-bit integers
    if isinstance(v, float):
        return repr(v) if holds(v) else None
    if isinstance(v, (list, tuple)):
        v = ";".join(csv_cell(x) for x in v)
    elif isinstance(v, dict):
        v = _dumps(v)
    else:
        v = str(v)
    # a newline would end the line: line protocol strings cannot hold one
    return '"' + _lp_string(v).replace("\n", "\\n").replace("\r", "\\r") + '"'


class IsoNs:
    """``2024-05-01T12:00:00.123Z`` -> nanoseconds since the epoch; the seconds part is
    memoised (consecutive records share it)."""

    def __init__(self):
        self._prefix = None
        self._sec = 0

    def __call__(self, text):
        if not isinstance(text, str) or len(text) < 19:
            return None
        prefix = text[:19]
        if prefix != self._prefix:
            import calendar
            import time as _time

            try:
                self._sec = calendar.timegm(_time.strptime(prefix, "%Y-%m-%dT%H:%M:%S"))
            except ValueError:
                return None
            self._prefix = prefix
        frac = text[19:].rstrip("Z")
        ns = 0
        if frac.startswith(".") and frac[1:].isdigit():
            ns = int((frac[1:] + "000000000")[:9])
        return self._sec * 1_000_000_000 + ns


class InfluxWriter(LineWriter):
    """InfluxDB line protocol, one record per line (see the module's description)."""

    def __init__(self, stream, flush=True, default_measurement="record"):
        super().__init__(stream, flush)
        self.default_measurement = default_measurement
        self._ns = IsoNs()
        self._keys = {}
        self._last = {}            # series (measurement and tags) -> its last timestamp (ns)

    def line(self, rec) -> str:
        kind = rec.get("kind")
        head = lp_measurement(str(kind) if kind not in (None, "") else self.default_measurement)
        for tag in _LP_TAGS:
            v = rec.get(tag)
            if v is not None and v != "":
                head += f",{tag}={lp_key(str(v))}"
        keys = self._keys
        fields = []
        for k, v in rec.items():
            if k in _LP_TAGS or k == "time" or k[:1] == "_":
                continue
            text = lp_field_value(v)
            if text is None:
                continue
            ek = keys.get(k)
            if ek is None:
                ek = keys[k] = lp_key(k)
            fields.append(f"{ek}={text}")
        if not fields:          # a line needs a field
            fields.append("present=true")
        ns = self._ns(rec.get("time"))
        if ns is not None:
            # a series keeps one point per timestamp: two records of one series within the
            # time's resolution get the next nanosecond, never the same time
            last = self._last.get(head)
            if last is not None and ns <= last:
                ns = last + 1
            self._last[head] = ns
        return f"{head} {','.join(fields)}" + (f" {ns}" if ns is not None else "")

    def write(self, rec):
        self._put(self.line(rec) + "\n")
        self.count += 1

    def write_many(self, recs):
        self.write_lines([self.line(rec) for rec in recs])


def make_writer(fmt, stream, columns, *, title=None, table_columns=None, header=True, measurement="record"):
    """A writer for ``fmt``. ``columns`` fixes the CSV column set (and the table's, unless
    ``table_columns`` is given); ``measurement`` names the line-protocol measurement of records
    without a ``kind``."""
    if fmt == "jsonl":
        return JsonlWriter(stream)
    if fmt == "json":
        return JsonWriter(stream, header=header)
    if fmt == "csv":
        return CsvWriter(stream, columns, header=header)
    if fmt == "table":
        return TableWriter(stream, table_columns or columns, title=title)
    if fmt == "influx":
        return InfluxWriter(stream, default_measurement=measurement)
    from ..errors import InvalidValue

    raise InvalidValue(f"format: {fmt!r}; allowed {', '.join(FORMATS)}")
