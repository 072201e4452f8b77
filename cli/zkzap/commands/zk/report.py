"""``zk report``: one run's telemetry, or several runs compared, as a report with plots (PNG, SVG,
PDF, HTML) or in the terminal."""

from __future__ import annotations

import os
import re

import click

from ...errors import OK, OUTPUT_ERROR, USAGE, UsageError
from .. import CONTEXT, Command
from ..options import Choice, InputPath, OutputPath, exits, note

#: What a report is written as (named by the suffix of -o, or --format).
REPORT_FORMATS = ("png", "svg", "pdf", "html")


class AlignType(click.ParamType):
    name = "align"

    def convert(self, value, param, ctx):
        text = str(value).strip().lower()
        if text in ("start", "first", "running") or re.fullmatch(r"step:[1-9]\d*", text):
            return text
        self.fail(f"{value!r}; allowed start, first, running or step:N (N a step number, 1 or more)", param, ctx)


@exits({OK: "written", USAGE: "bad usage, an unreadable input, or matplotlib missing (pip install 'zkzap[plot]'; "
                            "plotly for --interactive: pip install 'zkzap[interactive]')",
        OUTPUT_ERROR: "the report could not be written"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("run_files", metavar="RUN...", nargs=-1, required=True, type=InputPath("run", label="RUN"))
@click.option("--steps", "steps_files", multiple=True, type=InputPath("steps"), metavar="STEPS.csv",
              help="The per-step averages of 'zk profile --steps-csv': target lines, the step windows, thrust and "
                   "EGT vs rpm, TSFC vs thrust. One per RUN, in order (a --summary with steps serves too).")
@click.option("--summary", "summary_files", multiple=True, type=InputPath("summary"), metavar="SUMMARY.json",
              help="The summary of 'zk profile --summary-json' (or --summary-json of monitor, send): the header "
                   "table, the limits and their events, the steps. One per RUN, in order.")
@click.option("--limit", "limit", multiple=True, metavar="EXPR",
              help="Draw this limit (FIELD OP NUMBER[,warn=N], as on the sessions) as a labelled line, its "
                   "warning level dashed. Repeatable; the limits of a --summary are drawn too.")
@click.option("--limits", "limits_files", multiple=True, type=InputPath("limits"), metavar="FILE",
              help="Draw the limits of FILE (one EXPR per line). Repeatable.")
@click.option("--label", "labels", multiple=True, metavar="NAME",
              help="The name of a RUN in the legend, in order (default: its file name). Repeatable.")
@click.option("--align", type=AlignType(), default="start", show_default=True,
              help="The common time axis: start (each run from its session's start, t = 0, where its schedule "
                   "started), first (from its first record), running (from the engine's first running state) "
                   "or step:N (from the start of step N of each run).")
@click.option("-o", "--output", type=OutputPath("document", formats=REPORT_FORMATS, default=None), default=None,
              metavar="REPORT",
              help="Write REPORT.png, .svg, .pdf or .html (one self-contained file).")
@click.option("--format", "fmt", type=Choice(REPORT_FORMATS), default=None,
              help="The report's format (default: from the -o name).")
@click.option("--title", default=None, help="Heading of the report (default: 'Run report: RUN').")
@click.option("--meta", multiple=True, metavar="KEY=VALUE",
              help="A line of run metadata in the header (engine=K-100 serial=1234 ...). Repeatable.")
@click.option("--terminal", is_flag=True, help="Draw the time histories in the terminal instead (no matplotlib "
                                               "needed).")
@click.option("--interactive", is_flag=True,
              help="With -o REPORT.html: interactive plots (zoom and pan on one time axis, every line's value at "
                   "the cursor) through plotly, an optional extra: pip install 'zkzap[interactive]'. One "
                   "self-contained file (plotly.js inlined, about 5 MB).")
def report(run_files, steps_files, summary_files, limit, limits_files, labels, align, output, fmt, title, meta,
           terminal, interactive):
    """Render a run's telemetry as a report with plots, or compare several runs.

    RUN is what 'zk monitor', 'zk send --for' or 'zk profile' wrote (CSV snapshot rows, JSON
    Lines or JSON), a --raw-log or a --capture pcapng file (decoded on the fly; a capture's own
    receive times are its time axis), or '-' for standard input. The report has time histories
    on a shared time axis — rpm (and the target), EGT, thrust, throttle (and the target), fuel
    flow, voltages — with the engine states shaded, each step's settle time hatched and its
    averaging window shaded and numbered, limits and warning levels as labelled lines and
    violations marked in red; with steps, thrust vs rpm, EGT vs rpm and TSFC vs thrust; and a
    header with --title, --meta and the --summary table. Plots without data are skipped and
    named on stderr.

    Several RUNs are compared: their time histories overlaid on one time axis (--align), a
    legend naming each run (--label), the steady-state curves of each, and their steps side by
    side with the differences from the first run.

    Needs matplotlib (pip install 'zkzap[plot]'), except --terminal; --interactive writes an
    HTML page of plotly figures instead (zoom, pan, a readout at the cursor; pip install
    'zkzap[interactive]').

    \b
    Examples:
      zk profile run.csv --sim -o tel.csv --steps-csv steps.csv --summary-json sum.json
      zk report tel.csv --steps steps.csv --summary sum.json -o report.html --meta engine=K-100
      zk report before.csv after.csv --summary before.json --summary after.json --align step:1 -o cmp.png
      zk report tel.csv --limits engine.limits -o run.pdf
      zk report tel.csv --steps steps.csv -o run.html --interactive
      zk report run.bin -o run.png
      zk monitor --sim --duration 20 | zk report - --terminal
    """
    from ...api import limits as L
    from ...io import report as R

    pairs = []
    for m in meta:
        k, sep, v = m.partition("=")
        if not sep or not k.strip():
            raise UsageError(f"meta: {m!r} is not KEY=VALUE")
        pairs.append((k.strip(), v.strip()))
    n = len(run_files)
    for what, given in (("steps", steps_files), ("summary", summary_files), ("label", labels)):
        if given and len(given) != n:
            raise UsageError(f"{what}: {len(given)} given for {n} run{'s' if n > 1 else ''}; give one per RUN, "
                             f"in the order of the RUNs")
    if list(run_files).count("-") > 1:
        raise UsageError("run: '-' given twice; standard input is one run")
    conditions = L.read_limits(limit, limits_files)
    # a rate limit (FIELD/s) is no level of its field: no line on the field's plot
    limits = [(c.text, c.field, c.op, c.threshold, c.warn) for c in conditions if not c.rate]
    if terminal:
        if output or fmt or interactive:
            raise UsageError(f"{'output' if output else 'format' if fmt else 'interactive'}: not with --terminal "
                             "(it draws on the terminal)")
    else:
        if not output:
            raise UsageError("output: give -o REPORT.png|svg|pdf|html, or --terminal")
        if output == "-":
            raise UsageError("output: a file name is needed (its extension names the format)")
        fmt = R.output_format(output, fmt)
        from ...outfile import check_path

        check_path(output, "output")                  # its inputs: the options' own check
        if interactive:
            if fmt != "html":
                raise UsageError(f"interactive: an HTML report (-o REPORT.html); {output} names {fmt}")
            from ...io.report_interactive import require

            require()                                 # refuse early (exit 2) without plotly
        else:
            R._mpl()                                  # refuse early (exit 2) without matplotlib
    steps = [R.load_steps(p) for p in steps_files] or [None] * n
    summaries = [R.load_summary(p) for p in summary_files] or [None] * n
    fields = {x[1] for x in limits} | {x[1] for s in summaries for x in R.summary_limits(s)}
    runs = []
    for path, st, sm in zip(run_files, steps, summaries):
        run = R.load_run(path, extra=sorted(fields))
        for text in run.notes:
            note(text)
        run.steps = st if st is not None else ((sm or {}).get("steps") or None)
        run.summary = sm
        runs.append(run)
    for run, name in zip(runs, labels or R.labels_for([r.name for r in runs])):
        run.label = name
    R.align(runs, align)
    runs[0].aligned = align
    title = title or (f"Run report: {os.path.basename(run_files[0])}" if n == 1 else
                      "Runs compared: " + ", ".join(r.label for r in runs))
    if terminal:
        import sys

        from ...io.term import console_for

        skipped = R.terminal(runs, console_for(sys.stdout))
    else:
        from ...outfile import replacing

        with replacing(output, suffix=os.path.splitext(output)[1]) as tmp:
            skipped = R.render(tmp, fmt, runs, limits, title, pairs, interactive=interactive)
    for s in skipped:
        note(f"skipped {s}")
