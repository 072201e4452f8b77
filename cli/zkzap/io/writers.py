"""Record writers by format: ``jsonl``, ``json``, ``csv`` and ``table``.

A writer takes dict records one at a time (:meth:`write`) and is closed at the end
(:meth:`close`). JSON Lines and CSV are flushed record by record (``flush=True``) so a
killed process leaves a whole, parseable file; ``json`` streams one array without holding it
in memory. ``table`` is for people: rich, only on a terminal, imported only when used.

Value rendering in CSV: None -> empty, booleans -> ``true``/``false``, lists joined with
``;``, dicts as ``key=value`` joined with ``;``.
"""

from __future__ import annotations

import json

from . import FORMATS  # noqa: F401 - re-exported

_dumps = json.JSONEncoder(ensure_ascii=False, separators=(",", ":")).encode


def csv_cell(v) -> str:
    if v is None:
        return ""
    if v is True:
        return "true"
    if v is False:
        return "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return ";".join(csv_cell(x) for x in v)
    if isinstance(v, dict):
        return ";".join(f"{k}={csv_cell(x)}" for k, x in v.items())
    return str(v)


def _csv_quote(s: str) -> str:
    if any(c in s for c in ',"\n\r'):
        return '"' + s.replace('"', '""') + '"'
    return s


class Writer:
    def __init__(self, stream, flush=True):
        self.stream = stream
        self.flush = flush
        self.count = 0

    def write(self, rec: dict) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def close(self) -> None:
        try:
            self.stream.flush()
        except (BrokenPipeError, ValueError):
            pass


class JsonlWriter(Writer):
    def write(self, rec):
        self.stream.write(_dumps(rec) + "\n")
        if self.flush:
            self.stream.flush()
        self.count += 1


class JsonWriter(Writer):
    """One JSON array, written incrementally; ``[]`` when there are no records."""

    def write(self, rec):
        self.stream.write(("[\n" if self.count == 0 else ",\n") + _dumps(rec))
        if self.flush:
            self.stream.flush()
        self.count += 1

    def close(self):
        self.stream.write("[]\n" if self.count == 0 else "\n]\n")
        super().close()


class CsvWriter(Writer):
    """CSV with one header and a fixed column set. ``header=False`` when appending to a file
    that already has one. Keys not in ``columns`` are dropped; missing ones are empty."""

    def __init__(self, stream, columns, flush=True, header=True):
        super().__init__(stream, flush)
        self.columns = list(columns)
        if header:
            stream.write(",".join(self.columns) + "\n")
            if flush:
                stream.flush()

    def write(self, rec):
        get = rec.get
        self.stream.write(",".join(_csv_quote(csv_cell(get(c))) for c in self.columns) + "\n")
        if self.flush:
            self.stream.flush()
        self.count += 1


class TableWriter(Writer):
    """A rich table for a terminal. Rows are buffered and printed in blocks of ``block`` rows
    so a long stream still shows progress; ``columns`` is a list of (key, heading)."""

    def __init__(self, stream, columns, title=None, block=500, console=None):
        super().__init__(stream, True)
        self.columns = [(c, c) if isinstance(c, str) else c for c in columns]
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
        from rich.table import Table

        from .term import console_for

        console = self._console or console_for(self.stream)
        table = Table(title=self.title, title_justify="left", header_style="bold")
        for _, heading in self.columns:
            table.add_column(heading)
        for rec in self.rows:
            table.add_row(*(csv_cell(rec.get(k)) for k, _ in self.columns))
        console.print(table)
        self.rows = []
        self.title = None

    def close(self):
        self._emit()
        super().close()


def make_writer(fmt, stream, columns, *, title=None, table_columns=None, header=True):
    """A writer for ``fmt``. ``columns`` fixes the CSV column set (and the table's, unless
    ``table_columns`` is given)."""
    if fmt == "jsonl":
        return JsonlWriter(stream)
    if fmt == "json":
        return JsonWriter(stream)
    if fmt == "csv":
        return CsvWriter(stream, columns, header=header)
    if fmt == "table":
        return TableWriter(stream, table_columns or columns, title=title)
    raise ValueError(f"format: {fmt!r}; allowed {', '.join(FORMATS)}")
