"""Excel workbooks of a logging session (``-o run.xlsx``; the optional ``xlsx`` extra: openpyxl).

A workbook has three sheets: ``records`` (one row per record, the columns of the CSV, a units
row under the header), ``steps`` (the per-step averages of ``zk profile``, with units) and
``summary`` (the run's summary: one row per figure, the limits as a table). Numbers are
numbers, booleans booleans, ``time`` a date-time (UTC), lists ``;``-joined text. More records
than a sheet holds (1 048 576 rows) continue on ``records 2``, ``records 3``...

openpyxl's write-only mode streams the rows to a temporary file, so memory stays flat whatever
the run's length; the workbook is assembled when the session ends and renamed over ``-o FILE``
whole (a zip has no end to append to: ``--append`` is refused, and a run that fails to start
leaves an existing file as it was). Ctrl-C and SIGTERM end the session first, so the workbook
is written. A process killed with SIGKILL (or a power cut) writes no workbook, so the rows are
also kept as they are written in ``FILE.xlsx.partial.csv`` (the CSV's columns, flushed per
row), removed once the workbook is saved: after a kill it holds every row up to the kill, and a
session refuses to start while it exists (it would be the only copy of a killed run).

openpyxl's streaming writer keeps each sheet in a temporary file it names itself in the system's
temporary directory (``openpyxl.XXXX``) and removes at the exit — not after a SIGKILL, and it
offers no way to choose the directory. So the workbook's temporary files go to a directory of
its own, ``zkzap-xlsx-PID-XXXX`` in the temporary directory (:func:`_private_temp`): openpyxl's
files are created only when a sheet gets its first row and when the workbook is saved, and for
those calls alone :data:`tempfile.tempdir` points there (under a lock, restored after). The
directory is removed when the workbook is saved or the writer dropped; a killed run's is removed
by the next workbook run (:func:`_sweep`: the directories whose process no longer exists), so
nothing of openpyxl's is left behind in the temporary directory itself.
"""

from __future__ import annotations

import contextlib
import datetime
import os
import threading

from ..errors import OutputError, UsageError

#: The journal of a workbook's rows beside it, until the workbook is saved.
PARTIAL = ".partial.csv"
#: The extra that provides openpyxl.
EXTRA = "xlsx"
#: How a record's time is shown: to the millisecond it holds.
TIME_FORMAT = "yyyy-mm-dd hh:mm:ss.000"
#: Rows of a sheet (Excel's limit).
MAX_ROWS = 1_048_576
#: Units of the columns that are not status fields (status fields take theirs from the tables).
UNITS = {
    "time": "UTC", "t": "s", "step_start_s": "s", "step_end_s": "s", "window_start_s": "s", "window_end_s": "s",
    "tsfc_g_kn_s": "g/(kN·s)", "tsfc_kg_kgf_h": "kg/(kgf·h)", "target_throttle_pct": "%", "target_rpm": "rpm",
    "duration_s": "s", "schedule_s": "s", "running_s": "s", "fuel_used_l": "L", "fuel_total_l": "L",
    "max_rpm": "rpm", "max_egt_c": "°C", "fuel_density_kg_l": "kg/L", "gap_s": "s", "since_t": "s",
    # thrust is a force: kgf, though the protocol's tables say kg
    "thrust_kg": "kgf", "thrust_from_kg": "kgf", "thrust_corrected_kg": "kgf", "rpm_corrected": "rpm",
    "drift_rpm": "rpm", "drift_egt_c": "°C", "drift_thrust_kg": "kgf",
}


#: The name of a workbook's private temporary directory: its process, then mkdtemp's part.
TEMP_PREFIX = "zkzap-xlsx-"
_TEMP_LOCK = threading.Lock()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:                            # another user's process: alive
        return True
    return True


def _sweep() -> None:
    """Remove the private temporary directories that killed workbook runs left (their process gone)."""
    import shutil
    import tempfile

    base = tempfile.gettempdir()
    try:
        names = os.listdir(base)
    except OSError:
        return
    for name in names:
        if not name.startswith(TEMP_PREFIX):
            continue
        pid = name[len(TEMP_PREFIX):].split("-", 1)[0]
        if pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)):
            shutil.rmtree(os.path.join(base, name), ignore_errors=True)


