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

from ..errors import UsageError

#: Time-history panels: (title, unit label, [(column, legend label)]).
PANELS = (
    ("Engine speed", "rpm", [("rpm", "rpm"), ("target_rpm", "target rpm")]),
    ("Exhaust gas temperature", "EGT (°C)", [("egt_c", "EGT")]),
    ("Thrust", "thrust (kgf)", [("thrust_kg", "thrust")]),
    ("Throttle", "throttle (%)", [("throttle_pct", "throttle (ECU)"), ("target_throttle_pct", "target")]),
    ("Fuel flow", "fuel flow (L/min)", [("fuel_flow_l_min", "fuel flow")]),
    ("Voltages", "voltage (V)", [("power_voltage_v", "battery"), ("pump_voltage_v", "pump"),
                                 ("radio_voltage_v", "radio")]),
)
#: Columns measured (not targets: those come from the steps file).
MEASURED = ("rpm", "egt_c", "thrust_kg", "throttle_pct", "fuel_flow_l_min", "power_voltage_v", "pump_voltage_v",
            "radio_voltage_v")
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
    engine-state changes ``[(t, name)]`` and limit events ``[(t, limit)]``."""

    def __init__(self, name):
        self.name = name
        self.t = array("d")
        self.series = {}
        self.present = set()
        self.states = []
        self.limit_events = {}
        self.warn_events = {}
        self.columns = set()         # the columns (keys) the input has
        self.notes = []              # what reading the input left out (a cut JSON array)

    def add(self, rec):
        t = _float(rec.get("t"))
        if t is None:
            return
        self.t.append(t)
        for c in MEASURED:
            v = _float(rec.get(c))
            s = self.series.get(c)
            if s is None:
                s = self.series[c] = array("d", [math.nan] * (len(self.t) - 1))
            s.append(math.nan if v is None else v)
            if v is not None:
                self.present.add(c)
        name = rec.get("engine_state_name")
        if name and isinstance(name, str) and (not self.states or self.states[-1][1] != name):
            self.states.append((t, name))
        for key, events in (("limit", self.limit_events), ("warnings", self.warn_events)):
            for text in _texts(rec.get(key)):
                events.setdefault(text, t)


def _float(v):
    if v is None or v == "" or isinstance(v, bool):
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


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


def load_run(path) -> Run:
    """Read a telemetry CSV / JSON Lines / JSON file, a raw log or a pcapng capture into a :class:`Run`.

    The text formats are read line by line in constant memory (a JSON array too, so a run
    killed before its closing bracket reads up to its last whole record, noted in
    :attr:`Run.notes`); text that is not UTF-8, a line that is not a record and a CSV row the
    csv module refuses are a UsageError naming ``FILE:LINE``."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError as e:
        raise UsageError(f"run: cannot read {path}: {e.strerror}") from None
    run = Run(path)
    if _is_binary(head):
        _load_raw(path, run)
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
        run.add(rec)


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
            run.add(rec)
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
            run.add(rec)
    except csv.Error as e:
        raise UsageError(f"run: {path}:{lines.n}: not a CSV row: {e}") from None


def _load_raw(path, run):
    """A raw log, or a pcapng capture (by its content: its own receive times become ``t``)."""
    from ..api.capture import replay_source
    from ..api.telemetry import Telemetry

    src = replay_source(path, fast=True)
    tel = Telemetry(None, None, True, wall0=src.wall0, wall_clock=getattr(src, "wall_clock", False))
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
    return isinstance(v, (int, float)) and not isinstance(v, bool)


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
               and isinstance(x.get("verdict", ""), str) and _number_or_null(x.get("first_violation_t")),
               "a limit: an object with limit, verdict and first_violation_t", "limits"),
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


# --- what to draw --------------------------------------------------------------------------------

