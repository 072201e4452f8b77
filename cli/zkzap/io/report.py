"""Run reports: the time histories of a logged run, the steady-state curves of its steps, and its
header (title, metadata, summary), as PNG, SVG, PDF or one self-contained HTML file.

Inputs: the telemetry a ``zk monitor``/``zk send --for``/``zk profile`` run wrote (CSV snapshot
rows, JSON Lines or JSON records), or a ``--raw-log`` capture decoded on the fly; optionally the
``--steps-csv`` file and the ``--summary-json`` file of a ``zk profile`` run. Only the columns
a plot needs are kept in memory (as float arrays).

matplotlib is imported only by :func:`render` (optional extra ``plot``); :func:`terminal` draws the
time histories with rich for a quick look over ssh.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from array import array

from ..codec.fields import beyond_float, quote_value
from ..errors import InvalidValue, UsageError, clip
from ..infile import open_input

#: Time-history panels: (title, unit label, [(column, legend label)]).
PANELS = (
    ("Engine speed", "rpm", [("rpm", "rpm"), ("target_rpm", "target rpm"), ("rpm_corrected", "corrected N/√θ")]),
    ("Exhaust gas temperature", "EGT (°C)", [("egt_c", "EGT")]),
    ("Thrust", "thrust (kgf)", [("thrust_kg", "thrust (ECU)"), ("thrust_corrected_kg", "corrected F/δ")]),
    ("Throttle", "throttle (%)", [("throttle_pct", "throttle (ECU)"), ("target_throttle_pct", "target")]),
    ("Fuel flow", "fuel flow (L/min)", [("fuel_flow_l_min", "fuel flow (ECU)"),
                                        ("fuel_flow_corrected_l_min", "corrected")]),
    ("Voltages", "voltage (V)", [("power_voltage_v", "battery"), ("pump_voltage_v", "pump"),
                                 ("radio_voltage_v", "radio")]),
)
#: Columns measured (not targets: those come from the steps file).
MEASURED = ("rpm", "egt_c", "thrust_kg", "throttle_pct", "fuel_flow_l_min", "power_voltage_v", "pump_voltage_v",
            "radio_voltage_v", "rpm_corrected", "thrust_corrected_kg", "fuel_flow_corrected_l_min")
#: The keys of a record that are no external sensor's channel (the rest of a record's numbers are).
_NOT_SENSOR = ("time", "t", "kind", "id", "frame", "payload", "stale", "stale_ids", "warnings", "limit", "reserved",
               "out_of_range", "gap_s", "since_t", "reason", "step", "target_rpm", "target_throttle_pct")
#: Steady-state plots from the steps: (title, x column, x label, y column, y label).
STEP_PLOTS = (
    ("Thrust vs rpm", "rpm_mean", "rpm", "thrust_kg_mean", "thrust (kgf)"),
    ("EGT vs rpm", "rpm_mean", "rpm", "egt_c_mean", "EGT (°C)"),
    ("TSFC vs thrust", "thrust_kg_mean", "thrust (kgf)", "tsfc_g_kn_s", "TSFC (g/(kN·s))"),
)
#: Engine-state groups shaded behind the time histories.
STATE_GROUPS = (
    ("starting", ("ignition-min-throttle", "ignition", "preheat", "fuel-ramp", "learn-max-throttle",
                  "learn-min-throttle", "learn-idle", "restart"), "#fff2cc"),
    ("running", ("running", "running-min-throttle", "running-pump-limit"), "#e2f0d9"),
    ("cooling", ("cooling",), "#deebf7"),
)
FORMATS = ("png", "svg", "pdf", "html")
MISSING_EXTRA = "zk report needs matplotlib: pip install 'zkzap[plot]'"


class Run:
    """A run's series: ``t`` and each measured column as float arrays (nan where empty), the
    engine-state changes ``[(t, name)]`` and limit events ``[(t, limit)]``. ``extra``: more
    columns to keep (the fields limits name). ``label`` names the run in a comparison's legend."""

    def __init__(self, name, extra=()):
        self.name = name
        self.label = name
        self.keep = tuple(MEASURED) + tuple(c for c in extra if c not in MEASURED)
        self.t = array("d")
        self.series = {}
        self.present = set()
        self.states = []
        self.limit_events = {}
        self.warn_events = {}
        self.columns = set()         # the columns (keys) the input has
        self.notes = []              # what reading the input left out (a cut JSON array)
        self.steps = None            # rows of its steps file (or its summary's steps)
        self.summary = None
        self.offset = 0.0            # subtracted from t on a comparison's common axis
        self.outside = 0             # records with a value outside the protocol's range
        self.first_outside = None    # (t, column, value, (lo, hi))
        self.sensors = []            # the columns of external sensors (numbers no status field holds)
        self.trip_t = None           # when the run tripped (its trip record): nothing was sent after it
        self._looked = 0

    def add(self, rec, where=None):
        """Take the record ``rec`` (read at ``where``, ``FILE:LINE``)."""
        try:
            self._add(rec)
        except InvalidValue as e:
            key = next((c for c in ("t", *self.keep) if _beyond(rec.get(c))), "?")
            raise UsageError(f"run: {where or self.name}: {key}: {e}") from None

    def _add(self, rec):
        t = _float(rec.get("t"))
        if t is None:
            return
        trip = rec.get("trip")
        if trip or rec.get("kind") in ("trip", "rundown"):
            # a trip's record, or the rundown's end after it (a CSV row with only its trip column)
            if self.trip_t is None and rec.get("kind") != "rundown" and not str(trip or "").startswith("rundown"):
                self.trip_t = t
            return
        if rec.get("kind") not in (None, "", "status"):
            return                   # a control frame, a gap: no status values
        if self._looked < 100:
            self._looked += 1
            self._discover(rec)
        values = [_float(rec.get(c)) for c in self.keep]      # all read before any is kept
        self.t.append(t)
        ranges = _ranges()
        outside = None
        for c, v in zip(self.keep, values):
            r = ranges.get(c)
            if v is not None and r is not None and not r[0] <= v <= r[1] and outside is None:
                outside = (t, c, v, r)
            s = self.series.get(c)
            if s is None:
                s = self.series[c] = array("d", [math.nan] * (len(self.t) - 1))
            s.append(math.nan if v is None else v)
            if v is not None:
                self.present.add(c)
        if outside is not None:
            self.outside += 1
            if self.first_outside is None:
                self.first_outside = outside
        name = rec.get("engine_state_name")
        if name and isinstance(name, str) and (not self.states or self.states[-1][1] != name):
            self.states.append((t, name))
        for key, events in (("limit", self.limit_events), ("warnings", self.warn_events)):
            for text in _texts(rec.get(key)):
                events.setdefault(text, t)

    def _discover(self, rec):
        known = _known_keys()
        for k, v in rec.items():
            if k in known or k in self.keep or not isinstance(k, str) or k.endswith("_name"):
                continue
            if _float(v) is not None:
                self.keep += (k,)
                self.sensors.append(k)
                self.series[k] = array("d", [math.nan] * len(self.t))

    def running_t(self):
        """When the engine first reached a running state (None: never)."""
        from ..api.logbook import RUNNING_STATES

        return next((t for t, name in self.states if name in RUNNING_STATES), None)


_RANGES = None
_KNOWN = None


def _known_keys():
    global _KNOWN
    if _KNOWN is None:
        from ..codec import zk

        _KNOWN = frozenset(zk.STATUS_KEYS) | frozenset(MEASURED) | frozenset(_NOT_SENSOR)
    return _KNOWN


def _ranges():
    """The protocol's range of each status field (its table's physical range)."""
    global _RANGES
    if _RANGES is None:
        from .xlsx import status_fields

        _RANGES = {}
        for key, fields in status_fields().items():
            got = [r for r in (f.physical_range() for f in fields) if r is not None]
            if got:
                _RANGES[key] = (min(r[0] for r in got), max(r[1] for r in got))
    return _RANGES


#: A run has at least this many status records; more than :data:`MAX_OUTSIDE` of them with a
#: value outside the protocol's ranges and it is no run (a chunk of another file, decoded).
MIN_RECORDS = 10
MAX_OUTSIDE = 0.02


