"""The report of an endurance run (``zap cycle --report``): per-cycle reach times and currents
over the run, their histograms, and a summary, as PNG, SVG, PDF or one self-contained HTML
file — the formats of ``zk report`` (:mod:`zkzap.io.report`), chosen the same way.

The input is the cycle records (:data:`zkzap.api.cycle.COLUMNS`), from the run itself or read
back from its output file (CSV, JSON Lines or a JSON array), kept as float arrays.
matplotlib is imported only to draw (optional extra ``plot``).
"""

from __future__ import annotations

import csv
import json
import math
from array import array

from ..errors import UsageError
from .report import FORMATS, _file_meta, _mpl, _svg, output_format  # noqa: F401 - one report family

SERIES = ("cycle", "reach_b_s", "reach_a_s", "peak_current_ma", "mean_current_ma", "min_voltage_v", "overshoot_b",
          "overshoot_a", "min_voltage_raw")


class CycleRun:
    """The series of a cycle run (float arrays, nan where empty), the statuses seen and the
    cycles with error bits."""

    def __init__(self, name="cycle run"):
        self.name = name
        self.series = {k: array("d") for k in SERIES}
        self.statuses = {}
        self.flagged = 0
        self.groups = {}
        """{bus name: CycleRun} of a run on several buses (records with ``bus``): each bus its own
        series in the per-cycle plots."""

    def add(self, rec) -> None:
        bus = rec.get("bus")
        if bus not in (None, ""):
            if bus not in self.groups:
                self.groups[bus] = CycleRun(str(bus))
            self.groups[bus].add({k: v for k, v in rec.items() if k != "bus"})
        for k in SERIES:
            v = rec.get(k)
            try:
                self.series[k].append(float(v) if v not in (None, "") else math.nan)
            except (TypeError, ValueError):
                self.series[k].append(math.nan)
        status = rec.get("status") or "ok"
        self.statuses[status] = self.statuses.get(status, 0) + 1
        errors = rec.get("errors")
        if errors not in (None, "", [], "[]"):
            self.flagged += 1

    def __len__(self):
        return len(self.series["cycle"])

    def voltage(self):
        """``(series key, unit, axis label)`` of the lowest voltage: in volts, or raw where the
        records hold only raw values (Modbus RTU: the 17Lf's map gives present-voltage no unit)."""
        if not any(v == v for v in self.series["min_voltage_v"]) and any(v == v for v in self.series["min_voltage_raw"]):
            return "min_voltage_raw", "(raw)", "voltage (raw: unit not documented)"
        return "min_voltage_v", "V", "voltage (V)"

    def summary_rows(self):
        def stats(key, unit, dec=3):
            vals = sorted(v for v in self.series[key] if v == v)
            if not vals:
                return "-"
            p99 = vals[min(len(vals) - 1, max(0, math.ceil(0.99 * len(vals)) - 1))]
            return (f"mean {sum(vals) / len(vals):.{dec}f} {unit}, p99 {p99:.{dec}f}, min {vals[0]:.{dec}f}, "
                    f"max {vals[-1]:.{dec}f}")

        cycles = [v for v in self.series["cycle"] if v == v]
        buses = [("buses", "; ".join(f"{name}: {len(g)} cycles" for name, g in self.groups.items()))] \
            if len(self.groups) > 1 else []
        return buses + [("cycles", f"{len(self)}" + (f" ({int(min(cycles))}..{int(max(cycles))})" if cycles else "")),
                ("statuses", ", ".join(f"{k} {v}" for k, v in sorted(self.statuses.items()))),
                ("reach time to B", stats("reach_b_s", "s")), ("reach time to A", stats("reach_a_s", "s")),
                ("peak current", stats("peak_current_ma", "mA", 0)),
                ("mean current", stats("mean_current_ma", "mA", 1)),
                ("lowest voltage", stats(*self.voltage()[:2], 1)),
                ("cycles with error bits", str(self.flagged))]


def load_records(path) -> CycleRun:
    """A :class:`CycleRun` from a cycle output file (.csv, .jsonl, .json)."""
    run = CycleRun(path)
    try:
        with open(path, encoding="utf-8") as f:
            head = f.read(1)
            f.seek(0)
            if head == "[":
                from ..api.documents import load_json

                for rec in load_json(f.read(), path):
                    if isinstance(rec, dict):
                        run.add(rec)
            elif head == "{":
                for n, line in enumerate(f, 1):
                    if line.strip():
                        try:
                            run.add(json.loads(line))
                        except ValueError:
                            raise UsageError(f"{path}:{n}: not a JSON record") from None
            else:
                for rec in csv.DictReader(f):
                    run.add(rec)
    except OSError as e:
        raise UsageError(f"{path}: cannot read: {e.strerror or e}") from None
    return run