@contextlib.contextmanager
def _private_temp(directory):
    """openpyxl's temporary files in ``directory`` for the calls inside (tempfile's default
    directory, process-wide, so held under a lock and restored after)."""
    import tempfile

    with _TEMP_LOCK:
        before = tempfile.tempdir
        tempfile.tempdir = directory
        try:
            yield
        finally:
            tempfile.tempdir = before


def require():
    """Refuse (exit 2) without openpyxl, naming the extra."""
    from .bridges import require_extra

    require_extra("openpyxl", EXTRA, "format xlsx")


def unit_of(column) -> str:
    """The unit of a record, step or summary column: from the protocol tables, or from
    :data:`UNITS`; a step's ``X_mean``/``X_min``/``X_max`` has the unit of X."""
    if column in UNITS:
        return UNITS[column]
    units = _status_units()
    if column in units:
        return units[column]
    for tail in ("_mean", "_min", "_max", "_std"):
        if column.endswith(tail):
            return unit_of(column[: -len(tail)])
    if column.startswith("tsfc_corrected_"):
        return unit_of("tsfc_" + column[len("tsfc_corrected_"):])
    for suffix, unit in (("_kg", "kgf"), ("_l_min", "L/min"), ("_hpa", "hPa"), ("_c", "°C"), ("_pct", "%"),
                         ("_s", "s"), ("_n", "N")):
        if column.endswith(suffix):
            return unit
    if column.startswith("rpm"):
        return "rpm"
    return ""


_UNITS = None
_FIELDS = None


def status_fields() -> dict:
    """Every status field of the protocol tables by its key: ``{key: [field, ...]}`` (one per
    status ID that carries it)."""
    global _FIELDS
    if _FIELDS is None:
        from ..codec import zk

        _FIELDS = {}
        for s in zk.STATUS:
            for f in s.layout.fields:
                _FIELDS.setdefault(f.key, []).append(f)
    return _FIELDS


def _status_units():
    global _UNITS
    if _UNITS is None:
        _UNITS = {k: next(f.unit for f in fs if f.unit) for k, fs in status_fields().items() if any(f.unit for f in fs)}
    return _UNITS


def cell(value, column=None):
    """A value as a workbook cell: numbers and booleans as they are, ``time`` as a date-time,
    lists ``;``-joined, dicts ``key=value``, anything else as text."""
    if value is None or isinstance(value, (bool, int, float)):
        from .writers import fits_double

        # a cell is a double, written with 16 significant digits (openpyxl): 1.7976931348623157e308
        # would come back as infinity, so a workbook holds numbers below 1e308
        return value if value is None or isinstance(value, bool) or (fits_double(value) and abs(value) < 1e308) \
            else None
    if column == "time" and isinstance(value, str):
        try:
            return datetime.datetime.strptime(value.rstrip("Z"), "%Y-%m-%dT%H:%M:%S.%f")
        except ValueError:
            return _xml_text(value)
    from .writers import csv_cell

    return _xml_text(value if isinstance(value, str) else csv_cell(value))


def _xml_text(text: str) -> str:
    """``text`` as a cell holds it: the control characters XML has no place for written as
    ``\\xNN`` (openpyxl refuses them, and the workbook would be lost)."""
    from openpyxl.cell.cell import ILLEGAL_CHARACTERS_RE

    return ILLEGAL_CHARACTERS_RE.sub(lambda m: f"\\x{ord(m.group()):02x}", text)