def check_run(run, path, min_records=1) -> None:
    """Refuse (UsageError) what is not a run: fewer than ``min_records`` status records (a raw
    log: :data:`MIN_RECORDS`, since bytes of any file can hold a frame by chance), or more than
    :data:`MAX_OUTSIDE` of them holding values outside the protocol's ranges; a few such records
    are noted."""
    n = len(run.t)
    if n < min_records:
        raise UsageError(f"run: {path}: not a run: {n} status record{'s' if n != 1 else ''} (at least "
                         f"{min_records})")
    if run.outside:
        t, c, v, (lo, hi) = run.first_outside
        what = f"{c} {v:g} at t={t:g} s is outside the protocol's range {lo:g}..{hi:g}"
        if run.outside > MAX_OUTSIDE * n:
            raise UsageError(f"run: {path}: not a run: {run.outside} of {n} records hold values outside the "
                             f"protocol's ranges ({what})")
        run.notes.append(f"{path}: {run.outside} record{'s' if run.outside > 1 else ''} hold values outside the "
                         f"protocol's ranges ({what})")


def _float(v):
    """A record's number, or None (empty, not a number, not finite); InvalidValue for a number
    written in full that no float holds (an integer of 400 digits, ``1e400``)."""
    if v.__class__ is str:                    # the common case of a text input, first
        if not v:
            return None
        try:
            f = float(v)
        except ValueError:
            return None
        if f - f == 0.0:                      # finite
            return f
        if beyond_float(v, f):
            raise InvalidValue(f"{clip(repr(v))} is beyond a float's range (1.8e308)")
        return None
    if v is None or isinstance(v, bool):
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    except OverflowError:                     # an int beyond a float's range
        raise InvalidValue(f"{quote_value(v)} is beyond a float's range (1.8e308)") from None
    if isinstance(v, str) and beyond_float(v, f):
        raise InvalidValue(f"{clip(repr(v))} is beyond a float's range (1.8e308)")
    return f if math.isfinite(f) else None


def _beyond(v) -> bool:
    try:
        _float(v)
    except InvalidValue:
        return True
    return False


def _texts(v):
    if not v:
        return []
    if isinstance(v, list):
        return [str(x) for x in v]
    text = str(v)
    if text.startswith("["):
        try:
            return [str(x) for x in json.loads(text)]
        except ValueError:
            pass
    return [x for x in text.split(";") if x]


def _is_binary(head: bytes) -> bool:
    if not head:
        return False
    if head[:2] in (b"\xff\xfe", b"\xfe\xff") and 0 in head[2:4]:
        return False                            # UTF-16 text: the text reader says so
    if b"\0" in head or head[0] in (0xF1, 0xF2, 0xF3, 0xF4, 0xF5, 0xF6, 0xF7, 0xF8, 0xF9, 0xFA):
        return True
    # the first line decides: text whose first line is text (a stray byte further on is named
    # by the text reader, with its line), bytes otherwise
    first, newline, _ = head.partition(b"\n")
    try:
        first.decode("utf-8")
    except UnicodeDecodeError as e:
        return bool(newline) or e.start < len(first) - 4     # not just a character cut at the block's end
    return False


def load_run(path, extra=()) -> Run:
    """Read a telemetry CSV / JSON Lines / JSON file, a raw log or a pcapng capture into a
    :class:`Run` (``-``: standard input, spooled to a temporary file so that it is read in
    constant memory like any file).

    The text formats are read line by line in constant memory (a JSON array too, so a run
    killed before its closing bracket reads up to its last whole record, noted in
    :attr:`Run.notes`); text that is not UTF-8, a line that is not a record and a CSV row the
    csv module refuses are a UsageError naming ``FILE:LINE``."""
    if path == "-":
        return _load_stdin(extra)
    try:
        with open_input(path) as f:
            head = f.read(4096)
    except OSError as e:
        raise UsageError(f"run: cannot read {path}: {e.strerror}") from None
    run = Run(path, extra)
    if head.startswith(b"PK\x03\x04"):
        _load_xlsx(path, run)
    elif head.startswith(b"\x89MCAP"):
        _load_mcap(path, run)
    elif _is_binary(head):
        _load_raw(path, run)
        run.min_records = MIN_RECORDS
    else:
        from ..api.textfile import iter_lines

        text = head.lstrip(b"\xef\xbb\xbf").lstrip()
        lines = iter_lines(path, "run")
        if text.startswith(b"{"):
            _json_lines(lines, path, run)
        elif text.startswith(b"["):
            _json_array(lines, path, run)
        else:
            _csv_rows(lines, path, run)
    if not len(run.t):
        raise UsageError(f"run: {path}: no records")
    check_run(run, path, getattr(run, "min_records", 1))
    return run


def _record(value, path, n):
    if not isinstance(value, dict):
        raise UsageError(f"run: {path}:{n}: not a JSON record (an object)")
    return value


def _json_lines(lines, path, run):
    for n, line in lines:
        if not line.strip():
            continue
        try:
            rec = _record(json.loads(line), path, n)
        except (ValueError, RecursionError):
            raise UsageError(f"run: {path}:{n}: not a JSON record") from None
        if n <= 100:
            run.columns.update(rec)
        run.add(rec, f"{path}:{n}")


#: The longest record of a JSON array read (characters, over however many lines it spans).
MAX_RECORD = 1 << 20


def _json_array(lines, path, run):
    """The records of a JSON array, one at a time (however its lines are laid out)."""
    decoder = json.JSONDecoder()
    buf, opened, closed, count, start = "", False, False, 0, 1
    for n, line in lines:
        if not buf.strip():
            start = n
        buf += line
        while True:
            rest = buf.lstrip(" \t\r\n,") if opened else buf.lstrip()
            if not rest:
                buf = ""
                break
            if closed:
                raise UsageError(f"run: {path}:{n}: text after the JSON array's closing bracket")
            if not opened:
                if rest[0] != "[":
                    raise UsageError(f"run: {path}:{n}: not a JSON array of records")
                opened, buf = True, rest[1:]
                continue
            if rest[0] == "]":
                closed, buf = True, rest[1:]
                continue
            try:
                rec, end = decoder.raw_decode(rest)
            except RecursionError:
                raise UsageError(f"run: {path}:{start}: not a JSON record") from None
            except ValueError:
                if len(rest) > MAX_RECORD:
                    raise UsageError(f"run: {path}:{start}: not a JSON record") from None
                buf = rest                     # the record goes on on the next line
                break
            _record(rec, path, start)
            if count < 100:
                run.columns.update(rec)
            run.add(rec, f"{path}:{start}")
            count += 1
            buf, start = rest[end:], n
    if not closed:
        cut = " and its last record is cut" if buf.strip() else ""
        run.notes.append(f"{path}: the JSON array is not closed{cut} (a run that was stopped by force?): "
                         f"read its {count} whole records")


class _Numbered:
    """The text of ``(line number, text)`` pairs, remembering the number of the last one
    (the csv module's own count lags a row it refuses)."""

    def __init__(self, lines):
        self.lines, self.n = lines, 0

    def __iter__(self):
        for self.n, text in self.lines:
            yield text


def _csv_rows(lines, path, run):
    lines = _Numbered(lines)
    reader = csv.DictReader(lines)
    try:
        if not reader.fieldnames or "t" not in reader.fieldnames:
            raise UsageError(f"run: {path}: expected the CSV that 'zk monitor' or 'zk profile' writes "
                             f"(a header with a 't' column), JSON records or a raw log")
        run.columns.update(reader.fieldnames)
        for rec in reader:
            run.add(rec, f"{path}:{lines.n}")
    except csv.Error as e:
        raise UsageError(f"run: {path}:{lines.n}: not a CSV row: {e}") from None


def _load_stdin(extra):
    import shutil
    import sys
    import tempfile

    if sys.stdin is None:
        raise UsageError("run: '-': no standard input")
    from ..infile import counted, shown_as

    with tempfile.NamedTemporaryFile(prefix="zkzap-report-", suffix=".run") as tmp:
        with counted(sys.stdin.buffer, "stdin") as stdin:       # how much came: a progress display's
            shutil.copyfileobj(stdin, tmp, 1 << 16)
        tmp.flush()
        shown_as(tmp.name, "stdin")
        try:
            run = load_run(tmp.name, extra)
        except UsageError as e:
            raise UsageError(str(e).replace(tmp.name, "stdin")) from None
        finally:
            shown_as(tmp.name, None)
    run.name = run.label = "stdin"
    return run


def _load_raw(path, run):
    """A raw log, or a pcapng capture (by its content: its own receive times become ``t``). A
    file most of whose bytes are no ZK status frame is no raw log (a binary that happens to hold
    a few bytes a CRC lets through)."""
    from ..api.capture import replay_source
    from ..api.telemetry import Telemetry

    src = replay_source(path, fast=True)
    tel = Telemetry(None, None, True, clock=src.clock)
    try:
        while True:
            got = src.poll()
            if got is None:
                break
            for t, frame in got:
                for rec in tel.feed(t, frame):
                    run.columns.update(rec)
                    run.add(rec)
        for rec in tel.flush():
            run.add(rec)
    finally:
        src.close()
    framer = getattr(src, "framer", None)
    frames, skipped = getattr(framer, "frames", 0), getattr(framer, "skipped", 0)
    if skipped > frames * 7:
        raise UsageError(f"run: {path}: not a run: {skipped} of its {skipped + frames * 7} bytes are no ZK status "
                         f"frame ({frames} frames); expected a raw log (--raw-log), a capture, or the CSV, JSON, "
                         f"workbook or MCAP a session writes")


