"""Columnar files of a logging session, for the tools test cells read: Apache Parquet
(``-o run.parquet``, the optional ``parquet`` extra: pyarrow) and ASAM MDF 4 (``-o run.mf4``, the
optional ``mdf`` extra: asammdf).

Both take the records a CSV takes (the snapshot rows: every field's latest value on each row),
with the channel names of the CSV's columns and the units of the workbook's units row
(:func:`zkzap.io.xlsx.unit_of`; an external sensor's declared unit).

- **Parquet**: one column per CSV column, typed from the first rows: booleans, numbers
  (float64; integers are exact up to 2^53), ``time`` a UTC timestamp in milliseconds, anything
  else text (lists ``;``-joined). Each column's unit is in its field metadata (``unit``), the
  writer in the file's (``zkzap``). Rows are written in row groups of :data:`CHUNK` records, so
  memory stays flat whatever the run's length.
- **MDF 4**: one channel group, its master channel ``t`` (session seconds), a channel per
  numeric CSV column with its unit (booleans as 0/1; text columns, such as the state names, are
  left out: their numbers are there; a sample without a value is NaN, MDF's own); the
  measurement's start time is the session's time 0. Written by :mod:`.mdf4` as the records come,
  :attr:`Mf4Writer.chunk` records at a time, each flushed: the file on disk is an unfinalized MDF
  (the standard's state of a logger's file cut short) until the close finalizes it, so a killed
  run's ``FILE.tmpPID`` opens in asammdf with every record but the last chunk's. Writing needs no
  extra (asammdf reads the files back).

In both, a number the file cannot hold (NaN, ±Infinity, an integer beyond a float64) is no
value, never a wrong one.

The file is written beside ``-o FILE`` and renamed over it when the session ends (a run that
wrote no record leaves an existing file as it was; ``--append`` is refused: neither format has
an end to append to). A process killed without a word leaves the file beside it,
``FILE.tmpPID``: a Parquet file without its footer, an MDF file unfinalized (readable).
"""

from __future__ import annotations

import datetime
import math
import os

from ..errors import OutputError, UsageError

#: Records per row group (Parquet) or per append (MDF).
CHUNK = 4096
#: Format -> (the module it needs, the extra that provides it); MDF 4 is written by zkzap itself.
EXTRAS = {"parquet": ("pyarrow", "parquet")}


def require(fmt) -> None:
    """Refuse (exit 2) without the format's library, naming the extra."""
    from .bridges import require_extra

    if fmt in EXTRAS:
        module, extra = EXTRAS[fmt]
        require_extra(module, extra, f"format {fmt}")


def check(fmt, output, append) -> None:
    """Refuse what the format cannot do, before anything is opened."""
    require(fmt)
    if append:
        raise UsageError(f"append: a {fmt} file cannot be appended to; give a new -o FILE.{fmt}")
    if not output or output == "-":
        raise UsageError(f"format {fmt}: needs a file; give -o FILE.{fmt}")
    import importlib

    # imported now, before the session: the first record's write is no second-long import that
    # the output's queue would take for a stalled disk
    importlib.import_module("pyarrow.parquet" if fmt == "parquet" else "zkzap.io.mdf4")


def _number(v):
    """A record's value as a float64, or None: not a number, or one a float64 cannot hold
    (NaN, ±Infinity, an integer beyond its range) — no value, never a wrong one."""
    if isinstance(v, bool):
        return float(v)
    if isinstance(v, (int, float)):
        try:
            f = float(v)
        except OverflowError:             # an integer of hundreds of digits
            return None
        return f if math.isfinite(f) else None
    return None


def _time(v):
    if not isinstance(v, str):
        return None
    try:
        return datetime.datetime.strptime(v.rstrip("Z"), "%Y-%m-%dT%H:%M:%S.%f").replace(tzinfo=datetime.timezone.utc)
    except ValueError:
        return None


class _Columnar:
    """Records buffered in chunks of :attr:`chunk`, written to ``path`` beside, renamed at the close."""

    chunk = CHUNK

    def __init__(self, path, columns, units=None):
        from .xlsx import unit_of

        self.path = path
        self.columns = list(columns)
        units = units or {}
        self.units = {c: units.get(c) or unit_of(c) for c in self.columns}
        self.tmp = f"{path}.tmp{os.getpid()}"
        self._rows = []
        self.count = 0

    def write(self, rec) -> None:
        self._rows.append(rec)
        self.count += 1
        if len(self._rows) >= self.chunk:
            self._flush()

    def write_many(self, recs) -> None:
        for r in recs:
            self.write(r)

    def _flush(self):
        rows, self._rows = self._rows, []
        if rows:
            try:
                self._chunk(rows)
            except OSError as e:
                raise OutputError(f"output: cannot write {self.path}: {e.strerror or e}") from None

    def close(self) -> None:
        if self.tmp is None:
            return
        try:
            self._flush()
            self._finish()
            os.replace(self.tmp, self.path)
        except OSError as e:
            try:
                os.unlink(self.tmp)
            except OSError:
                pass
            raise OutputError(f"output: cannot write {self.path}: {e.strerror or e}") from None
        finally:
            self.tmp = None


