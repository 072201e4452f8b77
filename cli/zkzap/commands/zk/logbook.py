"""``zk logbook FILE``: the runs recorded with ``--logbook FILE``, and the engine's totals."""

from __future__ import annotations

import click

from ...errors import OK, USAGE
from .. import CONTEXT, Command
from ..options import FilePath, IntRange, exits, format_option

TABLE = [("id", "run"), ("started", "started UTC"), ("duration_s", "s"), ("running_s", "run s"),
         ("starts", "starts"), ("max_rpm", "max rpm"), ("max_egt_c", "EGT °C"), ("fuel_used_l", "fuel L"),
         ("command", "command"), ("outcome", "outcome")]


@exits({OK: "listed", USAGE: "FILE is missing or not a logbook"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("logbook_file", metavar="FILE", type=FilePath())
@format_option()
@click.option("--totals", "only_totals", is_flag=True, help="Only the totals (running hours, starts, fuel).")
@click.option("--last", type=IntRange(1), default=None, metavar="N", help="Only the last N runs.")
def logbook(logbook_file, fmt, only_totals, last):
    """List the runs in an engine logbook, with totals.

    FILE is the SQLite database that '--logbook FILE' on 'zk send --for', 'zk profile' and
    'zk monitor' append a run to: start and end time, duration, engine-running time, starts
    (entries into a running state), max rpm and EGT, fuel used, ECU errors, limits violated,
    the command, schedule and files. On a terminal a table and the totals line; -f json gives
    one document {"runs": [...], "totals": {...}}; jsonl/csv a row per run (--totals: the
    totals alone).

    \b
    Examples:
      zk logbook engine.db
      zk logbook engine.db --totals -f json | jq .running_hours
      zk logbook engine.db -f csv > runs.csv
    """
    import sys

    from ...api import logbook as lb
    from ..options import resolve_format, write_rows

    recs = lb.runs(logbook_file)
    totals = lb.totals(recs)
    if last:
        recs = recs[-last:]
    fmt = resolve_format(fmt, sys.stdout)
    if fmt == "json":
        import json

        doc = totals if only_totals else {"runs": recs, "totals": totals}
        click.echo(json.dumps(doc, ensure_ascii=False, indent=2))
        return
    if only_totals:
        write_rows([totals], list(totals), fmt)
        return
    if fmt == "table":
        rows = [dict(r, errors=", ".join(r["errors"]), limits_violated=", ".join(r["limits_violated"]),
                     started=r["started"].replace("T", " ").rstrip("Z"), duration_s=round(r["duration_s"]),
                     running_s=round(r["running_s"]), command=r["command"].replace("zk ", ""),
                     outcome=r["outcome"] + (" !" if r["errors"] or r["limits_violated"] else ""))
                for r in recs]
        write_rows(rows, list(lb.COLUMNS), "table", title=f"logbook {logbook_file}: {len(recs)} runs",
                   table_columns=TABLE)
        click.echo(f"totals: {totals['runs']} runs, {totals['running_hours']:.3f} running hours "
                   f"({totals['running_s']:g} s), {totals['starts']} starts, {totals['fuel_used_l']:g} L fuel, "
                   f"max rpm {totals['max_rpm'] if totals['max_rpm'] is not None else '-'}, "
                   f"max EGT {totals['max_egt_c'] if totals['max_egt_c'] is not None else '-'} °C", err=True)
        return
    write_rows(recs, list(lb.COLUMNS), fmt)