def _load_xlsx(path, run):
    """The records sheet(s) of a workbook a session wrote (``-o run.xlsx``: a units row under
    the header)."""
    from .bridges import require_extra

    require_extra("openpyxl", "xlsx", "run: a workbook")
    import zipfile

    from openpyxl import load_workbook

    try:
        book = load_workbook(path, read_only=True, data_only=True)
    except (OSError, zipfile.BadZipFile, KeyError, ValueError) as e:
        raise UsageError(f"run: {path}: not a workbook a session wrote: {e}") from None
    try:
        sheets = [ws for ws in book.worksheets if ws.title == "records" or ws.title.startswith("records ")]
        if not sheets:
            raise UsageError(f"run: {path}: a workbook without a records sheet (expected the workbook "
                             f"'zk monitor -o run.xlsx' or 'zk profile -o run.xlsx' writes)")
        for ws in sheets:
            rows = ws.iter_rows(values_only=True)
            header = next(rows, None)
            if not header or "t" not in header:
                raise UsageError(f"run: {path}: sheet {ws.title}: no header with a 't' column")
            header = [str(h) if h is not None else "" for h in header]
            run.columns.update(header)
            for n, row in enumerate(rows, 2):
                rec = dict(zip(header, row))
                if n == 2 and rec.get("t") == "s":
                    continue                               # the units row
                run.add(rec, f"{path}: sheet {ws.title}: row {n}")
    finally:
        book.close()


def _load_mcap(path, run):
    """The status messages of an MCAP file a session wrote (``-o run.mcap``), in log-time order;
    a file cut by a kill reads up to its last whole chunk."""
    from .bridges import require_extra

    require_extra("mcap", "mcap", "run: an MCAP file")
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader

    with open_input(path) as f:
        try:
            for _schema, channel, message in NonSeekingReader(f).iter_messages():
                if not channel.topic.startswith("/zk/status/"):
                    continue
                try:
                    rec = json.loads(message.data)
                except ValueError:
                    raise UsageError(f"run: {path}: a message on {channel.topic} is not a JSON record") from None
                if isinstance(rec, dict):
                    run.columns.update(rec)
                    run.add(rec)
        except McapError as e:
            if not len(run.t):
                raise UsageError(f"run: {path}: not an MCAP file a session wrote: {e}") from None
            run.notes.append(f"{path}: the MCAP file ends early ({e}): read up to its last whole chunk")


def load_steps(path) -> list:
    """The rows of a ``zk profile --steps-csv`` file (UsageError naming ``FILE:LINE`` for text
    that is not UTF-8 or not CSV)."""
    from ..api.textfile import iter_lines

    lines = _Numbered(iter_lines(path, "steps"))
    try:
        rows = list(csv.DictReader(lines))
    except csv.Error as e:
        raise UsageError(f"steps: {path}:{lines.n}: not a CSV row: {e}") from None
    if rows and "step" not in rows[0]:
        raise UsageError(f"steps: {path}: expected the CSV that 'zk profile --steps-csv' writes")
    return rows


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and not _beyond(v)


def _number_or_null(v):
    return v is None or _is_number(v)


#: The lists of a summary the report reads: key -> (check of an item, the item in words, the
#: list in words). Everything the report reads of a summary is checked here, so a hand-edited or
#: damaged summary is refused naming the key instead of failing while the report is drawn.
_SUMMARY_LISTS = {
    "states": (lambda x: isinstance(x, str), "a state name (a string)", "state names"),
    "errors": (lambda x: isinstance(x, dict) and _is_number(x.get("code")) and isinstance(x.get("name"), str)
               and _is_number(x.get("t")), "an ECU error: an object with code, name and t", "ECU errors"),
    "limits": (lambda x: isinstance(x, dict) and isinstance(x.get("limit"), str)
               and isinstance(x.get("verdict", ""), str) and _number_or_null(x.get("first_violation_t"))
               and all(isinstance(x.get(k), (str, type(None))) for k in ("field", "op"))
               and all(_number_or_null(x.get(k)) for k in ("threshold", "warn")),
               "a limit: an object with limit, verdict and first_violation_t (and field and op as "
               "strings, threshold and warn as numbers)", "limits"),
    "steps": (lambda x: isinstance(x, dict) and isinstance(x.get("step"), (str, int, float, type(None))),
              "a step: an object with a step number", "steps"),
}


def load_summary(path) -> dict:
    """A ``zk profile --summary-json`` document, its lists checked (UsageError naming the file
    and the key: ``summary: sum.json: states[2]: 5 is not a state name (a string)``)."""
    from ..api.documents import DocumentError, read

    try:
        doc, name = read(path, "summary", finite=False)
    except DocumentError as e:
        raise UsageError(f"summary: {e} (expected 'zk profile --summary-json' output)") from None
    if not isinstance(doc, dict):
        raise UsageError(f"summary: {path}: expected a JSON object")
    for key, (ok, shape, plural) in _SUMMARY_LISTS.items():
        value = doc.get(key)
        if value is None:
            continue
        if not isinstance(value, list):
            raise UsageError(f"summary: {path}: {key}: {_short(value)} is not a list of {plural}")
        for i, item in enumerate(value):
            if not ok(item):
                raise UsageError(f"summary: {path}: {key}[{i}]: {_short(item)} is not {shape}")
    return doc


def _short(value, width=40):
    text = json.dumps(value, ensure_ascii=False, default=str)
    return text if len(text) <= width else text[:width - 3] + "..."


def summary_limits(summary) -> list:
    """The limits a summary names, as ``(text, field, op, threshold, warn)``."""
    out = []
    for s in (summary or {}).get("limits") or ():
        if s.get("field") and s.get("op") and _float(s.get("threshold")) is not None:
            out.append((s.get("limit") or f"{s['field']}{s['op']}{s['threshold']}", s["field"], s["op"],
                        float(s["threshold"]), _float(s.get("warn"))))
    return out


def align(runs, how="start") -> None:
    """Put each run's time on a common axis: ``start`` (each from its session's start, t = 0:
    where its schedule started, however late its first status frame came), ``first`` (each from
    its first record), ``running`` (from the engine's first running state) or ``step:N`` (from
    the start of step N)."""
    for run in runs:
        if how == "start":
            run.offset = 0.0
        elif how == "first":
            run.offset = run.t[0] if len(run.t) else 0.0
        elif how == "running":
            t = run.running_t()
            if t is None:
                raise UsageError(f"align: running: the engine never ran in {run.name}")
            run.offset = t
        else:
            n = how.split(":", 1)[1]
            row = next((r for r in run.steps or () if str(r.get("step")) == n), None)
            if row is None or _float(row.get("step_start_s")) is None:
                raise UsageError(f"align: step:{n}: {run.name} has no step {n}"
                                 + ("" if run.steps else " (give its --steps or a --summary with steps)"))
            run.offset = float(row["step_start_s"])


def labels_for(paths) -> list:
    """Legend names for runs: their file names, with as much of the path as tells them apart."""
    parts = [os.path.normpath(p).split(os.sep) if p != "-" else ["stdin"] for p in paths]
    n = 1
    while True:
        names = [os.sep.join(p[-n:]) for p in parts]
        if len(set(names)) == len(names) or all(len(p) <= n for p in parts):
            return names
        n += 1


# --- what to draw --------------------------------------------------------------------------------

def plan(run, steps=None, summary=None, limits=()):
    """``(panels, step_plots, skipped)``: the panels that have data and the reasons others do not.
    A limit on a field no panel shows gets a panel of its own when the run has that field."""
    return plan_many([run], [steps], limits)