def plan(run, steps=None, summary=None):
    """``(panels, step_plots, skipped)``: the panels that have data and the reasons others do not."""
    skipped = []
    panels = []
    targets = _targets(steps) if steps else {}
    for title, unit, lines in PANELS:
        have = [(c, label) for c, label in lines if c in run.present or c in targets]
        if any(c in run.present for c, _ in have):
            panels.append((title, unit, have))
        else:
            cols = [c for c, _ in lines if not c.startswith("target")]
            absent = [c for c in cols if c not in run.columns]
            if len(absent) == len(cols):
                why = f"{run.name} has no column {' or '.join(cols)}"
            else:
                why = f"no values in {' or '.join(cols)} in {run.name}"
            skipped.append(f"{title.lower()}: {why}")
    step_plots = []
    if not steps:
        skipped.append("steady-state plots (thrust vs rpm, EGT vs rpm, TSFC vs thrust): no --steps file")
    else:
        for title, x, xl, y, yl in STEP_PLOTS:
            pts = [(float(r[x]), float(r[y]), str(r.get("settled")).lower() not in ("false", "none", ""))
                   for r in steps if _float(r.get(x)) is not None and _float(r.get(y)) is not None
                   and (y != "tsfc_g_kn_s" or float(r[y]) > 0)]
            if pts:
                step_plots.append((title, xl, yl, sorted(pts)))
            else:
                skipped.append(f"{title}: no step has both {x} and {y}")
    return panels, step_plots, skipped


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
    for key, label, unit in (("schedule", "schedule", ""), ("port", "port", ""), ("outcome", "outcome", ""),
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


# --- matplotlib ----------------------------------------------------------------------------------

def _mpl():
    try:
        import matplotlib
    except ImportError:
        raise UsageError(MISSING_EXTRA) from None
    matplotlib.use("Agg", force=True)
    from matplotlib.figure import Figure

    return Figure


def _history_axes(fig, grid, run, panels, steps, summary):
    import numpy as np

    t = np.frombuffer(run.t, dtype=float)
    targets = _targets(steps) if steps else {}
    axes = []
    shared = None
    limit_events = _limit_times(run, summary)
    for i, (title, unit, lines) in enumerate(panels):
        ax = fig.add_subplot(grid[i], sharex=shared)
        shared = shared or ax
        axes.append(ax)
        _shade_states(ax, run, t[-1] if len(t) else 0, legend=i == 0)
        for c, label in lines:
            if c in targets:
                xs, ys = [], []
                for a, b, v in targets[c]:
                    xs += [a, b, math.nan]
                    ys += [v, v, math.nan]
                ax.plot(xs, ys, color="black", linestyle="--", linewidth=1.0, label=label)
            elif c in run.present:
                ax.plot(t, np.frombuffer(run.series[c], dtype=float), linewidth=1.2, label=label)
        if unit == "rpm":
            ax.yaxis.set_major_formatter(_kilo())
        for n, (text, et) in enumerate(limit_events):
            ax.axvline(et, color="red", linewidth=1.2, label=f"limit violated: {text}" if i == 0 else None)
        ax.set_ylabel(unit)
        ax.set_title(title, fontsize=9, loc="left")
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=8)
        if i < len(panels) - 1:
            ax.tick_params(labelbottom=False)
        handles, labels = ax.get_legend_handles_labels()
        if handles:
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0, frameon=False)
    if axes:
        axes[-1].set_xlabel("time since start (s)")
    return axes


def _shade_states(ax, run, t_end, legend=True):
    group_of = {name: (g, colour) for g, names, colour in STATE_GROUPS for name in names}
    used = set()
    for i, (t0, name) in enumerate(run.states):
        t1 = run.states[i + 1][0] if i + 1 < len(run.states) else t_end
        g = group_of.get(name)
        if g is None or t1 <= t0:
            continue
        ax.axvspan(t0, t1, color=g[1], zorder=0,
                   label=f"state: {g[0]}" if legend and g[0] not in used else None)
        used.add(g[0])


def _step_axes(fig, grid, step_plots):
    for i, (title, xl, yl, pts) in enumerate(step_plots):
        ax = fig.add_subplot(grid[i])
        good = [p for p in pts if p[2]]
        bad = [p for p in pts if not p[2]]
        if good:
            ax.plot([p[0] for p in good], [p[1] for p in good], marker="o", linewidth=1.0, label="settled steps")
        if bad:
            ax.plot([p[0] for p in bad], [p[1] for p in bad], marker="o", linestyle="none", markerfacecolor="none",
                    color="grey", label="never settled")
        for axis, label in ((ax.xaxis, xl), (ax.yaxis, yl)):
            if label == "rpm":
                axis.set_major_formatter(_kilo())
        ax.set_title(title, fontsize=9)
        ax.set_xlabel(xl, fontsize=8)
        ax.set_ylabel(yl, fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7, loc="best")


def _kilo():
    from matplotlib.ticker import FuncFormatter

    return FuncFormatter(lambda v, _: f"{v / 1000:g}k" if v else "0")


def figure_histories(run, panels, steps, summary, title, meta):
    Figure = _mpl()
    n = max(len(panels), 1)
    fig = Figure(figsize=(11, 1.7 * n + 1.2), layout="constrained")
    grid = fig.add_gridspec(n, 1)
    _history_axes(fig, grid, run, panels, steps, summary)
    fig.suptitle(title, fontsize=11, x=0.01, ha="left")
    return fig


def figure_steps(step_plots, title):
    Figure = _mpl()
    fig = Figure(figsize=(11, 3.4), layout="constrained")
    grid = fig.add_gridspec(1, max(len(step_plots), 1))
    _step_axes(fig, grid, step_plots)
    fig.suptitle(title, fontsize=11, x=0.01, ha="left")
    return fig