class XlsxWriter:
    """Records into a workbook saved as ``path`` at :meth:`close` (see the module's text).

    :meth:`sheets` gives the steps (``columns``, ``rows``) and the summary (a dict) before the
    close; without them those sheets say so."""

    def __init__(self, path, columns, units=None):
        from openpyxl import Workbook

        from .writers import CsvWriter

        self.path = path
        self.columns = list(columns)
        self.units = dict(units or {})        # declared units (an external sensor's channels)
        self.partial = path + PARTIAL
        try:
            stream = open(self.partial, "x", encoding="utf-8", newline="")
        except OSError as e:
            raise OutputError(f"output: cannot write {self.partial}: {e.strerror or e}") from None
        self._journal = CsvWriter(stream, self.columns)
        import tempfile

        _sweep()
        try:
            self._temp = tempfile.mkdtemp(prefix=f"{TEMP_PREFIX}{os.getpid()}-")
        except OSError as e:
            stream.close()
            os.unlink(self.partial)
            raise OutputError(f"output: cannot make a temporary directory for {path}: {e.strerror or e}") from None
        self.book = Workbook(write_only=True)
        self._sheet = None
        self._n = 0
        self._rows = 0
        self._steps = None
        self._summary = None
        self._new_sheet()

    def _new_sheet(self):
        self._n += 1
        self._sheet = self.book.create_sheet("records" if self._n == 1 else f"records {self._n}")
        self._sheet.freeze_panes = "A3"        # the header and units stay in view
        with _private_temp(self._temp):        # the sheet's first row makes its temporary file
            self._sheet.append(self.columns)
        self._sheet.append([self.units.get(c) or unit_of(c) for c in self.columns])
        self._rows = 2

    def write(self, rec) -> None:
        if self._rows >= MAX_ROWS:
            self._new_sheet()
        self._sheet.append([self._cell(rec.get(c), c) for c in self.columns])
        self._rows += 1
        self._journal.write(rec)

    def _cell(self, value, column):
        v = cell(value, column)
        if isinstance(v, datetime.datetime):
            from openpyxl.cell import WriteOnlyCell

            c = WriteOnlyCell(self._sheet, value=v)
            c.number_format = TIME_FORMAT          # the milliseconds shown, not only kept
            return c
        return v

    def sheets(self, steps=None, summary=None) -> None:
        """The steps (``(columns, rows)``) and the summary of the run, written at the close."""
        self._steps = steps
        self._summary = summary

    def close(self) -> None:
        if self.book is None:
            return
        book, self.book = self.book, None
        steps = book.create_sheet("steps")
        with _private_temp(self._temp):         # each sheet's first row makes its temporary file
            if self._steps:
                cols, rows = self._steps
                steps.freeze_panes = "B3"
                steps.append(list(cols))
            else:
                steps.append(["no steps (zk profile --settle/--average/--steps-csv averages each step)"])
            summary = book.create_sheet("summary")
            summary.append(["figure", "value", "unit"])
        if self._steps:
            steps.append([self.units.get(c[:-5] if c.endswith(("_mean", "_min", "_max")) else c[:-4]
                                         if c.endswith("_std") else c) or unit_of(c) for c in cols])
            for r in rows:
                steps.append([cell(r.get(c), c) for c in cols])
        _summary_rows(summary, self._summary)
        tmp = f"{self.path}.tmp{os.getpid()}"
        try:
            book.save(tmp)
            os.replace(tmp, self.path)
        except OSError as e:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            self._journal.stream.close()
            raise OutputError(f"output: cannot write {self.path}: {e.strerror or e} "
                              f"(the rows are in {self.partial})") from None
        finally:
            self._drop_temp()
        self._journal.stream.close()
        try:
            os.unlink(self.partial)
        except OSError:
            pass

    def _drop_temp(self):
        import shutil

        if getattr(self, "_temp", None):
            shutil.rmtree(self._temp, ignore_errors=True)
            self._temp = None

    def __del__(self):
        self._drop_temp()


def _summary_rows(sheet, summary):
    """The summary's rows, under the header row ``figure, value, unit`` (given by the caller)."""
    if not summary:
        sheet.append(["no summary"])
        return
    tables = []
    for key, value in summary.items():
        if key == "steps":
            continue                           # the steps sheet
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            tables.append((key, value))
            continue
        if isinstance(value, dict):
            for k, v in value.items():
                sheet.append([f"{key}.{k}", cell(v) if not isinstance(v, dict) else cell(str(v)), unit_of(k)])
            continue
        if key == "states" and isinstance(value, list):
            value = " > ".join(value)
        sheet.append([key, cell(value), unit_of(key)])
    for key, rows in tables:
        sheet.append([])
        cols = list(dict.fromkeys(k for r in rows for k in r))
        sheet.append([f"{key}:"])
        sheet.append(cols)
        for r in rows:
            sheet.append([cell(r.get(c), c) for c in cols])


def check(output, append) -> None:
    """Refuse what a workbook cannot do, before anything is opened."""
    require()
    if append:
        raise UsageError("append: a workbook cannot be appended to; give a new -o FILE.xlsx")
    if not output or output == "-":
        raise UsageError("format xlsx: a workbook needs a file; give -o FILE.xlsx")
    if os.path.lexists(output + PARTIAL):
        raise UsageError(f"output: {output + PARTIAL} holds the rows of a run killed before its workbook "
                         "was written; move or delete it first")