def _axes(fig, run):
    s = run.series
    parts = list(run.groups.items()) if len(run.groups) > 1 else [("", run)]    # a series per bus

    def per_cycle(ax, keys):
        for name, part in parts:
            for key, label in keys:
                ax.plot(part.series["cycle"], part.series[key], ".", ms=3,
                        label=(f"{label}, {name}" if label else name) if name else label)
        if any(label for _, label in keys) or len(parts) > 1:
            ax.legend(loc="best", fontsize="small")

    grid = fig.add_gridspec(3, 2)
    ax = fig.add_subplot(grid[0, 0])
    per_cycle(ax, (("reach_b_s", "to B"), ("reach_a_s", "to A")))
    ax.set_title("Reach time per cycle")
    ax.set_xlabel("cycle")
    ax.set_ylabel("reach time (s)")
    ax = fig.add_subplot(grid[0, 1])
    vals = [v for k in ("reach_b_s", "reach_a_s") for v in s[k] if v == v]
    if vals:
        ax.hist(vals, bins=min(50, max(5, len(vals) // 4)))
    ax.set_title("Reach time histogram")
    ax.set_xlabel("reach time (s)")
    ax.set_ylabel("legs")
    ax = fig.add_subplot(grid[1, 0])
    per_cycle(ax, (("peak_current_ma", "peak"), ("mean_current_ma", "mean")))
    ax.set_title("Current per cycle")
    ax.set_xlabel("cycle")
    ax.set_ylabel("current (mA)")
    ax = fig.add_subplot(grid[1, 1])
    vals = [v for v in s["peak_current_ma"] if v == v]
    if vals:
        ax.hist(vals, bins=min(50, max(5, len(vals) // 4)))
    ax.set_title("Peak current histogram")
    ax.set_xlabel("peak current (mA)")
    ax.set_ylabel("cycles")
    ax = fig.add_subplot(grid[2, 0])
    key, _, label = run.voltage()
    per_cycle(ax, ((key, ""),))
    ax.set_title("Lowest supply voltage per cycle")
    ax.set_xlabel("cycle")
    ax.set_ylabel(label)
    ax = fig.add_subplot(grid[2, 1])
    per_cycle(ax, (("overshoot_b", "at B"), ("overshoot_a", "at A")))
    ax.set_title("Overshoot per cycle")
    ax.set_xlabel("cycle")
    ax.set_ylabel("overshoot (counts)")


def figure(run, title, meta=()):
    Figure = _mpl()
    fig = Figure(figsize=(12, 12), layout="constrained")
    text = title + "\n" + "   ".join(f"{k}: {v}" for k, v in list(meta) + run.summary_rows()[:2])
    fig.suptitle(text, fontsize="medium")
    _axes(fig, run)
    return fig


def render(path, fmt, run, title="zkzap cycle report", meta=()) -> None:
    """Write the report of ``run`` to ``path`` in ``fmt`` (png, svg, pdf, html)."""
    if not len(run):
        raise UsageError("report: no cycle to report")
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*constrained.*", category=UserWarning)
        if fmt == "html":
            from html import escape

            rows = list(meta) + run.summary_rows()
            table = "".join(f"<tr><th>{escape(str(k))}</th><td>{escape(str(v))}</td></tr>" for k, v in rows)
            fig = figure(run, title, meta)
            text = (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{escape(title)}</title>"
                    "<style>body{font-family:sans-serif;margin:1.5em;max-width:1300px}table{border-collapse:collapse}"
                    "td,th{border-bottom:1px solid #ccc;padding:2px 8px;text-align:left}svg{max-width:100%;height:auto}"
                    f"</style></head><body><h1>{escape(title)}</h1><table id=\"summary\">{table}</table>"
                    f"<figure id=\"cycles\">{_svg(fig)}</figure></body></html>\n")
            with open(path, "w", encoding="utf-8") as f:
                f.write(text)
            return
        fig = figure(run, title, meta)
        fig.savefig(path, format=fmt, dpi=100, metadata=_file_meta(fmt, title))