def plan_many(runs, steps_list, limits=()):
    skipped = []
    panels = []
    targets = {}
    for steps in steps_list:
        for c in _targets(steps or ()):
            targets.setdefault(c, True)
    present = set().union(*(r.present for r in runs))
    columns = set().union(*(r.columns for r in runs))
    names = " or ".join(r.name for r in runs)
    for title, unit, lines in PANELS:
        have = [(c, label) for c, label in lines if c in present or c in targets]
        if any(c in present for c, _ in have):
            panels.append((title, unit, have))
        else:
            cols = [c for c, _ in lines if not c.startswith("target")]
            absent = [c for c in cols if c not in columns]
            if len(absent) == len(cols):
                why = f"{names} has no column {' or '.join(cols)}"
            else:
                why = f"no values in {' or '.join(cols)} in {names}"
            skipped.append(f"{title.lower()}: {why}")
    shown = {c for _, _, lines in panels for c, _ in lines}
    for run in runs:
        for c in run.sensors:
            if c in present and c not in shown:
                shown.add(c)
                panels.append((f"Sensor {c}", _unit(c, _declared_units(runs).get(c)), [(c, c)]))
    for text, field, *_ in limits:
        if field in shown:
            continue
        shown.add(field)
        if field in present:
            panels.append((field, _unit(field), [(field, field)]))
        else:
            skipped.append(f"limit {text}: {names} has no values of {field}")
    step_plots = []
    if not any(steps_list):
        skipped.append("steady-state plots (thrust vs rpm, EGT vs rpm, TSFC vs thrust): no --steps file")
    else:
        for title, x0, xl, y0, yl in STEP_PLOTS:
            series = []
            sources = set()
            for run, steps in zip(runs, steps_list):
                # the thrust TSFC was computed from: the --thrust-from sensor's, when the steps have it
                x, y = (_thrust_column(steps) if c == "thrust_kg_mean" else c for c in (x0, y0))
                if "thrust_from_kg_mean" in (x, y):
                    sources.add(next((r.get("thrust_from") for r in steps if r.get("thrust_from")), "sensor"))
                pts = [(float(r[x]), float(r[y]), settled(r))
                       for r in steps or () if _float(r.get(x)) is not None and _float(r.get(y)) is not None
                       and (y != "tsfc_g_kn_s" or float(r[y]) > 0)]
                if pts:
                    series.append((run.label, sorted(pts)))
            if sources:
                where = f"kgf, sensor {', '.join(sorted(sources))}"
                xl, yl = (lbl.replace("kgf", where) if lbl.startswith("thrust") else lbl for lbl in (xl, yl))
            if series:
                step_plots.append((title, xl, yl, series))
            else:
                skipped.append(f"{title}: no step has both {x} and {y}")
    return panels, step_plots, skipped


def _unit(field, unit=None):
    from .xlsx import unit_of

    unit = unit or unit_of(field)
    return f"{field} ({unit})" if unit else field


def settled(row) -> bool:
    """Whether a step row (from a steps file or a summary) settled."""
    return str(row.get("settled")).lower() not in ("false", "none", "")


def _thrust_column(steps):
    """The steps' thrust column: the sensor's (``--thrust-from``) when they have one, else the ECU's."""
    return ("thrust_from_kg_mean" if any(_float(r.get("thrust_from_kg_mean")) is not None for r in steps or ())
            else "thrust_kg_mean")


def _declared_units(runs):
    """The units the runs' summaries declare for their sensors' channels."""
    out = {}
    for run in runs:
        for s in (run.summary or {}).get("aux") or ():
            for c in (s.get("channels") or []) if isinstance(s, dict) else ():
                if isinstance(c, dict) and isinstance(c.get("name"), str) and isinstance(c.get("unit"), str):
                    out.setdefault(c["name"], c["unit"])
    return out


def _sent_until(run) -> float:
    """Until when the run's schedule was sent: its trip (the rundown after it is recorded, and
    no target was sent then), else its last record."""
    if run.trip_t is not None:
        return run.trip_t
    return run.t[-1] if len(run.t) else 0.0


def _targets(steps):
    """Target step lines from the steps file: {column: [(t0, t1, value)]}."""
    out = {}
    for r in steps:
        a, b = _float(r.get("step_start_s")), _float(r.get("step_end_s"))
        if a is None or b is None:
            continue
        for c in ("target_rpm", "target_throttle_pct"):
            v = _float(r.get(c))
            if v is not None:
                out.setdefault(c, []).append((a, b, v))
    return out


def _limit_times(run, summary):
    events = dict(run.limit_events)
    for s in (summary or {}).get("limits") or ():
        if s.get("first_violation_t") is not None:
            events.setdefault(s["limit"], s["first_violation_t"])
    return sorted(events.items(), key=lambda kv: kv[1])


def summary_rows(summary):
    """(label, value) rows of a summary JSON for the header."""
    if not summary:
        return []

    def v(x, unit=""):
        return "-" if x is None else f"{x:g}{unit}" if isinstance(x, float) else f"{x}{unit}"

    rows = []
    for key, label, unit in (("engine", "engine", ""), ("schedule", "schedule", ""), ("port", "port", ""),
                             ("outcome", "outcome", ""),
                             ("duration_s", "duration", " s"), ("frames", "frames", ""),
                             ("max_rpm", "max rpm", ""), ("max_egt_c", "max EGT", " °C"),
                             ("fuel_used_l", "fuel used", " L"), ("running_s", "engine running", " s"),
                             ("starts", "starts", ""), ("aborted", "abort sent", "")):
        if key in summary and summary[key] is not None:
            rows.append((label, v(summary[key], unit)))
    if "states" in summary:
        rows.append(("states", " > ".join(summary["states"]) or "-"))
    if "errors" in summary:
        rows.append(("ECU errors", ", ".join(f"{e['code']} {e['name']} at {e['t']:g} s" for e in summary["errors"])
                     or "none"))
    for s in summary.get("limits") or ():
        verdict = s.get("verdict", "")
        if s.get("first_violation_t") is not None:
            verdict += f" at {s['first_violation_t']:g} s"
        rows.append((f"limit {s['limit']}", f"{verdict}, extreme {v(s.get('extreme'))}"))
    return rows


#: Step quantities a comparison puts side by side: (column, label, decimals).
COMPARED = (("rpm_mean", "rpm", 0), ("egt_c_mean", "EGT °C", 0), ("thrust_kg_mean", "thrust kgf", 2),
            ("fuel_flow_l_min_mean", "fuel L/min", 3), ("tsfc_g_kn_s", "TSFC g/(kN·s)", 2))


def compared_steps(runs):
    """The runs' steps side by side by step number: ``[(step, target, [(label, values,
    differences)])]``, one entry per quantity of :data:`COMPARED`: each run's value (an unsettled
    step's starred) and each later run's difference from the first run (value and %)."""
    numbers = []
    for run in runs:
        for r in run.steps or ():
            if r.get("step") not in numbers:
                numbers.append(r.get("step"))
    out = []
    by_run = [{r.get("step"): r for r in run.steps or ()} for run in runs]
    cols_of = {col: [_thrust_column(run.steps) if col == "thrust_kg_mean" else col for run in runs]
               for col, _, _ in COMPARED}
    for n in numbers:
        targets = [(b.get(n) or {}).get("target") for b in by_run]
        target = targets[0] or next((t for t in targets if t), "")
        if len({t for t in targets if t}) > 1:
            target = " / ".join(t or "-" for t in targets)
        marks = ["" if settled(b.get(n) or {"settled": True}) else "*" for b in by_run]
        quantities = []
        for col, label, dec in COMPARED:
            values = [_float((b.get(n) or {}).get(c)) for b, c in zip(by_run, cols_of[col])]
            ref = values[0]
            diffs = []
            for v in values[1:]:
                if v is None or ref is None:
                    diffs.append("-")
                else:
                    pct = f" ({_signed((v - ref) / ref * 100, 1)} %)" if ref else ""
                    diffs.append(f"{_signed(v - ref, dec)}{pct}")
            quantities.append((label, [_fmt(v, dec) + m for v, m in zip(values, marks)], diffs))
        out.append((n, target, quantities))
    return out


def step_comparison(runs, short=False):
    """``(header, rows)``: :func:`compared_steps` as one row per step, each quantity of
    :data:`COMPARED` per run and its difference from the first run (value and %). ``short``
    names the runs by their number (#1, #2: the header lists them)."""
    names = [f"#{k + 1}" if short else run.label for k, run in enumerate(runs)]
    header = ["step", "target"]
    for _, label, _ in COMPARED:
        header += [f"{label} {names[0]}"]
        for name in names[1:]:
            header += [f"{label} {name}", f"Δ {name}"]
    rows = []
    for n, target, quantities in compared_steps(runs):
        row = [n, target]
        for _, values, diffs in quantities:
            row.append(values[0])
            for v, d in zip(values[1:], diffs):
                row += [v, d]
        rows.append(row)
    return header, rows


#: Under a comparison: what the mark of an unsettled step's value means.
UNSETTLED_NOTE = "* not settled (its note says why): compare it with care"


