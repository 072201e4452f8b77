"""Motion commands: ``zap play`` (a timed path), ``zap teach`` (record waypoints) and ``zap
calibrate`` (teach the two ends of the stroke).

Thin: options -> :mod:`zkzap.api.motion` / :mod:`zkzap.api.units` -> writers.
"""

from __future__ import annotations

import sys

import click

from ...errors import CHECK_FAILED, DEVICE_ERROR, NO_REPLY, CheckFailed, UsageError
from .. import CONTEXT, Command
from ..options import (Choice, FiniteRange, InputPath, IntRange, OutputPath, buses_option, close_output,
                       dry_run_option, exits, note, open_output, output_format, output_options, ports_given,
                       protocol_options, unit_options, unit_scales, warn)
from .compose import _link_args, check_sim_args, link_options, open_link
from .scan import IdList, _progress

ROW_FORMATS = ("table", "jsonl", "json", "csv")
PATH_FORMATS = ("csv", "jsonl", "json")


def _wire(common):
    """The motion wire (:mod:`zkzap.api.motion_wire`) of the command's --protocol and --map."""
    from ...api.motion_wire import wire_for
    from ..options import zap_map

    return wire_for(common.get("protocol") or "ir", zap_map())


def _plan_lines(plan, fmt):
    """-n: the plan's steps and their frames on stdout."""
    from ...io.writers import make_writer

    if fmt in ("json", "jsonl"):
        writer = make_writer(fmt, sys.stdout, ["t", "goals", "speeds", "currents", "frames"])
        for step in plan.steps:
            writer.write(step.record())
        writer.close()
        return
    out = sys.stdout
    for step in plan.steps:
        for frame in step.frames:
            out.write(f"{step.t:9.3f}  {plan.protocol.describe(frame)}  {frame.hex(' ').upper()}\n")
    out.flush()


def _summary(player, seconds, prefix=""):
    s = player.summary()
    late = (f"lateness p50 {s['lateness_p50_ms']:.2f} ms, p99 {s['lateness_p99_ms']:.2f} ms, "
            f"max {s['lateness_max_ms']:.2f} ms" if s["lateness_max_ms"] is not None else "no step sent")
    reads = f"{s['reads']} log reads" + (f" ({s['read_failures']} unanswered)" if s["read_failures"] else "")
    note(f"{prefix}{s['steps']} of {player.total} steps in {seconds:.2f} s; {late}; {reads}")


def _raise_stopped(stopped):
    from ...api.motion import describe_stop
    from ...errors import DeviceError

    where = describe_stop(stopped.positions, stopped.mode)
    warn(f"stopped every actuator ({stopped.message}): {where}")
    if stopped.reason == "interrupted":
        return
    raise_stop(stopped)


def raise_stop(stopped):
    """The exit of a play (or a bus of it) that stopped for ``stopped.reason``."""
    from ...errors import DeviceError, NoReply

    if stopped.reason == "device-error":
        raise DeviceError(f"stopped: {stopped.message}")
    if stopped.reason == "no-reply":
        raise NoReply(f"stopped: {stopped.message}")
    raise CheckFailed(f"stopped: {stopped.message}")