def figure_all(run, panels, step_plots, steps, summary, title, meta):
    """One figure: header (title, metadata, summary table), time histories, steady-state plots."""
    Figure = _mpl()
    rows = list(meta) + summary_rows(summary)
    header_h = 0.5 + 0.19 * len(rows) if rows else 0.15
    n = len(panels)
    heights = [header_h] + [1.7] * n + ([3.0] if step_plots else [])
    fig = Figure(figsize=(11, sum(heights) + 0.6), layout="constrained")
    grid = fig.add_gridspec(len(heights), 1, height_ratios=heights)
    head = fig.add_subplot(grid[0])
    head.axis("off")
    head.set_title(title, fontsize=12, loc="left", fontweight="bold")
    if rows:
        table = head.table(cellText=[[k, _clip(v)] for k, v in rows], colWidths=[0.22, 0.78], loc="upper left",
                           cellLoc="left", edges="horizontal")
        table.auto_set_font_size(False)
        table.set_fontsize(8)
        table.scale(1, 1.0)
    if n:
        sub = grid[1:1 + n].subgridspec(n, 1, hspace=0.08)
        _history_axes(fig, sub, run, panels, steps, summary)
    if step_plots:
        sub = grid[-1].subgridspec(1, len(step_plots), wspace=0.25)
        _step_axes(fig, sub, step_plots)
    return fig


def _clip(text, width=110):
    text = str(text)
    return text if len(text) <= width else text[:width - 1] + "…"


def render(path, fmt, run, steps=None, summary=None, title="zkzap run report", meta=()):
    """Write the report to ``path`` in ``fmt`` (png, svg, pdf, html); returns the skipped plots."""
    panels, step_plots, skipped = plan(run, steps, summary)
    if fmt == "html":
        text = _html(run, panels, step_plots, steps, summary, title, meta)
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        return skipped
    fig = figure_all(run, panels, step_plots, steps, summary, title, meta)
    fig.savefig(path, format=fmt, dpi=110, metadata=_file_meta(fmt, title))
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


def _html(run, panels, step_plots, steps, summary, title, meta):
    from html import escape

    parts = [f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{escape(title)}</title>",
             "<style>body{font-family:sans-serif;margin:1.5em;max-width:1100px}table{border-collapse:collapse;"
             "font-size:0.9em;margin:0.5em 0 1em}td,th{border-bottom:1px solid #ccc;padding:2px 8px;text-align:left}"
             "figure{margin:1em 0}svg{max-width:100%;height:auto}</style></head><body>",
             f"<h1>{escape(title)}</h1>"]
    rows = list(meta) + summary_rows(summary)
    if rows:
        parts.append("<table id=\"summary\">" + "".join(
            f"<tr><th>{escape(str(k))}</th><td>{escape(str(v))}</td></tr>" for k, v in rows) + "</table>")
    if panels:
        fig = figure_histories(run, panels, steps, summary, "Time histories", ())
        parts.append(f"<figure id=\"time-histories\"><figcaption>Time histories: "
                     f"{escape(', '.join(p[0] for p in panels))}</figcaption>{_svg(fig)}</figure>")
    if step_plots:
        fig = figure_steps(step_plots, "Steady state (step means)")
        parts.append(f"<figure id=\"steady-state\"><figcaption>Steady state: "
                     f"{escape(', '.join(p[0] for p in step_plots))}</figcaption>{_svg(fig)}</figure>")
    if steps:
        cols = ["step", "target", "window_start_s", "window_end_s", "rpm_mean", "egt_c_mean", "thrust_kg_mean",
                "fuel_flow_l_min_mean", "tsfc_g_kn_s", "tsfc_kg_kgf_h", "settled", "note"]
        parts.append("<h2>Steps</h2><table id=\"steps\"><tr>" + "".join(f"<th>{c}</th>" for c in cols) + "</tr>"
                     + "".join("<tr>" + "".join(f"<td>{escape(str(r.get(c, '')))}</td>" for c in cols) + "</tr>"
                               for r in steps) + "</table>")
    parts.append("</body></html>\n")
    return "\n".join(parts)


# --- terminal ------------------------------------------------------------------------------------

def terminal(run, console, steps=None, width=None, height=6):
    """Draw the time histories with block characters (rich), one panel per quantity."""
    from rich.text import Text

    panels, _, skipped = plan(run, steps, None)
    skipped = [s for s in skipped if not s.startswith("steady-state")]
    width = width or max(20, min(console.width, 160) - 16)
    t = run.t
    t_end = t[-1] if len(t) else 0.0
    t0 = t[0] if len(t) else 0.0
    span = (t_end - t0) or 1.0
    blocks = " ▁▂▃▄▅▆▇█"
    for title, unit, lines in panels:
        c = next(c for c, _ in lines if c in run.present)
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
                line.append(blocks[int(round(cell * 8))])
            label = f"{hi:>10.6g} " if row == height else f"{lo:>10.6g} " if row == 1 else " " * 11
            console.print(Text(label, style="dim") + Text("".join(line), style="cyan"))
        console.print(Text(" " * 11 + f"{t0:<.6g} s".ljust(width - 10) + f"{t_end:.6g} s", style="dim"))
    return skipped


def output_format(path, fmt=None):
    if fmt:
        return fmt
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    if ext == "htm":
        ext = "html"
    if ext not in FORMATS:
        raise UsageError(f"output: {path}: cannot tell the format from the name; use .png, .svg, .pdf or .html "
                         f"(or --format)")
    return ext