def _fmt(v, dec):
    if v is None:
        return "-"
    text = f"{v:.{dec}f}"
    return text[1:] if text.startswith("-") and not text.strip("-0.") else text      # no -0.0


def _signed(v, dec):
    text = f"{v:+.{dec}f}"
    return text if text.strip("+-0.") else text.replace("-", "+", 1)


# --- matplotlib ----------------------------------------------------------------------------------

def _mpl():
    try:
        import matplotlib
    except ImportError:
        raise UsageError(MISSING_EXTRA) from None
    matplotlib.use("Agg", force=True)
    from matplotlib.figure import Figure

    return Figure


#: Line colours of a comparison's runs (matplotlib's default cycle, named so targets stay black).
RUN_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
LIMIT_COLOUR, WARN_COLOUR = "#c00000", "#e69500"


#: A time history draws at most this many bins' minimum and maximum per line (the axes are
#: about 1,000 pixel columns wide at the report's size: two bins to a column keeps every peak and
#: every dip the series has; the numbers — steps, summary, limits — always use every record).
DRAW_BINS = 2000


def decimate(t, v, bins=None):
    """``(t, v)`` for drawing a line of the float arrays ``t`` and ``v``: the series itself when
    it has at most ``2 * bins`` points, else, of each of ``bins`` equal time bins, the points of
    its minimum and its maximum in their order (a line through them reaches every extreme the
    series does, bin by bin), and a NaN where a bin has no value (a gap stays a gap). numpy."""
    import numpy as np

    bins = bins or DRAW_BINS
    t = np.asarray(t, dtype=float)
    v = np.asarray(v, dtype=float)
    n = len(t)
    if n <= 2 * bins:
        return t, v
    t0, t1 = np.nanmin(t), np.nanmax(t)
    span = (t1 - t0) or 1.0
    b = np.clip(((t - t0) / span * bins).astype(np.int64), 0, bins - 1)
    idx = np.arange(n)
    finite = ~np.isnan(v)
    fb, fi, fv = b[finite], idx[finite], v[finite]
    picked = []
    if len(fi):
        # per bin (sorted by bin, then by value): the first is the bin's minimum, the last its maximum
        order = np.lexsort((fv, fb))
        sb = fb[order]
        starts = np.flatnonzero(np.r_[True, sb[1:] != sb[:-1]])
        ends = np.r_[starts[1:], len(sb)] - 1
        picked += [fi[order[starts]], fi[order[ends]]]
    # a bin without any value: a gap (one NaN point, at the bin's first record)
    has = np.zeros(bins, dtype=bool)
    has[fb] = True
    first = np.full(bins, -1, dtype=np.int64)
    first[b[::-1]] = idx[::-1]
    gaps = first[(~has) & (first >= 0)]
    keep = np.unique(np.concatenate(picked + [gaps]))
    return t[keep], v[keep]


def _history_axes(fig, grid, runs, panels, limits, work=None):
    """The time histories, a panel each (``work``: a :class:`~zkzap.io.term.Work` told of each)."""
    import numpy as np

    many = len(runs) > 1
    axes = []
    shared = None
    ref = runs[0]
    for i, (title, unit, lines) in enumerate(panels):
        if work is not None:
            work.step(f"report: drawing {title.lower()}", 0)
        ax = fig.add_subplot(grid[i], sharex=shared)
        shared = shared or ax
        axes.append(ax)
        if not many:
            _shade_states(ax, ref, ref.t[-1] if len(ref.t) else 0, legend=i == 0)
        if ref.steps:
            _shade_windows(ax, ref, label=i == 0, numbers=i == 0)
        for k, run in enumerate(runs):
            t = np.frombuffer(run.t, dtype=float) - run.offset
            targets = _targets(run.steps) if run.steps else {}
            for j, (c, label) in enumerate(lines):
                name = f"{label} — {run.label}" if many else label
                if c in targets:
                    if many and k:
                        continue                     # the targets of the reference run
                    xs, ys = target_line(run, targets[c])
                    ax.plot(xs, ys, color="black", linestyle="--", linewidth=1.0, label=label)
                elif c in run.present:
                    style = {"color": RUN_COLOURS[k % len(RUN_COLOURS)]} if many else {}
                    if many and j:
                        style["linestyle"] = (":", "-.", "--")[(j - 1) % 3]
                    ax.plot(*decimate(t, np.frombuffer(run.series[c], dtype=float)), linewidth=1.2, label=name,
                            **style)
        fields = {c for c, _ in lines}
        levels = [v for _, field, _, threshold, warn in limits if field in fields for v in (threshold, warn)
                  if v is not None]
        if levels:                                   # room for the lines and their labels
            lo, hi = ax.get_ylim()
            lo, hi = min([lo] + levels), max([hi] + levels)
            pad = (hi - lo) * 0.08 or 1.0
            ax.set_ylim(lo - (pad if min(levels) <= lo else 0), hi + pad)
        for text, field, op, threshold, warn in limits:
            if field not in fields:
                continue
            ax.axhline(threshold, color=LIMIT_COLOUR, linewidth=1.0, linestyle="-", label=f"limit {text}")
            # the limit's label above its line, the warning's below its own: apart however close
            above = warn is None or threshold >= warn
            _line_label(ax, threshold, f"limit {op} {threshold:g}", LIMIT_COLOUR, above=above)
            if warn is not None:
                ax.axhline(warn, color=WARN_COLOUR, linewidth=1.0, linestyle="--", label=f"warning {op} {warn:g}")
                _line_label(ax, warn, f"warn {op} {warn:g}", WARN_COLOUR, above=not above)
        for k, run in enumerate(runs):
            for text, et in _limit_times(run, run.summary):
                who = f" ({run.label})" if many else ""
                ax.axvline(et - run.offset, color="red", linewidth=1.2,
                           label=f"limit violated: {text}{who}" if i == 0 else None)
        if "rpm" in unit:
            ax.yaxis.set_major_formatter(_kilo())
        ax.set_ylabel(unit, fontsize=8)
        ax.set_title(title, fontsize=9, loc="left")
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=8)
        if i < len(panels) - 1:
            ax.tick_params(labelbottom=False)
        handles, labels = ax.get_legend_handles_labels()
        if handles:
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0, frameon=False)
        if work is not None:
            work.step()
    if axes:
        ends = [run.t[-1] - run.offset for run in runs if len(run.t)]
        starts = [min(run.t) - run.offset for run in runs if len(run.t)]
        if ends and max(ends) > min(starts):
            axes[0].set_xlim(min(min(starts), 0.0), max(ends))   # the plots stop where the runs did
        what = {"start": "the start", "running": "the engine's first running state"}
        axes[-1].set_xlabel("time since " + (what.get(getattr(ref, "aligned", "start"), f"the start of "
                                             f"{getattr(ref, 'aligned', 'the run').replace(':', ' ')}")) + " (s)")
    return axes


def target_line(run, segments):
    """``(xs, ys)``: a target's steps (``[(t0, t1, value)]``) on the run's aligned axis, NaN
    between them; none after the run ended (an abort: never sent)."""
    xs, ys = [], []
    end = _sent_until(run)
    for a, b, v in segments:
        if a >= end:
            continue
        xs += [a - run.offset, min(b, end) - run.offset, math.nan]
        ys += [v, v, math.nan]
    return xs, ys


def step_windows(run):
    """``[(step, start, window start, window end, settled)]`` of the run's steps on its aligned
    axis, cut at the end of what was sent."""
    out = []
    end = _sent_until(run)
    for r in run.steps or ():
        a, w0, w1 = (_float(r.get(k)) for k in ("step_start_s", "window_start_s", "window_end_s"))
        if a is None or w0 is None or w1 is None or a >= end:
            continue
        w0, w1 = min(w0, end), min(w1, end)
        out.append((r.get("step"), a - run.offset, w0 - run.offset, w1 - run.offset, settled(r)))
    return out


def state_spans(run, t_end):
    """``[(t0, t1, group, colour)]``: the run's engine states by :data:`STATE_GROUPS` on its
    aligned axis (the last until ``t_end``, on the run's own axis)."""
    group_of = {name: (g, colour) for g, names, colour in STATE_GROUPS for name in names}
    out = []
    for i, (t0, name) in enumerate(run.states):
        t1 = run.states[i + 1][0] if i + 1 < len(run.states) else t_end
        g = group_of.get(name)
        if g is not None and t1 > t0:
            out.append((t0 - run.offset, t1 - run.offset, g[0], g[1]))
    return out


def _line_label(ax, y, text, colour, above=True):
    from matplotlib.transforms import blended_transform_factory

    ax.text(0.995, y, text, color=colour, fontsize=6.5, ha="right", va="bottom" if above else "top",
            transform=blended_transform_factory(ax.transAxes, ax.transData), clip_on=True)