class ParquetWriter(_Columnar):
    """Records into an Apache Parquet file (see the module's text)."""

    def __init__(self, path, columns, units=None):
        super().__init__(path, columns, units)
        self._writer = None
        self._kinds = None

    def _schema(self, rows):
        import pyarrow as pa

        kinds, fields = {}, []
        for c in self.columns:
            values = [r.get(c) for r in rows if r.get(c) is not None]
            if c == "time":
                kind, typ = "time", pa.timestamp("ms", tz="UTC")
            elif values and all(isinstance(v, bool) for v in values):
                kind, typ = "bool", pa.bool_()
            elif values and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values) \
                    or not values and self.units.get(c):
                kind, typ = "number", pa.float64()
            else:
                kind, typ = "text", pa.string()
            kinds[c] = kind
            meta = {"unit": self.units[c]} if self.units.get(c) else None
            fields.append(pa.field(c, typ, metadata=meta))
        return kinds, pa.schema(fields, metadata={"zkzap": "records of a zk session (snapshot rows)"})

    def _chunk(self, rows):
        import pyarrow as pa
        import pyarrow.parquet as pq

        from .writers import csv_cell

        if self._writer is None:
            self._kinds, schema = self._schema(rows)
            self._writer = pq.ParquetWriter(self.tmp, schema, compression="zstd")
        arrays = []
        for c in self.columns:
            kind = self._kinds[c]
            vals = [r.get(c) for r in rows]
            if kind == "time":
                vals = [_time(v) for v in vals]
            elif kind == "bool":
                vals = [v if isinstance(v, bool) else None for v in vals]
            elif kind == "number":
                vals = [_number(v) if not isinstance(v, bool) else None for v in vals]
            else:
                vals = [None if v is None else csv_cell(v) for v in vals]
            arrays.append(vals)
        self._writer.write_table(pa.table(arrays, schema=self._writer.schema))

    def _finish(self):
        if self._writer is None:
            self._chunk_empty()
        self._writer.close()

    def _chunk_empty(self):
        import pyarrow.parquet as pq

        self._kinds, schema = self._schema([])
        self._writer = pq.ParquetWriter(self.tmp, schema)


class Mf4Writer(_Columnar):
    """Records into an ASAM MDF 4 file, streamed (:mod:`.mdf4`; see the module's text)."""

    #: Records per append at most, and the seconds a record waits at most: each append is on
    #: disk (flushed) before the next is gathered, so a killed run loses half a second at most.
    chunk = 256
    wait_s = 0.5

    def __init__(self, path, columns, units=None, start=None):
        super().__init__(path, columns, units)
        self._mdf = None
        self._file = None
        self._numeric = None
        self._since = 0.0              # when the oldest record not yet appended came (monotonic)
        self._start = start            # the wall time (POSIX) of the session's t = 0

    def write(self, rec) -> None:
        import time

        now = time.monotonic()
        if not self._rows:
            self._since = now
        super().write(rec)
        if self._rows and now - self._since >= self.wait_s:
            self._flush()

    def _start_ns(self, rows):
        import time

        first = _time(rows[0].get("time")) if rows else None
        if first is not None:
            return int(round((first.timestamp() - float(rows[0]["t"])) * 1e9))
        return int((self._start if self._start is not None else time.time()) * 1e9)

    def _chunk(self, rows):
        from .mdf4 import Mdf4Stream

        rows = [r for r in rows if _number(r.get("t")) is not None]
        if not rows:
            return
        if self._mdf is None:
            from .. import __version__

            self._numeric = [c for c in self.columns if c not in ("t", "time") and any(
                _number(r.get(c)) is not None for r in rows)]
            self._file = open(self.tmp, "w+b")
            self._mdf = Mdf4Stream(self._file, [(c, self.units.get(c) or "") for c in self._numeric],
                                   self._start_ns(rows), tool_version=__version__,
                                   comment="records of a zk session")
        self._mdf.append([(float(r["t"]), *(_nan(r.get(c)) for c in self._numeric)) for r in rows])

    def _finish(self):
        from .mdf4 import empty

        if self._mdf is None:
            with open(self.tmp, "wb") as f:
                empty(f, self._start_ns([]))
            return
        try:
            self._mdf.close()
        finally:
            self._file.close()


def _nan(v):
    n = _number(v)
    return math.nan if n is None else n


def writer(fmt, path, columns, units=None):
    """The writer of ``fmt`` (``parquet``, ``mf4``) onto ``path``."""
    return (ParquetWriter if fmt == "parquet" else Mf4Writer)(path, columns, units)
