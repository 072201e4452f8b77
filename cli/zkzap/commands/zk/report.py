"""``zk report``: a run's telemetry as a report with plots (PNG, SVG, PDF, HTML) or in the terminal."""

from __future__ import annotations

import os

import click

from ...errors import OutputError, UsageError
from .. import CONTEXT, Command
from ..options import FilePath, note

EPILOG = ("Exit status: 0 written; 2 bad usage, an unreadable input, or matplotlib missing (pip install "
          "'zkzap[plot]'); 7 the report could not be written.")


@click.command(cls=Command, context_settings=CONTEXT, epilog=EPILOG)
@click.argument("run_file", metavar="RUN", type=FilePath())
@click.option("--steps", "steps_file", type=FilePath(), default=None, metavar="STEPS.csv",
              help="The per-step averages of 'zk profile --steps-csv': target lines, thrust and EGT vs rpm, "
                   "TSFC vs thrust.")
@click.option("--summary", "summary_file", type=FilePath(), default=None, metavar="SUMMARY.json",
              help="The summary of 'zk profile --summary-json': the header table and limit events.")
@click.option("-o", "--output", type=FilePath(), default=None, metavar="REPORT",
              help="Write REPORT.png, .svg, .pdf or .html (one self-contained file).")
@click.option("--format", "fmt", type=click.Choice(["png", "svg", "pdf", "html"]), default=None,
              help="The report's format (default: from the -o name).")
@click.option("--title", default=None, help="Heading of the report (default: 'Run report: RUN').")
@click.option("--meta", multiple=True, metavar="KEY=VALUE",
              help="A line of run metadata in the header (engine=K-100 serial=1234 ...). Repeatable.")
@click.option("--terminal", is_flag=True, help="Draw the time histories in the terminal instead (no matplotlib "
                                               "needed).")
def report(run_file, steps_file, summary_file, output, fmt, title, meta, terminal):
    """Render a run's telemetry as a report with plots.

    RUN is what 'zk monitor', 'zk send --for' or 'zk profile' wrote (CSV snapshot rows, JSON
    Lines or JSON), a --raw-log or a --capture pcapng file (decoded on the fly; a capture's own
    receive times are its time axis). The report has time histories on
    a shared time axis — rpm (and the target), EGT, thrust, throttle (and the target), fuel flow,
    voltages — with the engine states shaded and limit violations marked in red; with --steps,
    thrust vs rpm, EGT vs rpm and TSFC vs thrust; and a header with --title, --meta and the
    --summary table. Plots without data are skipped and named on stderr.

    Needs matplotlib (pip install 'zkzap[plot]'), except --terminal.

    \b
    Examples:
      zk profile run.csv --sim -o tel.csv --steps-csv steps.csv --summary-json sum.json
      zk report tel.csv --steps steps.csv --summary sum.json -o report.html --meta engine=K-100
      zk report run.bin -o run.png
      zk report tel.csv --terminal
    """
    from ...io import report as R

    pairs = []
    for m in meta:
        k, sep, v = m.partition("=")
        if not sep or not k.strip():
            raise UsageError(f"meta: {m!r} is not KEY=VALUE")
        pairs.append((k.strip(), v.strip()))
    if terminal:
        if output or fmt:
            raise UsageError(f"{'output' if output else 'format'}: not with --terminal (it draws on the terminal)")
    else:
        if not output:
            raise UsageError("output: give -o REPORT.png|svg|pdf|html, or --terminal")
        if output == "-":
            raise UsageError("output: a file name is needed (its extension names the format)")
        fmt = R.output_format(output, fmt)
        d = os.path.dirname(os.path.abspath(output))
        if not os.path.isdir(d):
            raise UsageError(f"output: cannot write {output}: no such directory")
        if os.path.exists(output):
            for path in (run_file, steps_file, summary_file):
                if path and os.path.exists(path) and os.path.samefile(path, output):
                    raise UsageError(f"output: {output} is also an input")
        R._mpl()                                      # refuse early (exit 2) without matplotlib
    steps = R.load_steps(steps_file) if steps_file else None
    summary = R.load_summary(summary_file) if summary_file else None
    run = R.load_run(run_file)
    for text in run.notes:
        note(text)
    title = title or f"Run report: {os.path.basename(run_file)}"
    if terminal:
        import sys

        from ...io.term import console_for

        skipped = R.terminal(run, console_for(sys.stdout), steps)
    else:
        tmp = output + ".tmp"
        try:
            skipped = R.render(tmp, fmt, run, steps, summary, title, pairs)
            os.replace(tmp, output)
        except OSError as e:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise OutputError(f"output: cannot write {output}: {e.strerror or e}") from None
    for s in skipped:
        note(f"skipped {s}")