#: An averaging window's shade (settled, not settled): neither a state's colour.
WINDOW_COLOURS = ("#c7c1dd", "#f2b8b5")
#: The settle time's hatching.
SETTLING_COLOUR = "#9aa7b8"


def _shade_windows(ax, run, label=True, numbers=True):
    """Each step's settle time (hatched) and averaging window (shaded), numbered above."""
    from matplotlib.transforms import blended_transform_factory

    tr = blended_transform_factory(ax.transData, ax.transAxes)
    first = True
    shown = set()
    for step, a, w0, w1, ok in step_windows(run):
        if w0 > a:
            ax.axvspan(a, w0, facecolor="none", edgecolor=SETTLING_COLOUR, hatch="///", linewidth=0, zorder=0.5,
                       label="settling" if label and first else None)
        if w1 > w0:
            what = "averaging window" if ok else "averaging window (not settled)"
            ax.axvspan(w0, w1, color=WINDOW_COLOURS[0 if ok else 1], alpha=0.55, zorder=0.6,
                       label=what if label and what not in shown else None)
            shown.add(what)
        if numbers:
            ax.text((a + max(w1, a)) / 2, 1.0, f"{step}{'' if ok else '*'}", transform=tr, ha="center",
                    va="bottom", fontsize=7, color="#34495e" if ok else "#a61c00", fontweight="bold")
        first = False


def _shade_states(ax, run, t_end, legend=True):
    """The engine states shaded: one collection of spans per group (a long run's thousands of
    state changes are a few artists, not one each)."""
    spans = {}
    for t0, t1, group, colour in state_spans(run, t_end):
        spans.setdefault((group, colour), []).append((t0, t1 - t0))
    for (group, colour), xranges in spans.items():
        ax.broken_barh(xranges, (0, 1), transform=ax.get_xaxis_transform(), facecolors=colour, zorder=0,
                       label=f"state: {group}" if legend else None)


def _step_axes(fig, grid, step_plots):
    many = any(len(series) > 1 for *_, series in step_plots)
    for i, (title, xl, yl, series) in enumerate(step_plots):
        ax = fig.add_subplot(grid[i])
        for k, (name, pts) in enumerate(series):
            colour = RUN_COLOURS[k % len(RUN_COLOURS)]
            good = [p for p in pts if p[2]]
            bad = [p for p in pts if not p[2]]
            who = f" — {name}" if many else ""
            if good:
                ax.plot([p[0] for p in good], [p[1] for p in good], marker="o", linewidth=1.0, color=colour,
                        label=f"settled steps{who}")
            if bad:
                ax.plot([p[0] for p in bad], [p[1] for p in bad], marker="o", linestyle="none",
                        markerfacecolor="none", color=colour if many else "grey", label=f"never settled{who}")
        for axis, label in ((ax.xaxis, xl), (ax.yaxis, yl)):
            if label == "rpm":
                axis.set_major_formatter(_kilo())
        ax.set_title(title, fontsize=9)
        ax.set_xlabel(xl, fontsize=8)
        ax.set_ylabel(yl, fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6.5, loc="best")


def _kilo():
    from matplotlib.ticker import FuncFormatter

    return FuncFormatter(lambda v, _: f"{v / 1000:g}k" if v else "0")


def _wrap(text, width=95):
    import textwrap

    return "\n".join(textwrap.wrap(str(text), width)) or str(text)


def figure_histories(runs, panels, limits, title):
    Figure = _mpl()
    n = max(len(panels), 1)
    fig = Figure(figsize=(11, 1.7 * n + 1.2), layout="constrained")
    grid = fig.add_gridspec(n, 1)
    _history_axes(fig, grid, runs, panels, limits)
    if title:
        fig.suptitle(_wrap(title), fontsize=11, x=0.01, ha="left")
    return fig


def figure_steps(step_plots, title):
    Figure = _mpl()
    fig = Figure(figsize=(11, 3.4), layout="constrained")
    grid = fig.add_gridspec(1, max(len(step_plots), 1))
    _step_axes(fig, grid, step_plots)
    if title:
        fig.suptitle(_wrap(title), fontsize=11, x=0.01, ha="left")
    return fig


#: A step table's columns: (column, heading, decimals; None: as it is).
STEP_TABLE = (("step", "step", None), ("target", "target", None), ("window_start_s", "window from (s)", 1),
              ("window_end_s", "to (s)", 1), ("frames", "frames", None), ("rpm_mean", "rpm", 0),
              ("rpm_std", "± rpm", 0), ("egt_c_mean", "EGT (°C)", 0), ("egt_c_std", "± EGT", 1),
              ("thrust_kg_mean", "thrust ECU (kgf)", 2), ("thrust_from_kg_mean", "thrust sensor (kgf)", 3),
              ("thrust_from_kg_std", "± thrust sensor", 3), ("fuel_flow_l_min_mean", "fuel flow ECU (L/min)", 3),
              ("fuel_flow_from_l_min_mean", "fuel flow sensor (L/min)", 4),
              ("tsfc_g_kn_s", "TSFC (g/(kN·s))", 2), ("tsfc_kg_kgf_h", "TSFC (kg/(kgf·h))", 4),
              ("rpm_corrected", "rpm corrected", 0), ("thrust_corrected_kg", "thrust corrected (kgf)", 3),
              ("tsfc_corrected_g_kn_s", "TSFC corrected", 2), ("settled", "settled", None), ("note", "note", None))


def step_table(steps):
    """``(columns, headings)`` of a step table: :data:`STEP_TABLE`'s columns the steps have values
    in (the basic ones always), then each sensor channel's mean (``X_mean`` columns beyond them)."""
    always = {"step", "target", "rpm_mean", "egt_c_mean", "thrust_kg_mean", "tsfc_g_kn_s", "settled", "note"}
    cols, head = [], []
    known = {c for c, _, _ in STEP_TABLE}
    for c, h, _ in STEP_TABLE:
        if c in always or any(r.get(c) not in (None, "") for r in steps):
            cols.append(c)
            head.append(h)
    for c in steps[0] if steps else ():
        if c.endswith("_mean") and c not in known and not c.startswith(("pump_voltage", "throttle", "fuel_flow")):
            if any(r.get(c) not in (None, "") for r in steps):
                cols.insert(cols.index("settled"), c)
                head.insert(head.index("settled"), c[:-5].replace("_", " "))
    return cols, head


_DECIMALS = {c: d for c, _, d in STEP_TABLE}


def _cell(row, col):
    v = row.get(col)
    dec = _DECIMALS.get(col, 3 if col.endswith("_mean") else None)
    f = _float(v)
    if col == "settled":
        return "yes" if settled(row) else "NO" if str(v).lower() == "false" else "-"
    if dec is None or f is None:
        return "" if v is None else v
    return _fmt(f, dec)


def header_rows(runs, meta):
    """The header's rows: ``[label, value, ...]`` with one value per run (the metadata spans
    them): the runs' files and where their time axis starts, then their summaries side by side."""
    many = len(runs) > 1
    rows = [[k, v] + [""] * (len(runs) - 1) for k, v in meta]
    if many:
        rows.append(["file"] + [r.name for r in runs])
        rows.append(["t = 0 at"] + [f"{r.offset:g} s of the run" for r in runs])
    table = {}
    for k, run in enumerate(runs):
        for label, value in summary_rows(run.summary):
            table.setdefault(label, [""] * len(runs))[k] = value
    rows += [[label] + values for label, values in table.items()]
    return rows


#: The header table's font size (points), and what one of its lines takes (inches): a row of
#: one line, and each further line of a wrapped cell.
HEADER_FONT = 8
HEADER_ROW_IN = 0.19
HEADER_LINE_IN = 0.135
#: The widest character of the header's font, in ems, for how many fit a column (DejaVu Sans:
#: digits 0.64, lower case about 0.55; a little wider is a line broken early, never a cut).
_EM_PER_CHAR = 0.62


def _chars(width_in, fontsize=HEADER_FONT):
    """How many characters of ``fontsize`` points fit in ``width_in`` inches of a table cell (its
    padding taken off)."""
    return max(8, int(width_in * 72 / (fontsize * _EM_PER_CHAR)) - 2)


def _fold(text, width):
    """``text`` in lines of at most ``width`` characters: broken at spaces, after hyphens and
    after the separators of a file name or a list (``, / _ = & ; >``), a word longer than a line
    cut where it must — every character kept (a header's values are never cut off)."""
    import re
    import textwrap

    text = str(text)
    if len(text) <= width:
        return [text]
    # a break chance after a separator: a space textwrap may break at (marked by a zero-width
    # space), taken out again where the line went on
    spaced = re.sub(r"([,/_=&;>])(?=\S)", "\\1\u200b ", text)
    lines = textwrap.wrap(spaced, width + 1, break_long_words=True, break_on_hyphens=True)
    return [line.replace("\u200b ", "").replace("\u200b", "") for line in lines] or [text]


