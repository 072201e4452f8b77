"""``zk logbook FILE``: the runs recorded with ``--logbook FILE``, the engine's totals, one engine's
book (``--engine NAME``: hours, starts, fuel, hours above a throttle, totals since a service) and
services (``--service NAME``)."""

from __future__ import annotations

import click

from ...errors import OK, OUTPUT_ERROR, USAGE, UsageError
from ...io.term import fill
from .. import CONTEXT, Command
from ..options import FiniteRange, InputPath, IntRange, exits, format_option

#: The terminal table: (key, heading, priority). A narrow terminal leaves out the lowest first
#: (named under the table): the command, the session's duration, fuel, EGT, rpm, starts.
TABLE = [("id", "run"), ("started", "started UTC"), ("engine", "engine"), ("duration_s", "time s", -5),
         ("running_s", "running s"), ("starts", "starts", -1), ("max_rpm", "max rpm", -2), ("max_egt_c", "EGT °C", -3),
         ("fuel_used_l", "fuel L", -4), ("command", "command", -6), ("outcome", "outcome")]
#: Throttle (%) above which an engine's running hours are given by default.
DEFAULT_ABOVE = (80.0,)


@exits({OK: "listed (or the service recorded)", USAGE: "FILE is missing or not a logbook, or bad usage",
        OUTPUT_ERROR: "the service could not be written"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("logbook_file", metavar="FILE", type=InputPath("logbook"))
@format_option()
@click.option("--totals", "only_totals", is_flag=True, help="Only the totals (running hours, starts, fuel).")
@click.option("--last", type=IntRange(1), default=None, metavar="N", help="Only the last N runs.")
@click.option("--engine", default=None, metavar="NAME",
              help="One engine's book: its runs (recorded with --engine NAME), run and running hours, starts, "
                   "fuel, hours above --above, and the totals since its last service.")
@click.option("--above", "above", multiple=True, type=FiniteRange(0, 101), metavar="PCT",
              help="With --engine: running hours at or above this throttle, % (default 80; 1 % resolution). "
                   "Repeatable.")
@click.option("--service", default=None, metavar="NAME",
              help="Record a service of engine NAME now (the totals since a service start again).")
@click.option("--note", default=None, metavar="TEXT", help="With --service: what was done.")
def logbook(logbook_file, fmt, only_totals, last, engine, above, service, note):
    """List the runs in an engine logbook, with totals.

    FILE is the SQLite database that '--logbook FILE' on 'zk send --for', 'zk profile' and
    'zk monitor' append a run to: start and end time, duration, engine-running time, starts
    (entries into a running state), max rpm and EGT, fuel used, ECU errors, limits violated,
    the command, schedule and files, and the engine (--engine NAME on the session). On a
    terminal a table and the totals line; -f json gives one document {"runs": [...],
    "totals": {...}}; jsonl/csv a row per run (--totals: the totals alone).

    --engine NAME gives that engine's book: run hours, running hours, starts, fuel, hours at or
    above a throttle (--above PCT) and the same since its last service; --service NAME records
    a service (now, UTC) so that the totals since the service start again.

    \b
    Examples:
      zk logbook engine.db
      zk logbook engine.db --totals -f json | jq .running_hours
      zk logbook engine.db -f csv > runs.csv
      zk logbook engine.db --engine K100-1234 --above 80 --above 95
      zk logbook engine.db --service K100-1234 --note 'bearings, 25 h inspection'
    """
    import sys

    from ...api import logbook as lb
    from ..options import resolve_format, write_rows

    if service is not None:
        if engine or above or only_totals or last:
            raise UsageError("service: records a service; give no --engine, --above, --totals or --last with it")
        if not service.strip():
            raise UsageError("service: an empty engine name")
        lb.runs(logbook_file)                         # a missing file or no logbook: exit 2, nothing created
        svc = lb.record_service(logbook_file, service.strip(), note)
        click.echo(f"logbook {logbook_file}: service {svc['id']} of {svc['engine']} recorded at {svc['at']}", err=True)
        return
    if note is not None:
        raise UsageError("note: applies with --service NAME")
    if above and engine is None:
        raise UsageError("above: applies with --engine NAME")
    fmt = resolve_format(fmt, sys.stdout)
    if engine is not None:
        return _engine(logbook_file, engine, tuple(above) or DEFAULT_ABOVE, fmt, only_totals, last)
    recs = lb.runs(logbook_file)
    totals = lb.totals(recs)
    if last:
        recs = recs[-last:]
    if fmt == "json":
        import json

        doc = totals if only_totals else {"runs": recs, "totals": totals}
        click.echo(json.dumps(doc, ensure_ascii=False, indent=2))
        return
    if only_totals:
        if fmt == "table":
            _figures([totals], ["value"], f"logbook {logbook_file}: totals")
        else:
            write_rows([totals], list(totals), fmt)
        return
    _runs(recs, fmt, f"logbook {logbook_file}: {len(recs)} runs")
    if fmt == "table":
        click.echo(fill("totals: " + _totals_text(totals), sys.stderr), err=True)


def _runs(recs, fmt, title):
    from ...api import logbook as lb
    from ..options import write_rows

    if fmt == "table":
        rows = [dict(r, errors=", ".join(r["errors"]), limits_violated=", ".join(r["limits_violated"]),
                     started=r["started"].replace("T", " ").rstrip("Z"), duration_s=round(r["duration_s"]),
                     running_s=round(r["running_s"]),
                     fuel_used_l=None if r["fuel_used_l"] is None else round(r["fuel_used_l"], 3), command=r["command"].replace("zk ", ""),
                     outcome=r["outcome"] + (" !" if r["errors"] or r["limits_violated"] else ""),
                     engine=r.get("engine") or "-")
                for r in recs]
        write_rows(rows, list(lb.COLUMNS), "table", title=title, table_columns=TABLE)
        return
    write_rows([dict(r, throttle_s=";".join(f"{k}={v:g}" for k, v in sorted(r["throttle_s"].items(),
                                                                              key=lambda kv: int(kv[0]))))
                if fmt == "csv" else r for r in recs], list(lb.COLUMNS), fmt)


def _figures(rows, headings, title):
    """Totals on a terminal: a row per figure, a column per set of totals (``headings``), so that
    they fit a narrow terminal whole."""
    from ..options import write_rows

    table = [{"figure": k, **{str(j): r.get(k) for j, r in enumerate(rows)}} for k in rows[0]]
    write_rows(table, ["figure", *map(str, range(len(rows)))], "table", title=title,
               table_columns=[("figure", "figure")] + [(str(j), h) for j, h in enumerate(headings)])


def _totals_text(t) -> str:
    text = (f"{t['runs']} runs, {t['run_hours']:.3f} run hours, {t['running_hours']:.3f} running hours "
            f"({t['running_s']:g} s), {t['starts']} starts, {t['fuel_used_l']:g} L fuel, "
            f"max rpm {t['max_rpm'] if t['max_rpm'] is not None else '-'}, "
            f"max EGT {t['max_egt_c'] if t['max_egt_c'] is not None else '-'} °C")
    for pct, h in (t.get("hours_above") or {}).items():
        text += f", {h:.3f} h at or above {pct} % throttle"
    if t.get("simulated_runs"):
        n = t["simulated_runs"]
        text += f"; {n} run{'' if n == 1 else 's'} on a simulator not counted"
    return text


def _engine(path, engine, above, fmt, only_totals, last):
    import json
    import sys

    from ...api import logbook as lb
    from ..options import write_rows

    doc = lb.engine_report(path, engine, above)
    if not doc["runs"] and not doc["services"]:
        known = sorted({r.get("engine") for r in lb.runs(path) if r.get("engine")})
        raise UsageError(f"engine: no run of {engine!r} in {path}"
                         + (f"; engines there: {', '.join(known)}" if known else
                            " (runs name their engine with --engine NAME on the session)"))
    if last:
        doc["runs"] = doc["runs"][-last:]
    if fmt == "json":
        if only_totals:
            doc = {k: doc[k] for k in ("engine", "totals", "last_service", "since_service")}
        click.echo(json.dumps(doc, ensure_ascii=False, indent=2))
        return
    svc = doc["last_service"]
    rows = [dict(doc["totals"], engine=engine, period="all runs"),
            dict(doc["since_service"], engine=engine,
                 period=f"since the service of {svc['at']}" if svc else "since the service (none recorded)")]
    for r in rows:
        for pct, h in (r.pop("hours_above", None) or {}).items():
            r[f"hours_above_{pct}"] = h
    if only_totals and fmt == "table":
        _figures([{k: v for k, v in r.items() if k not in ("engine", "period")} for r in rows],
                 [r["period"] for r in rows], f"engine {engine}: totals")
        return
    if only_totals or fmt != "table":
        write_rows(rows, list(rows[0]), fmt)
        return
    _runs(doc["runs"], fmt, f"engine {engine}: {len(doc['runs'])} runs")
    click.echo(fill(f"engine {engine}: " + _totals_text(doc["totals"]), sys.stderr), err=True)
    where = f"since the service of {svc['at']}" + (f" ({svc['note']})" if svc and svc.get("note") else "") \
        if svc else "no service recorded"
    click.echo(fill(f"  {where}: " + _totals_text(doc["since_service"]), sys.stderr), err=True)
