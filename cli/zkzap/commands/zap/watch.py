"""``zap watch``: poll registers of several actuators, live on a terminal or as snapshot rows."""

from __future__ import annotations

import sys

import click

from ...codec import zap
from ...errors import NO_REPLY, NoReply, UsageError
from .. import CONTEXT, Command
from ..options import (Choice, FiniteRange, IntRange, buses_option, close_output, exits, note, open_output,
                       output_options, protocol_options, unit_options, unit_scales, zap_map)
from .compose import _link_args, link_options, open_link
from .params import REGISTER
from .scan import IdList

FORMATS = ("table", "jsonl", "json", "csv")


@exits({NO_REPLY: "an actuator never answered, or went unanswered for more than half of the watch (a bus that "
                  "died: every row is written first)"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("registers", nargs=-1, required=True, type=REGISTER, metavar="REGISTER...")
@click.option("--ids", "ids", type=IdList(), default="0", show_default=True, metavar="LIST",
              help="Actuators to poll, like 1,2,5-8.")
@click.option("-r", "--rate", type=FiniteRange(0.01, 10000), default=None, metavar="HZ",
              help="Polls per second (default: as fast as the line allows).")
@click.option("-c", "--count", type=IntRange(1, None), default=None, metavar="N", help="Stop after N polls.")
@click.option("-d", "--duration", type=FiniteRange(0, None, min_open=True), default=None, metavar="SECONDS",
              help="Stop after this long.")
@click.option("-u", "--until", "until", multiple=True, metavar="EXPR",
              help="Stop when every actuator meets EXPR, like 'moving==0' (REGISTER OP NUMBER; repeatable: all "
                   "must hold). The register is read too.")
@click.option("-f", "--format", "fmt", type=Choice(FORMATS), default=None,
              help="Record format (default: the live table on a terminal, else by the suffix of -o: .csv, .json, .jsonl; "
                   "jsonl in a pipe).")
@buses_option("Watch the IDs of the fleet file's buses (not --ids)")
@output_options
@unit_options
@link_options(several=True)
@protocol_options
def watch(registers, ids, rate, count, duration, until, fmt, output, append, bus_names, unit, fleet_file, **common):
    """Poll REGISTER... of every actuator listed, as fast as the line allows or at --rate.

    One Load Data per actuator and poll reads the registers as one contiguous block (the IR
    protocol has no sync read; registers far apart are read in separate blocks). Each read
    gives a snapshot row: time (ISO 8601 UTC, when it was read), t (seconds since the start),
    poll, id, one column per register (raw values, units as in 'zap registers'), errors,
    status (ok, no-reply, bad-reply) and rtt_ms. A read that fails after --retries is a row
    with empty values, and the watch goes on. On a terminal: a live table per actuator with units, sparklines, error
    bits in colour and link health, and the achieved poll rate beside the asked one and the
    wire limit. With --unit mm each position register gets a NAME_mm column (and its mm beside
    the counts in the table), by the strokes of --fleet. JSON Lines in a pipe; CSV by -f csv or an -o *.csv name. A summary goes to
    stderr at the end. Exit status 3 when an actuator never answered, or went unanswered for
    more than half of the watch's time (a bus that died mid-run: every row is written, the
    summary says how long each ID was silent, and the error names them).

    \b
    Examples:
      zap watch present-position present-current moving --ids 1-4 -p /dev/ttyUSB0
      zap watch present-position --ids 1,2 --rate 20 --duration 10 -o run.csv -p /dev/ttyUSB0
      zap move 3000 --id 1 -p /dev/ttyUSB0 && zap watch present-position --ids 1 --until moving==0 -p /dev/ttyUSB0
      zap watch --protocol modbus present-position present-current --ids 1,2 -p /dev/ttyUSB0

    With --protocol modbus each actuator is read with Read Holding Registers, one read per run
    of asked registers without a gap in the control table between them.
    """
    from ...api import expr
    from ...api.watch import Watcher, plan_reads, until_fields
    from ...io.term import is_tty

    if count is not None and duration is not None:
        raise UsageError("--count and --duration: give one of them")
    regmap = zap_map()
    modbus = common["protocol"] == "modbus"
    conds = [expr.parse(u, until_fields(regmap.registers if modbus else None), where="--until", allow_warn=False,
                        example="moving==0") for u in until]
    if common["return_mode"] == "0" and not modbus:
        raise UsageError("--return-mode 0: Load Data is never answered in feedback-return-mode 0")
    reads = plan_reads(list(registers) + [regmap.register(c.field.replace("_", "-")) for c in conds],
                       common["baud"], regmap if modbus else None)
    shown = [r for _, _, regs in reads for r in regs]
    from .motion import several_buses

    if several_buses(bus_names):
        return _watch_buses(registers, bus_names, shown, conds, rate, count, duration, fmt, output, append, unit,
                            fleet_file, common, ids)
    from ...api.watch import MM_REGISTERS

    scales = unit_scales(unit, fleet_file, ids)
    mm_cols = [f"{r.name}_mm" for r in shown if r.name in MM_REGISTERS] if scales else []
    if fmt is None and output and output != "-":
        from ...io import format_for_path

        fmt = format_for_path(output, FORMATS)
    stdout_tty = is_tty(sys.stdout)
    live = (fmt in (None, "table") and stdout_tty and not output) or (bool(output) and stdout_tty)
    if fmt == "table" and not stdout_tty:
        raise UsageError("--format table: the live table needs a terminal; use jsonl or csv in a pipe")
    record_fmt = None if live and not output else (fmt if fmt not in (None, "table") else "jsonl")
    columns = ["time", "t", "poll", "id"] + [r.name for r in shown] + mm_cols + ["errors", "status", "rtt_ms"]
    stream, had = (None, False)
    if record_fmt is not None:                  # checked now, opened by the first row
        stream, had = open_output(output, append, fmt=record_fmt, columns=columns)
    with open_link(ids=ids, **_link_args(common)) as bus:
        watcher = Watcher(bus, ids, list(registers), rate=rate, count=count, duration=duration, until=conds,
                          retries=common["retries"], scales=scales)
        writer = None
        if record_fmt is not None:
            from ...io.writers import make_writer

            writer = make_writer(record_fmt, stream, columns, header=not had)
        view = None
        if live:
            from ...io.watch_view import WatchView

            view = WatchView(watcher, asked=rate)
        try:
            if view is not None:
                view.__enter__()
            for row in watcher.rows():
                if writer is not None:
                    writer.write(row)
        finally:
            if view is not None:
                view.__exit__(None, None, None)
            if writer is not None:
                close_output(writer, stream)
            _summary(watcher, rate)
    silent = [i for i, h in watcher.health.items() if h.answered == 0 and not h.garbled]
    garbled = [i for i, h in watcher.health.items() if h.answered == 0 and h.garbled]
    if garbled:
        from ...errors import BadReply

        ids = ", ".join(map(str, garbled))
        raise BadReply(f"ID{'s' if len(garbled) > 1 else ''} {ids} at {watcher.bus.baud} baud: every reply was "
                       "garbled during the watch (a collision: two actuators answering to one ID; or a line fault)"
                       + (f"; no reply at all from ID{'s' if len(silent) > 1 else ''} {', '.join(map(str, silent))}"
                          if silent else ""), ids=garbled, collision=True)
    if silent:
        raise NoReply(f"no reply from ID{'s' if len(silent) > 1 else ''} {', '.join(map(str, silent))} "
                      f"at {watcher.bus.baud} baud during the watch")
    _mostly_silent(watcher)


def _mostly_silent(w, bus_name=None):
    """NoReply (exit 3) naming every ID that went unanswered for most of the watch."""
    dead = w.mostly_silent()
    if dead:
        where = f"bus {bus_name}: " if bus_name else ""
        said = "; ".join(f"ID {i} unanswered for {s:.1f} of {w.elapsed:.1f} s ({w.health[i].answered} of "
                         f"{w.health[i].asked} reads answered)" for i, s in dead.items())
        raise NoReply(f"{where}{said}: the bus was silent for most of the watch", ids=sorted(dead),
                      silent_s={i: round(s, 3) for i, s in dead.items()})


def _summary(w, rate):
    if w.started is None:
        return
    try:
        limit = f"{w.limit():.1f}"
    except ZeroDivisionError:
        limit = "?"
    asked = f"asked {rate:g}" if rate else "asked: as fast as possible"
    health = "; ".join(f"ID {i} {h.answered}/{h.asked}" + (f" ({', '.join(sorted(h.errors))})" if h.errors else "")
                       + (f", silent {h.silent_s:.1f} s" if h.silent_s >= 0.05 else "") for i, h in w.health.items())
    why = {"until": ", condition met", "count": "", "duration": ""}.get(w.stopped_by, "")
    note(f"{w.polls} polls in {w.elapsed:.2f} s: {w.achieved:.1f} polls/s ({asked}; wire limit {limit}/s){why}; "
         f"reads answered: {health}")


def _watch_buses(registers, bus_names, shown, conds, rate, count, duration, fmt, output, append, unit, fleet_file,
                 common, ids=()):
    """zap watch --buses: one watcher a bus, each on its own thread; rows name their bus."""
    from ...api import buses
    from ...api.watch import Watcher
    from ..options import output_format
    from .motion import bus_specs, open_spec

    if fmt == "table":
        raise UsageError("--format table: with several buses the rows are written as jsonl, json or csv")
    specs = bus_specs(bus_names, fleet_file, common, unit, ids)
    record_fmt = output_format(fmt, output, ("jsonl", "json", "csv"))
    if record_fmt == "table":
        record_fmt = "jsonl"
    columns = ["bus", "time", "t", "poll", "id"] + [r.name for r in shown] + ["errors", "status", "rtt_ms"]
    stream, had = open_output(output, append, fmt=record_fmt, columns=columns)
    watchers = {}

    def work(link, spec, emit, cancel):
        w = watchers[spec.name] = Watcher(link, spec.ids, list(registers), rate=rate, count=count, duration=duration,
                                          until=conds, retries=common["retries"])
        for row in w.rows():
            if cancel.is_set():
                break
            emit(row)

    from ...io.writers import make_writer

    writer = make_writer(record_fmt, stream, columns, header=not had)
    try:
        for row in buses.run(specs, work, open_bus=open_spec(common)):
            writer.write(row)
    finally:
        close_output(writer, stream)
        for spec in specs:
            w = watchers.get(spec.name)
            if w is not None and w.started is not None:
                health = "; ".join(f"ID {i} {h.answered}/{h.asked}" for i, h in w.health.items())
                note(f"bus {spec.name}: {w.polls} polls in {w.elapsed:.2f} s: {w.achieved:.1f} polls/s (wire limit "
                     f"{w.limit():.1f}/s); reads answered: {health}")
    silent = [f"{s.name} ID {i}" for s in specs for i, h in (watchers[s.name].health.items() if s.name in watchers
                                                              else ()) if h.answered == 0]
    if silent:
        raise NoReply(f"no reply during the watch from {', '.join(silent)}")
    for spec in specs:
        if spec.name in watchers:
            _mostly_silent(watchers[spec.name], spec.name)