@exits({DEVICE_ERROR: "an actuator reported error bits (or, on Modbus RTU, an exception reply): every actuator was "
                      "stopped",
        CHECK_FAILED: "a current over --limit: every actuator was stopped",
        NO_REPLY: "no log read was answered: the goals went out unconfirmed (on Modbus RTU: a goal's write was "
                  "unanswered, every actuator was stopped)"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("path", metavar="FILE", type=InputPath("zap path", label="FILE"))
@click.option("--interpolate", type=Choice(["linear"]), default=None,
              help="Send intermediate goals between the rows, linearly, at --rate.")
@click.option("-r", "--rate", type=FiniteRange(0.1, 2000), default=None, metavar="HZ",
              help="With --interpolate: goals per second (default 50, or what the line carries when less); a "
                   "rate the line cannot carry is refused.")
@click.option("--loop", "loops", type=IntRange(1, 1000000), default=1, show_default=True, metavar="N",
              help="Play the path N times.")
@click.option("--limit", type=FiniteRange(1, 1600), default=None, metavar="MA",
              help="Stop every actuator when one draws more than this current (mA).")
@click.option("--stop", "stop_mode", type=Choice(["hold", "off"]), default="hold", show_default=True,
              help="How to stop on Ctrl-C, an error or --limit: hold (goal = present position) or off (force off).")
@click.option("--no-log", is_flag=True, help="Read nothing between the steps (no log rows, no --limit check).")
@click.option("-f", "--format", "fmt", type=Choice(ROW_FORMATS), default=None,
              help="Log format (default: by the suffix of -o; JSON Lines in a pipe; none on a terminal). With "
                   "-n: text lines, or the steps as json/jsonl.")
@buses_option("Play (a row may name its bus: a bus column)")
@output_options(formats=("jsonl", "json", "csv"))
@unit_options
@dry_run_option
@link_options(several=True)
@protocol_options
def play(path, interpolate, rate, loops, limit, stop_mode, no_log, bus_names, fmt, output, append, unit, fleet_file,
         dry_run, **common):
    """Play a timed path: FILE rows of t (seconds), id (one, or several like "1,2"),
    position, and optionally speed and current.

    FILE is CSV with a header, a JSON array of objects or JSON Lines ('-': stdin). Rows at one
    time are one step: its goals go out as one sync move (Symmetric Store, broadcast), after
    the step's goal-current and goal-speed; with --protocol modbus one Write Multiple Registers
    per actuator (goal-speed and goal-current together, then goal-position), each answered and
    counted with its reply on the line. Every row is checked before anything moves, and
    the line must carry the plan: steps closer than their frames take on the wire, or an
    --interpolate --rate above 80% of what the line carries, are refused (exit 2) and the
    command says the rate it can carry. -n prints the plan and its frames and sends nothing.

    Between the steps the actuators are read one at a time (only where the read ends before
    the next step is due): log rows with t, loop, id, goal, present, tracking_error (present -
    goal), current_ma, voltage_v, errors, status (with --unit mm: goal_mm, present_mm,
    tracking_error_mm beside the counts; on Modbus RTU voltage_raw, the 17Lf's map giving
    present-voltage no unit, and errors from hardware-error). Ctrl-C, an error bit in a reply (exit 5) or a
    current over --limit (exit 1) stops every actuator (--stop hold: goal = present position;
    off: force off) and says where. A summary on stderr gives the steps' lateness.

    \b
    Examples:
      zap play path.csv -n                                 # the plan and its frames
      zap play path.csv -p /dev/ttyUSB0 -o run.csv
      zap play path.csv --interpolate linear --rate 50 --loop 10 --limit 900 -p /dev/ttyUSB0
      zap play path.json --unit mm --fleet fleet.json -p /dev/ttyUSB0 -f jsonl | jq .tracking_error_mm
    """
    from ...api import motion

    if rate is not None and interpolate is None:
        raise UsageError("--rate: applies only with --interpolate linear")
    import io

    text = sys.stdin.read() if path == "-" else None
    wire = _wire(common)
    scales = unit_scales(unit, fleet_file, _path_ids(path, text, wire) if unit == "mm" else [])
    rows = motion.read_path(io.StringIO(text) if text is not None else path, unit=unit, scales=scales,
                            name="stdin" if path == "-" else path, protocol=wire)
    if several_buses(bus_names):
        return _play_buses(path, rows, bus_names, fleet_file, unit, interpolate, rate, loops, limit, stop_mode, no_log,
                           fmt, output, append, dry_run, common, wire)
    p = motion.plan(rows, baud=common["baud"], stop_bits=common["stop_bits"], interpolate=interpolate, rate=rate,
                    protocol=wire)
    if dry_run:
        check_sim_args(common["port"], common["sim"], common["sim_ids"])
        note(f"{p.note}; {len(p.steps)} steps, {p.frames} frames, {p.duration:g} s"
             + (f" x {loops}" if loops > 1 else ""))
        _plan_lines(p, fmt)
        return
    if common["return_mode"] == "0" and not no_log:
        raise UsageError("--return-mode 0: the log reads are never answered; give --no-log")
    from ...io.term import is_tty

    record_fmt = None
    if not no_log:
        if output or fmt not in (None, "table"):
            record_fmt = output_format(fmt if fmt != "table" else None, output, ("jsonl", "json", "csv"))
        elif not is_tty(sys.stdout):
            record_fmt = "jsonl"
        if fmt == "table":
            raise UsageError("--format table: the log is written as jsonl, json or csv")
    columns = list(motion.LOG_COLUMNS) + list(wire.log_columns) + (motion.MM_COLUMNS if scales else [])
    stream, had = (None, False)
    if record_fmt is not None:
        stream, had = open_output(output, append, fmt=record_fmt, columns=columns)
    note(p.note)
    import time

    writer = None
    with open_link(ids=p.ids, **_link_args(common)) as bus:
        progress = _progress(len(p.steps) * loops, f"playing {path}")

        def on_progress(done, total):
            if progress is not None:
                progress.update(0, completed=done)

        player = motion.Player(bus, p, loops=loops, log=not no_log, limit=limit, stop_mode=stop_mode,
                               scales=scales, on_progress=on_progress)
        if record_fmt is not None:
            from ...io.writers import make_writer

            writer = make_writer(record_fmt, stream, columns, header=not had)
        started = time.monotonic()
        try:
            for row in player.rows():
                if writer is not None:
                    writer.write(row)
        except KeyboardInterrupt:
            player.stop()                  # interrupted while a row was written: the rods too
            raise
        finally:
            if progress is not None:
                progress.stop()
            if writer is not None:
                close_output(writer, stream)
            _summary(player, time.monotonic() - started)
            if player.stopped is not None and player.stopped.reason == "interrupted":
                _raise_stopped(player.stopped)
    if player.stopped is not None:
        _raise_stopped(player.stopped)
    _raise_unanswered(player)


def _raise_unanswered(player):
    """A play whose every log read went unanswered never passes: nothing confirmed a goal."""
    from ...errors import NoReply

    s = player.summary()
    if s["reads"] and s["read_failures"] == s["reads"]:
        raise NoReply(f"no actuator answered: {s['reads']} log reads unanswered, the goals went out unconfirmed")


def several_buses(bus_names) -> bool:
    """Whether the command works on several buses: --buses, or -p given more than once."""
    return bus_names is not None or ports_given() is not None


def bus_specs(bus_names, fleet_file, common, unit, ids=()):
    """The buses of ``--buses`` (exit 2 with -p or --sim, without --fleet, with --unit mm), or
    of ``-p`` given more than once: each port a bus named by its port, with ``ids``."""
    from ...api.buses import BusSpec, buses_of

    ports = ports_given()
    if ports is not None:
        if bus_names is not None:
            raise UsageError("--buses: the ports are the fleet file's; not with -p given more than once")
        if common["sim"]:
            raise UsageError("-p given more than once: not with --sim (one simulated bus)")
        if unit == "mm":
            raise UsageError("-p given more than once: --unit mm is for one bus (an ID's stroke is per bus)")
        baud = common["baud"][0] if isinstance(common["baud"], (list, tuple)) else common["baud"]
        return [BusSpec(port, port, baud, list(ids)) for port in ports]
    if not fleet_file:
        raise UsageError("--buses: needs --fleet FILE (the fleet file naming the buses)")
    if common["port"] or common["sim"]:
        raise UsageError("--buses: the ports are the fleet file's; not with -p or --sim")
    if unit == "mm":
        raise UsageError("--buses: --unit mm is for one bus (an ID's stroke is per bus)")
    names = None if bus_names.strip().lower() == "all" else [n.strip() for n in bus_names.split(",") if n.strip()]
    specs = buses_of(fleet_file, names)
    _same_protocol(fleet_file, common)
    return specs


def _same_protocol(fleet_file, common):
    """A fleet file's buses speak its protocol: --buses with another --protocol is refused (exit 2)."""
    from ...api import documents
    from ...api.fleet import format_of

    doc, name = documents.read(fleet_file, "fleet", format_of(fleet_file))
    theirs, ours = doc.get("protocol") or "ir", common.get("protocol") or "ir"
    if theirs != ours:
        raise UsageError(f"--buses: {name}'s buses speak the {theirs} protocol; give --protocol {theirs}")


def open_spec(common):
    """Opens a :class:`~zkzap.api.buses.BusSpec` with the command's link options (its
    --protocol and --map too)."""
    from ...link.zap_bus import open_bus

    protocol = common.get("protocol") or "ir"
    mode = 1 if common["return_mode"] == "auto" or protocol == "modbus" else int(common["return_mode"])
    latency = None if common.get("latency") is None else common["latency"] / 1000.0

    def opener(spec):
        return open_bus(spec.port, spec.baud, timeout=common["timeout"], return_mode=mode, retries=common["retries"],
                        stop_bits=common["stop_bits"], latency=latency, protocol=protocol,
                        regmap=common.get("regmap"))
    return opener


def _play_buses(path, rows, bus_names, fleet_file, unit, interpolate, rate, loops, limit, stop_mode, no_log, fmt,
                output, append, dry_run, common, wire):
    """zap play --buses: one player a bus, each on its own thread, their step 0 at one moment."""
    import time

    from ...api import buses, motion

    specs = bus_specs(bus_names, fleet_file, common, unit, sorted({i for r in rows for i in r.ids}))
    plans = {}
    for spec in specs:
        mine = motion.rows_for_bus(rows, spec, specs, "stdin" if path == "-" else path,
                                   shared=ports_given() is not None)
        if mine:
            plans[spec.name] = motion.plan(mine, baud=spec.baud, stop_bits=common["stop_bits"],
                                           interpolate=interpolate, rate=rate, protocol=wire)
    specs = [s for s in specs if s.name in plans]
    if dry_run:
        for spec in specs:
            p = plans[spec.name]
            note(f"bus {spec.name} ({spec.port}): {p.note}; {len(p.steps)} steps, {p.frames} frames")
        if fmt in ("json", "jsonl"):
            from ...io.writers import make_writer

            writer = make_writer(fmt, sys.stdout, ["bus", "t", "goals", "speeds", "currents", "frames"])
            for spec in specs:
                for step in plans[spec.name].steps:
                    writer.write({"bus": spec.name, **step.record()})
            writer.close()
        else:
            for spec in specs:
                for step in plans[spec.name].steps:
                    for frame in step.frames:
                        sys.stdout.write(f"{spec.name:>8s} {step.t:9.3f}  {frame.hex(' ').upper()}\n")
        return
    if common["return_mode"] == "0" and not no_log:
        raise UsageError("--return-mode 0: the log reads are never answered; give --no-log")
    columns = ["bus"] + list(motion.LOG_COLUMNS) + list(wire.log_columns)
    record_fmt = None if no_log else output_format(fmt if fmt != "table" else None, output, ("jsonl", "json", "csv"))
    if record_fmt == "table":
        record_fmt = "jsonl"
    stream, had = (None, False)
    if record_fmt is not None:
        stream, had = open_output(output, append, fmt=record_fmt, columns=columns)
    players = {}
    at = time.time() + 0.3 + 0.05 * len(specs)          # every port open by then: step 0 on every bus

    def work(link, spec, emit, cancel):
        player = players[spec.name] = motion.Player(link, plans[spec.name], loops=loops, log=not no_log, limit=limit,
                                                    stop_mode=stop_mode, cancel=cancel, start=at)
        player.run(emit)
        if player.stopped is not None and player.stopped.reason != "cancelled":
            cancel.set()                       # one bus stopped: every bus stops

    writer = None
    if record_fmt is not None:
        from ...io.writers import make_writer

        writer = make_writer(record_fmt, stream, columns, header=not had)
    started = time.monotonic()
    try:
        for row in buses.run(specs, work, open_bus=open_spec(common)):
            if writer is not None:
                writer.write(row)
    finally:
        if writer is not None:
            close_output(writer, stream)
        for spec in specs:
            player = players.get(spec.name)
            if player is not None:
                _summary(player, time.monotonic() - started, f"bus {spec.name}: ")
    first = None
    for spec in specs:
        player = players.get(spec.name)
        if player is not None and player.stopped is not None:
            from ...api.motion import describe_stop

            warn(f"bus {spec.name}: stopped every actuator ({player.stopped.message}): "
                 f"{describe_stop(player.stopped.positions, player.stopped.mode)}")
            if player.stopped.reason != "cancelled" and first is None:
                first = player.stopped
    if first is not None:
        if first.reason == "interrupted":
            raise KeyboardInterrupt
        raise_stop(first)
    for player in players.values():
        _raise_unanswered(player)


def scan_buses(ids, fmt, bus_names, fleet_file, common):
    """zap scan --buses: every bus of the fleet file scanned at its baud rate, one thread each;
    an ID the file puts on a bus that does not answer there is said."""
    from ...api import buses
    from ...api.zap import Bus
    from ...io.writers import make_writer
    from ..options import resolve_format
    from .scan import SCAN_COLUMNS, SCAN_TABLE, _emit

    specs = bus_specs(bus_names, fleet_file, common, "counts")    # -p again: no ID is expected anywhere
    bauds = list(common["baud"]) if ports_given() is not None else None
    fmt = resolve_format(fmt)
    writer = make_writer(fmt, sys.stdout, ["bus"] + SCAN_COLUMNS, table_columns=[("bus", "bus")] + SCAN_TABLE,
                         title="mightyZAP actuators")
    found = []

    def work(link, spec, emit, cancel):
        for rec in Bus.over(link).scan(ids, bauds or [spec.baud], retries=common["retries"],
                                       on_warning=lambda text: warn(f"bus {spec.name}: {text}"),
                                       on_note=lambda text: note(f"bus {spec.name}: {text}")):
            if cancel.is_set():
                return
            emit(rec)

    try:
        for rec in buses.run(specs, work, open_bus=open_spec(common)):
            _emit(writer, rec, found, fmt)
    finally:
        writer.close()
    for spec in specs:
        missing = sorted(set(spec.ids) - {r["id"] for r in found if r["bus"] == spec.name and r["status"] == "ok"})
        if missing:
            warn(f"bus {spec.name} ({spec.port}): ID{'s' if len(missing) > 1 else ''} "
                 f"{', '.join(map(str, missing))} of the fleet file did not answer")
    if not found:
        from ...errors import NoReply

        raise NoReply(f"no actuator answered on bus{'es' if len(specs) > 1 else ''} "
                      f"{', '.join(s.name for s in specs)}")


def _path_ids(path, text=None, wire=None):
    """The IDs a path file names (read without conversion: the fleet file's scales are for them)."""
    from ...api import motion

    if text is None:
        try:
            with open(path, encoding="utf-8") as f:
                text = f.read()
        except (OSError, UnicodeDecodeError):
            return []                       # read_path says what is wrong with it
    ids = set()
    for line, rec in motion._records(text, str(path)):
        for k, v in rec.items():
            if motion._ALIASES.get(str(k).lower(), str(k).lower()) == "id":
                ids.update(motion._ids(str(path), line, v, wire.protocol if wire is not None else "ir"))
    return sorted(ids)


# -- teach ---------------------------------------------------------------------------------------

@exits({NO_REPLY: "an actuator did not answer (the waypoints taken so far are written)"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.option("--ids", "ids", type=IdList(), required=True, metavar="LIST", help="Actuators to record, like 1,2,5-8.")
@click.option("-o", "--output", type=OutputPath("document", formats=PATH_FORMATS, default="csv"), required=True,
              help="The path file to write: .csv, .jsonl or .json (what zap play reads).")
@click.option("-r", "--rate", type=FiniteRange(0.1, 100), default=None, metavar="HZ",
              help="Record at this rate (t: the time since the first waypoint) instead of on Enter.")
@click.option("--interval", type=FiniteRange(0.01, 3600), default=1.0, show_default=True, metavar="SECONDS",
              help="Without --rate: the time between two waypoints in the file.")
@click.option("-c", "--count", type=IntRange(1, None), default=None, metavar="N", help="Stop after N waypoints.")
@click.option("-d", "--duration", type=FiniteRange(0, None, min_open=True), default=None, metavar="SECONDS",
              help="With --rate: stop after this long.")
@click.option("--force-off", is_flag=True,
              help="Turn the actuators' force off first, so the rods can be moved by hand (a goal position "
                   "turns it back on).")
@unit_options
@link_options
@protocol_options
def teach(ids, output, rate, interval, count, duration, force_off, unit, fleet_file, **common):
    """Record the actuators' present positions as waypoints: each time Enter is pressed (a
    line on stdin; 'q' or end of input finishes), or at --rate.

    Move the rods by hand with --force-off (zap teach holds the port: zap move cannot reach the
    bus meanwhile; to move them with sliders, teach from the browser console, zkzap web zap);
    each waypoint is one row per actuator (t, id, position), t = --interval x its number (with
    --rate: the time since the first). The file plays back with zap play (with --unit mm: positions in
    mm, played with --unit mm). Ctrl-C finishes too: the waypoints taken are written.

    \b
    Examples:
      zap teach --ids 1,2 -o path.csv -p /dev/ttyUSB0             # Enter per waypoint, q to finish
      zap teach --ids 1-4 --force-off --rate 10 --duration 20 -o path.csv -p /dev/ttyUSB0
    """
    from ...api import motion
    from ...link import stop

    from ...outfile import check_path

    if duration is not None and rate is None:
        raise UsageError("--duration: applies only with --rate")
    check_path(output, "--output")                # before anything is read: written whole at the end
    scales = unit_scales(unit, fleet_file, ids)
    fmt = OutputPath("document", formats=PATH_FORMATS, default="csv").format_of(output) or "csv"
    rows = []
    try:
        with open_link(ids=ids, **_link_args(common)) as bus:
            if force_off:
                bus.symmetric_store(motion.FORCE, [(i, 0) for i in ids])
                note(f"force off on ID{'s' if len(ids) > 1 else ''} {', '.join(map(str, ids))}: move the rods by hand")
            teacher = motion.Teacher(bus, ids, interval=interval, timed=rate is not None, scales=scales)
            if rate is None:
                prompt = sys.stdin.isatty()
                while count is None or teacher.count < count:
                    if prompt:
                        click.echo(f"waypoint {teacher.count + 1}: Enter to record, q to finish", err=True)
                    line = sys.stdin.readline()
                    if not line or line.strip().lower() in ("q", "quit"):
                        break
                    got = teacher.take()
                    rows += got
                    note(f"waypoint {teacher.count}: " + ", ".join(f"ID {r['id']} {r['position']}" for r in got))
            else:
                import time

                t0 = time.monotonic()
                while (count is None or teacher.count < count) and \
                        (duration is None or time.monotonic() - t0 < duration):
                    due = t0 + teacher.count / rate
                    wait = due - time.monotonic()
                    if wait > 0:
                        stop.pause(wait)
                    rows += teacher.take()
    finally:
        if rows:
            _write_path(output, rows, fmt)
            n = len({r["t"] for r in rows})
            note(f"{n} waypoint{'s' if n != 1 else ''} of {len(ids)} actuator{'s' if len(ids) != 1 else ''} "
                 f"written to {output}")
    if not rows:
        note("no waypoint taken; nothing written")


def _write_path(output, rows, fmt):
    import io

    from ...api.motion import write_path
    from ...outfile import write_whole

    buf = io.StringIO()
    write_path(buf, rows, fmt=fmt)
    write_whole(output, buf.getvalue(), what="output")


# -- calibrate -----------------------------------------------------------------------------------

@exits({NO_REPLY: "the actuator did not answer (nothing recorded)",
        CHECK_FAILED: "the two ends are the same position, or the speed could not be measured"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.option("-i", "--id", "ident", type=IdList(), required=True, metavar="ID", help="The actuator to calibrate.")
@click.option("--fleet", "fleet_file", type=OutputPath("state", formats=("json", "toml", "yaml"), default=None),
              required=True, help="The fleet file to record the calibration in (.json, .toml, .yaml; created when "
                                  "missing; its other entries are kept).")
@click.option("--travel", type=FiniteRange(0.01, 1000), default=None, metavar="MM",
              help="The distance between the two ends, measured (default: from the rated stroke).")
@click.option("--part", default=None, metavar="PART", help="Record the part number too (like 12Lf-20PT-27).")
@click.option("--stroke", type=FiniteRange(0.01, 1000), default=None, metavar="MM",
              help="Record the rated stroke too (mm).")
@click.option("--retracted", type=IntRange(0, 10000), default=None, metavar="COUNTS",
              help="The retracted end's position, known already (not read; 0..4095 on a 12Lf, 0..10000 on a 17Lf).")
@click.option("--extended", type=IntRange(0, 10000), default=None, metavar="COUNTS",
              help="The extended end's position, known already (not read; 0..4095 on a 12Lf, 0..10000 on a 17Lf).")
@click.option("--manual", is_flag=True,
              help="Show each end by hand (move the rod there, then Enter) instead of driving the rod to its "
                   "stroke limits.")
@click.option("--measure-speed", is_flag=True,
              help="Then move between the two ends at goal-speed 1023 and record the rod's speed (mm/s).")
@link_options
@protocol_options
def calibrate(ident, fleet_file, travel, part, stroke, retracted, extended, manual, measure_speed, **common):
    """Teach the two ends of an actuator's stroke and record them in the fleet file.

    The rod is driven to each end of its stroke limits and the position it stops at is read;
    with --manual the operator shows each end instead: move the rod there (zap move, the
    console, or by hand with the force off) and press Enter. --retracted/--extended give a
    position known already.
    The fleet file's motion entry of the actuator gets the calibration: both ends in counts and
    the travel between them in mm (--travel, measured; else from the rated stroke of --stroke,
    --part or the file). From then on --unit mm counts millimetres from the retracted end.
    With --protocol modbus (a 17Lf: positions 0..10000, no part table) give --travel or
    --stroke for millimetres.

    \b
    Examples:
      zap calibrate --id 1 --fleet fleet.json --part 12Lf-20PT-27 -p /dev/ttyUSB0
      zap calibrate --id 2 --fleet fleet.json --manual --travel 26.5 -p /dev/ttyUSB0
      zap calibrate --id 1 --fleet fleet.json --travel 26.8 --measure-speed -p /dev/ttyUSB0
    """
    import os

    from ...api import units

    if len(ident) != 1:
        raise UsageError("--id: one actuator")
    ident = ident[0]
    from ...api.fleet import check_ident

    wire = _wire(common)
    modbus = wire.protocol == "modbus"
    check_ident(wire.map, ident)
    for name, given in (("--retracted", retracted), ("--extended", extended)):
        if given is not None:
            try:
                wire.position.check(given)
            except ValueError as e:
                raise UsageError(f"{name}: {e}") from None
    if part is not None and modbus and stroke is None:
        raise UsageError(f"--part {part}: no {wire.map.model} part's stroke is in the model table; give --stroke")
    if part is not None and stroke is None:
        units.stroke_of_part(part)               # a part the table does not know needs --stroke
    from ...outfile import check_state

    check_state(fleet_file, "--fleet")            # read now and rewritten whole at the end
    motion_entry = {}
    existing = {}
    if os.path.exists(fleet_file):
        from ...api.fleet import read_document

        entry = read_document(fleet_file).get(ident)
        existing = (entry.motion if entry is not None else None) or {}
    if part is not None:
        motion_entry["part"] = part
    if stroke is not None:
        motion_entry["stroke_mm"] = stroke
    rated = stroke or existing.get("stroke_mm")
    if rated is None and (part or existing.get("part")) and not modbus:
        rated = units.stroke_of_part(part or existing.get("part"))
    regmap = wire.map if modbus else None
    rated_counts = units.position_range(regmap)[0]
    from ...api.zap import Bus

    with open_link(ids=[ident], **_link_args(common)) as link:
        bus = Bus.over(link)
        ends = {}
        for name, given, goal in (("retracted", retracted, wire.position.lo), ("extended", extended, wire.position.hi)):
            if given is not None:
                ends[name] = given
                continue
            if manual:
                click.echo(f"move ID {ident} to its {name} end, then press Enter", err=True)
                if not sys.stdin.readline():
                    raise UsageError(f"calibrate: the input ended before the {name} end was shown")
                ends[name] = int(bus.read(ident, "present-position"))
            else:                          # driven there: the goal is clamped to the stroke limit
                import warnings

                from ...errors import GoalClamped

                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", GoalClamped)      # the clamp is the point here
                    ends[name] = int(bus.move(ident, goal, wait=True, timeout=30, notify=None))
            note(f"{name} end: {ends[name]}")
        if ends["retracted"] == ends["extended"]:
            raise CheckFailed(f"calibrate: both ends read {ends['retracted']}: the rod did not move between them")
        if travel is None and rated is not None:
            travel = round(abs(ends["extended"] - ends["retracted"]) * rated / rated_counts, 3)
        cal = {"retracted": ends["retracted"], "extended": ends["extended"]}
        if travel is not None:
            cal["travel_mm"] = travel
        motion_entry["calibration"] = cal
        if measure_speed:
            if travel is None:
                raise UsageError("--measure-speed: needs the travel in mm (--travel, --stroke or --part)")
            motion_entry["max_speed_mm_s"] = _measure_speed(bus, ident, ends, travel)
    units.record_motion(fleet_file, ident, motion_entry)
    said = f"ID {ident}: retracted {cal['retracted']}, extended {cal['extended']}"
    if travel is not None:
        scale = units.Scale(calibration=cal, regmap=regmap)
        said += f", {travel:g} mm between them ({abs(scale.mm_per_count) * 1000:.2f} um a count)"
    else:
        said += " (no travel in mm: give --travel, --stroke or --part for millimetres)"
    note(said + (f"; {motion_entry['max_speed_mm_s']:g} mm/s at goal-speed 1023" if measure_speed else "")
         + f"; recorded in {fleet_file}")


def _measure_speed(bus, ident, ends, travel):
    """mm/s of the rod at goal-speed 1023: positions read during a move from the retracted to the
    extended end, timed on the session's clock (model time on a simulator run faster); the slope
    between the first and the last reading strictly between the ends (the rod ends extended)."""
    from ...link.clock import SessionClock

    clock = SessionClock.of_port(bus.link.port)
    bus.move(ident, ends["retracted"], speed=1023, wait=True, timeout=30)
    lo, hi = sorted((ends["retracted"], ends["extended"]))
    samples = []

    def seen(pos, goal, first):
        if lo < pos < hi:
            samples.append((clock.now(), pos))

    bus.move(ident, ends["extended"], speed=1023, wait=True, timeout=30, poll=0, on_progress=seen)
    if len(samples) < 2 or samples[-1][0] <= samples[0][0]:
        raise CheckFailed("calibrate: too few positions read during the move to measure its speed")
    (t0, p0), (t1, p1) = samples[0], samples[-1]
    counts_per_s = abs(p1 - p0) / (t1 - t0)
    return round(counts_per_s * travel / (hi - lo), 2)