def _folded(rows, widths_in):
    """Each cell of ``rows`` as its lines (:func:`_fold` to its column's width in inches), and
    each row's height in inches."""
    width_chars = [_chars(w) for w in widths_in]
    cells = [[_fold(v, width_chars[i]) for i, v in enumerate(r)] for r in rows]
    return cells, [HEADER_ROW_IN + HEADER_LINE_IN * (max(len(c) for c in r) - 1) for r in cells]


def _header_table(ax, rows, col_labels, widths_in, top):
    """The header's table in ``ax`` (rows of cells, column labels or None; ``widths_in`` each
    column's width in inches), every cell wrapped to its column (no value cut), each row as high
    as its most lines; it fills the axes from ``top`` (a fraction of the axes' height) down."""
    cells, heights = _folded(([col_labels] if col_labels else []) + rows, widths_in)
    total_in, total_w = sum(heights), sum(widths_in)
    text = [["\n".join(c) for c in r] for r in cells]
    table = ax.table(cellText=text[1:] if col_labels else text, colLabels=text[0] if col_labels else None,
                     colWidths=[w / total_w for w in widths_in], cellLoc="left", colLoc="left", edges="horizontal",
                     bbox=[0, 0, 1, top])
    table.auto_set_font_size(False)
    table.set_fontsize(HEADER_FONT)
    for (row, _col), cell in table.get_celld().items():
        cell.set_height(heights[row] / total_in)


def figure_all(runs, panels, step_plots, limits, title, meta, work=None):
    """One figure: header (title, metadata, summary table), time histories, steady-state plots
    and, comparing runs, their steps side by side. The header's cells are wrapped to their
    columns, never cut."""
    Figure = _mpl()
    rows = header_rows(runs, meta)
    comparison = step_comparison(runs, short=True) if len(runs) > 1 and any(r.steps for r in runs) else None
    fig_w = 11 if not comparison else 14
    title = _wrap(title, 90)
    many = len(runs) > 1
    col_labels = [""] + [f"#{k + 1} {r.label}" for k, r in enumerate(runs)] if many else None
    # the table spans the axes' width (less the layout's margins): the label column and one per run
    table_w = fig_w - 0.5
    widths_in = [table_w * 0.26] + [table_w * 0.74 / len(runs)] * len(runs)
    title_h = 0.35 + 0.2 * title.count("\n")
    table_h = sum(_folded(([col_labels] if col_labels else []) + rows, widths_in)[1]) if rows else 0.0
    header_h = title_h + (table_h + 0.1 if rows else 0)
    n = len(panels)
    heights = [header_h] + [1.7] * n + ([3.0] if step_plots else [])
    if comparison:
        heights.append(0.5 + 0.2 * (len(comparison[1]) + 1))
    fig = Figure(figsize=(fig_w, sum(heights) + 0.6), layout="constrained")
    grid = fig.add_gridspec(len(heights), 1, height_ratios=heights)
    head = fig.add_subplot(grid[0])
    head.axis("off")
    head.set_title(title, fontsize=12, loc="left", fontweight="bold")
    if rows:
        _header_table(head, rows, col_labels, widths_in, top=1.0)   # the title is above the axes
    if n:
        sub = grid[1:1 + n].subgridspec(n, 1, hspace=0.08)
        _history_axes(fig, sub, runs, panels, limits, work)
    if step_plots:
        sub = grid[1 + n].subgridspec(1, len(step_plots), wspace=0.25)
        _step_axes(fig, sub, step_plots)
    if comparison:
        ax = fig.add_subplot(grid[-1])
        ax.axis("off")
        ax.set_title("Steps side by side (Δ: difference from " + runs[0].label + "; " + UNSETTLED_NOTE + ")",
                     fontsize=9, loc="left")
        header, body = comparison
        table = ax.table(cellText=body, colLabels=header, loc="upper left", cellLoc="center")
        table.auto_set_font_size(False)
        table.set_fontsize(6.5)
    return fig


def render(path, fmt, runs, limits=(), title="zkzap run report", meta=(), interactive=False):
    """Write the report of ``runs`` (one, or several compared; each :class:`Run` with its
    ``steps``, ``summary`` and ``offset``) to ``path`` in ``fmt``; returns the skipped plots.
    ``interactive`` (HTML only): plotly figures instead of SVG (:mod:`.report_interactive`)."""
    if isinstance(runs, Run):
        runs = [runs]
    limits = list(limits) + [x for run in runs for x in summary_limits(run.summary)
                             if x[0] not in {y[0] for y in limits}]
    limits = list({x[0]: x for x in limits}.values())
    panels, step_plots, skipped = plan_many(runs, [r.steps for r in runs], limits)
    import warnings

    with warnings.catch_warnings():
        # constrained layout says so when a long title or legend leaves it no room; the report
        # is still whole, and the warning would be noise on the user's terminal
        warnings.filterwarnings("ignore", message=".*constrained.*", category=UserWarning)
        warnings.filterwarnings("ignore", message=".*[Tt]ight.*", category=UserWarning)
        if fmt == "html":
            if interactive:
                from .report_interactive import page

                text = page(runs, panels, step_plots, limits, title, meta)
            else:
                text = _html(runs, panels, step_plots, limits, title, meta)
            with open(path, "w", encoding="utf-8") as f:
                f.write(text)
            return skipped
        from .term import working

        # on a terminal, what is being drawn (a run of a million records takes seconds)
        with working("report: drawing", total=len(panels) + 1) as work:
            fig = figure_all(runs, panels, step_plots, limits, title, meta, work)
            work.step(f"report: writing the {fmt.upper()}", 0)
            fig.savefig(path, format=fmt, dpi=110, metadata=_file_meta(fmt, title))
            work.step()
    return skipped


def _file_meta(fmt, title):
    if fmt == "png":
        return {"Title": title, "Software": "zkzap"}
    if fmt == "svg":
        return {"Title": title}
    return {"Title": title, "Creator": "zkzap"}


def _svg(fig) -> str:
    import matplotlib

    buf = io.StringIO()
    with matplotlib.rc_context({"svg.fonttype": "none"}):     # text stays text: smaller, searchable
        fig.savefig(buf, format="svg")
    text = buf.getvalue()
    return text[text.index("<svg"):]


def _table(rows, header=None, ident=None):
    from html import escape

    out = f"<table{f' id={chr(34)}{ident}{chr(34)}' if ident else ''}>"
    if header:
        out += "<tr>" + "".join(f"<th>{escape(str(c))}</th>" for c in header) + "</tr>"
    return out + "".join("<tr>" + "".join(f"<td>{escape(str(c))}</td>" for c in r) + "</tr>" for r in rows) + \
        "</table>"


def _html(runs, panels, step_plots, limits, title, meta):
    from html import escape

    figures = []
    if panels:
        fig = figure_histories(runs, panels, limits, None)
        figures.append(f"<figure id=\"time-histories\"><figcaption>Time histories: "
                       f"{escape(', '.join(p[0] for p in panels))}</figcaption>{_svg(fig)}</figure>")
    if step_plots:
        fig = figure_steps(step_plots, None)
        figures.append(f"<figure id=\"steady-state\"><figcaption>Steady state (step means): "
                       f"{escape(', '.join(p[0] for p in step_plots))}</figcaption>{_svg(fig)}</figure>")
    return html_page(runs, title, meta, figures)


def html_page(runs, title, meta, figures, head=""):
    """The HTML report's page: the title, the summary table, ``figures`` (HTML), the steps side by
    side (comparing runs) and each run's step table; ``head``: more for the page's head."""
    from html import escape

    parts = [f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{escape(title)}</title>",
             "<style>body{font-family:sans-serif;margin:1.5em;max-width:1300px}table{border-collapse:collapse;"
             "font-size:0.9em;margin:0.5em 0 1em}td,th{border-bottom:1px solid #ccc;padding:2px 8px;text-align:left}"
             "figure{margin:1em 0}svg{max-width:100%;height:auto}</style>" + head + "</head><body>",
             f"<h1>{escape(title)}</h1>"]
    rows = header_rows(runs, meta)
    if rows:
        top = "" if len(runs) == 1 else "<tr><th></th>" + "".join(f"<th>{escape(r.label)}</th>" for r in runs) + \
            "</tr>"
        parts.append("<table id=\"summary\">" + top + "".join(
            "<tr><th>" + escape(str(r[0])) + "</th>" + "".join(f"<td>{escape(str(v))}</td>" for v in r[1:]) + "</tr>"
            for r in rows) + "</table>")
    parts += figures
    if len(runs) > 1 and any(r.steps for r in runs):
        header, body = step_comparison(runs)
        parts.append(f"<h2>Steps side by side</h2><p>Δ: the difference from {escape(runs[0].label)}. "
                     f"{escape(UNSETTLED_NOTE)}.</p>" + _table(body, header, "step-comparison"))
    for run in runs:
        if run.steps:
            cols, heads = step_table(run.steps)
            name = f"Steps: {run.label}" if len(runs) > 1 else "Steps"
            ident = "steps" if run is runs[0] else None
            parts.append(f"<h2>{escape(name)}</h2>" + _table([[_cell(r, c) for c in cols] for r in run.steps],
                                                            heads, ident))
    parts.append("</body></html>\n")
    return "\n".join(parts)


# --- terminal ------------------------------------------------------------------------------------

#: A compared run's mark in the terminal's overlays (its colour is its colour in the PNG); a cell
#: that several runs pass through shows :data:`SHARED_MARK`.
RUN_MARKS = ("•", "×", "+", "o", "*", "#", "~", "^")
SHARED_MARK = "◆"
_BLOCKS = " ▁▂▃▄▅▆▇█"
_LABEL = 11                                          # the value labels' column


def _bins(t, s, t0, span, width, offset=0.0):
    """The mean of series ``s`` in each of ``width`` time bins from ``t0`` over ``span`` (NaN: none)."""
    total, count = [0.0] * width, [0] * width
    for i in range(len(t)):
        v = s[i]
        if v == v:
            x = min(width - 1, max(0, int((t[i] - offset - t0) / span * (width - 1))))
            total[x] += v
            count[x] += 1
    return [total[x] / count[x] if count[x] else math.nan for x in range(width)]


def _axis_text(t0, t_end, width):
    from rich.text import Text

    end = f"{t_end:.6g} s"
    return Text(" " * _LABEL + f"{t0:<.6g} s".ljust(max(width - len(end), 1)) + end, style="dim")


def _value_label(row, height, lo, hi):
    return f"{hi:>10.6g} " if row == height else f"{lo:>10.6g} " if row == 1 else " " * _LABEL


def _single_panel(console, run, c, title, unit, width, height):
    """One run's quantity as block characters (the maximum of each column)."""
    from rich.text import Text

    t = run.t
    # a file appended to by two runs starts its t again: the panel spans every t it holds
    t0 = min(t) if len(t) else 0.0
    t_end = max(t) if len(t) else 0.0
    span = (t_end - t0) or 1.0
    col = [math.nan] * width
    s = run.series[c]
    for i in range(len(t)):
        v = s[i]
        if v == v:
            x = min(width - 1, int((t[i] - t0) / span * (width - 1)))
            col[x] = v if col[x] != col[x] else max(col[x], v)
    vals = [v for v in col if v == v]
    lo, hi = min(vals), max(vals)
    rng = (hi - lo) or 1.0
    console.print(Text(f"{title} — {unit}", style="bold"))
    for row in range(height, 0, -1):
        line = []
        for v in col:
            if v != v:
                line.append(" ")
                continue
            level = (v - lo) / rng * height
            cell = min(max(level - (row - 1), 0.0), 1.0)
            line.append(_BLOCKS[int(round(cell * 8))])
        console.print(Text(_value_label(row, height, lo, hi), style="dim") + Text("".join(line), style="cyan"))
    console.print(_axis_text(t0 - run.offset, t_end - run.offset, width))


def _overlay_panel(console, runs, lines, title, unit, width, height):
    """Several runs' quantity overlaid on one aligned time axis and one value scale: each run's
    bin means as its mark, in its colour; a cell two runs share as :data:`SHARED_MARK`."""
    from rich.text import Text

    drawn = []
    for k, run in enumerate(runs):
        c = next((c for c, _ in lines if c in run.present), None)
        if c is not None and len(run.t):
            drawn.append((k, run, c))
    if not drawn:
        return
    t0 = min(min(run.t) - run.offset for _, run, _ in drawn)
    t_end = max(max(run.t) - run.offset for _, run, _ in drawn)
    span = (t_end - t0) or 1.0
    means = [(k, _bins(run.t, run.series[c], t0, span, width, run.offset)) for k, run, c in drawn]
    vals = [v for _, m in means for v in m if v == v]
    lo, hi = min(vals), max(vals)
    rng = (hi - lo) or 1.0
    grid = [[set() for _ in range(width)] for _ in range(height)]
    for k, m in means:
        for x, v in enumerate(m):
            if v == v:
                grid[min(height - 1, int(round((v - lo) / rng * (height - 1))))][x].add(k)
    names = {c for _, _, c in drawn}
    console.print(Text(f"{title} — {unit}" + ("" if len(names) == 1 else f" ({', '.join(sorted(names))})"),
                       style="bold"))
    for row in range(height, 0, -1):
        text = Text(_value_label(row, height, lo, hi), style="dim")
        for cell in grid[row - 1]:
            if not cell:
                text.append(" ")
            elif len(cell) == 1:
                k = next(iter(cell))
                text.append(RUN_MARKS[k % len(RUN_MARKS)], style=RUN_COLOURS[k % len(RUN_COLOURS)])
            else:
                text.append(SHARED_MARK, style="bold")
        console.print(text)
    console.print(_axis_text(t0, t_end, width))


def _legend(runs):
    from rich.text import Text

    text = Text("runs: ", style="bold")
    for k, run in enumerate(runs):
        text.append(f"#{k + 1} ")
        text.append(RUN_MARKS[k % len(RUN_MARKS)], style=RUN_COLOURS[k % len(RUN_COLOURS)])
        text.append(f" {run.label}   ")
    text.append(f"{SHARED_MARK} several; t = 0 at ", style="dim")
    text.append(", ".join(f"{r.offset:g} s of #{k + 1}" for k, r in enumerate(runs)), style="dim")
    return text


def comparison_table(runs, width):
    """The steps of ``runs`` side by side for a terminal of ``width`` columns: a row per step and
    quantity, a column per run (``#1``, ``#2``: the title names them) and per difference from
    the first run; no value cut (the differences are left out first when the runs do not fit)."""
    from .term import fitted_table

    headings = ["step", "target", "quantity", "#1"]
    priority = [0, 0, 0, 0]
    for k in range(2, len(runs) + 1):
        headings += [f"#{k}", f"Δ #{k}"]
        priority += [0, -1]
    rows, sections = [], []
    for n, target, quantities in compared_steps(runs):
        sections.append(len(rows))
        for j, (label, values, diffs) in enumerate(quantities):
            row = [str(n) if j == 0 else "", str(target or "") if j == 0 else "", label, values[0]]
            for v, d in zip(values[1:], diffs):
                row += [v, d.replace(" %)", "%)")]           # "(+3.4%)": one word, never split at a wrap
            rows.append(row)
    names = ", ".join(f"#{k + 1} {r.label}" for k, r in enumerate(runs))
    return fitted_table(headings, rows, width, title=f"Steps side by side: {names} (Δ: the difference from #1)",
                        caption=UNSETTLED_NOTE, priority=priority, sections=sections)


def terminal(runs, console, width=None, height=6):
    """Draw the time histories with characters (rich): one run's quantities as block charts;
    several runs overlaid on their common (aligned) time axis, one panel per quantity, each run
    in its mark and colour; comparing runs, their steps side by side as a table that fits the
    terminal."""
    if isinstance(runs, Run):
        runs = [runs]
    panels, _, skipped = plan_many(runs, [r.steps for r in runs])
    skipped = [s for s in skipped if not s.startswith("steady-state")]
    width = width or max(20, min(console.width, 160) - _LABEL - 1)
    many = len(runs) > 1
    if many:
        console.print(_legend(runs))
    for title, unit, lines in panels:
        if many:
            _overlay_panel(console, runs, lines, title, unit, width, height + 2)
            continue
        c = next((c for c, _ in lines if c in runs[0].present), None)
        if c is not None:
            _single_panel(console, runs[0], c, title, unit, width, height)
    if many and any(r.steps for r in runs):
        console.print(comparison_table(runs, console.width))
    return skipped


def output_format(path, fmt=None):
    """The report's format: ``fmt``, else what the suffix of ``path`` names (.png, .svg, .pdf,
    .html); anything else is refused."""
    if fmt:
        return fmt
    from . import format_for_path

    return format_for_path(path, FORMATS, default=None)
