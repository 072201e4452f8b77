"""``zap cycle``: endurance cycles of one actuator, resumable, with a report.

Thin: options -> :mod:`zkzap.api.cycle` -> writers and :mod:`zkzap.io.cycle_report`.
"""

from __future__ import annotations

import time

import click

from ...errors import CHECK_FAILED, DEVICE_ERROR, NO_REPLY, CheckFailed, UsageError
from .. import CONTEXT, Command
from ..options import (FINITE, Choice, FiniteRange, InputPath, IntRange, OutputPath, buses_option, close_output,
                       exits, note, open_output, output_format, output_options, protocol_options, unit_options,
                       unit_scales, warn)
from .compose import _link_args, link_options, open_link
from .scan import IdList

REPORT_FORMATS = ("png", "svg", "pdf", "html")
REPORT_PATH = OutputPath("document", formats=REPORT_FORMATS, default="png")


def _given(name) -> bool:
    ctx = click.get_current_context()
    return ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE


@exits({DEVICE_ERROR: "the actuator reported error bits (it was stopped)",
        CHECK_FAILED: "a stall, a current over --limit or a leg over --leg-timeout (it was stopped)",
        NO_REPLY: "the actuator stopped answering"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.option("-i", "--id", "ident", type=IdList(), default=None, metavar="ID",
              help="The actuator to cycle (required with --between or the stroke limits: a write has no default "
                   "ID; a --path names its own, a --resume state file keeps it).")
@click.option("--between", nargs=2, type=FINITE, default=None, metavar="A B",
              help="The two ends of each cycle (counts, or mm with --unit mm): A -> B -> A (default: the "
                   "actuator's short and long stroke limits).")
@click.option("--path", "path_file", type=InputPath("zap path", label="--path"), default=None,
              help="Instead of --between: a cycle plays this path once (as zap play; every ID it names).")
@click.option("--dwell", type=FiniteRange(0, 3600), default=0.5, show_default=True, metavar="SECONDS",
              help="Time at each end once reached (polled: overshoot counts).")
@click.option("--cycles", "count", type=IntRange(1, 100_000_000), default=10, show_default=True, metavar="N",
              help="Cycles to run (with --resume: the run's total).")
@click.option("-d", "--duration", type=FiniteRange(0, None, min_open=True), default=None, metavar="SECONDS",
              help="Stop after this long (the rod held where it is; --resume goes on).")
@click.option("-s", "--speed", type=FINITE, default=None, metavar="SPEED",
              help="Goal speed written first (raw 1..1023; mm/s with --unit mm).")
@click.option("--stall", type=FiniteRange(0.01, 600), default=1.0, show_default=True, metavar="SECONDS",
              help="Stop when the rod makes no progress toward its goal for this long.")
@click.option("--limit", type=FiniteRange(1, 1600), default=None, metavar="MA",
              help="Stop when the current exceeds this (mA).")
@click.option("--leg-timeout", "leg_timeout", type=FiniteRange(0.01, 3600), default=10.0, show_default=True,
              metavar="SECONDS", help="Stop when one move takes longer than this.")
@click.option("--resume", "resume_path", type=OutputPath("state", formats=("json",), default="json"), default=None,
              metavar="STATE", help="The run's state, a JSON file rewritten after every cycle: a first run creates it; "
                                    "run again with it to go on at the next cycle (its settings, its output "
                                    "appended to).")
@click.option("--report", "report_path", type=REPORT_PATH, default=None,
              help="At the end, write a report of the whole run: .png (also a name without a suffix), .svg, "
                   ".pdf or .html (matplotlib: the 'plot' extra).")
@click.option("-f", "--format", "fmt", type=Choice(["jsonl", "json", "csv"]), default=None,
              help="Record format (default: by the suffix of -o; JSON Lines otherwise).")
@buses_option("Cycle --id (or --path)")
@output_options(formats=("jsonl", "json", "csv"))
@unit_options
@link_options(several=True)
@protocol_options
def cycle(ident, between, path_file, dwell, count, duration, speed, stall, limit, leg_timeout, resume_path,
          report_path, fmt, output, append, unit, fleet_file, bus_names, **common):
    """Run an actuator between two ends for many cycles, measuring each one.

    Each cycle moves A -> B -> A (--between; or plays --path once). Per leg the goal is written
    and present-position .. moving polled back to back, as fast as the line allows: the reach
    time (to within the end-compliance-margin), the overshoot past the goal (to the end of the
    --dwell), peak and mean current, the lowest voltage, the error bits of every reply. One
    record per cycle: cycle, time, t, reach_b_s, reach_a_s, overshoot_b, overshoot_a,
    peak_current_ma, mean_current_ma, min_voltage_v, errors, polls, status. With --protocol
    modbus the poll reads hardware-error, present-position, present-current and present-voltage
    (Read Holding Registers, one per run of the map), the error bits are hardware-error's, and
    min_voltage_raw holds the lowest voltage raw (the 17Lf's map gives it no unit).

    The run stops the rod where it is (goal = present position) on an error bit (exit 5), a
    stall, a current over --limit or a move over --leg-timeout (exit 1), a silent actuator (exit
    3) or Ctrl-C (130). --resume STATE records after each cycle how far the run got; the same
    command again (or just --resume STATE) goes on at its next cycle, appending to its output. --report writes plots of
    the whole run (reach time and current per cycle, their histograms, voltage, overshoot).

    Several buses at once: -p again (or --buses NAMES with --fleet): the same run on each bus,
    each on its own thread, every record naming its bus; a bus that stops (a stall, a limit, an
    error bit) stops every bus, each rod held. --resume keeps each bus's last cycle done (the
    same buses again go on, each at its next cycle); --report plots every bus, each its own
    series.

    \b
    Examples:
      zap cycle --id 1 --between 200 3500 --dwell 0.5 --cycles 10000 -p /dev/ttyUSB0 \\
          -o wear.csv --resume wear.json --report wear.png
      zap cycle --resume wear.json -p /dev/ttyUSB0 --report wear.png
      zap cycle --id 1 --between 2 25 --unit mm --fleet fleet.json --limit 900 -p /dev/ttyUSB0
      zap cycle --path wave.csv --cycles 100 -p /dev/ttyUSB0 -o wave-wear.jsonl
      zap cycle --id 1 --between 200 3500 --cycles 1000 -p /dev/ttyUSB0 -p /dev/ttyUSB1 -o wear.csv
    """
    from ...api import cycle as api

    cycles = count
    if ident is not None and len(ident) != 1:
        raise UsageError("--id: one actuator")
    ident = ident[0] if ident is not None else None
    params = {"id": ident, "between": list(between) if between else None, "path": path_file, "dwell": dwell,
              "cycles": cycles, "speed": speed, "stall": stall, "limit": limit, "timeout": leg_timeout,
              "unit": unit}
    first = 1
    state = None
    import os

    from .motion import several_buses

    several = several_buses(bus_names)

    if resume_path is not None:
        from ...outfile import check_state

        check_state(resume_path, "--resume")
    if resume_path is not None and os.path.exists(resume_path):
        state = api.CycleState.load(resume_path)
        if (state.buses is not None) != several:
            raise UsageError(f"--resume: the run in {resume_path} was on "
                             + (f"{len(state.buses)} buses ({', '.join(state.buses)}); give them again (-p once a "
                                "bus, or --buses)" if state.buses is not None else "one bus; give one -p"))
        for key, opt in (("id", "ident"), ("between", "between"), ("path", "path_file"), ("dwell", "dwell"),
                         ("speed", "speed"), ("stall", "stall"), ("limit", "limit"), ("timeout", "leg_timeout"),
                         ("unit", "unit")):
            if _given(opt) and params[key] != state.params.get(key):
                raise UsageError(f"--{opt.replace('_', '-').replace('ident', 'id')}"
                                 f": {params[key]!r} differs from the run in {resume_path} ({state.params.get(key)!r})")
            params[key] = state.params.get(key, params[key])
        if not _given("count"):
            params["cycles"] = state.params["cycles"]
        first = state.done + 1
        if first > params["cycles"]:
            raise UsageError(f"--resume: the run in {resume_path} has done its {state.done} cycles; give --cycles "
                             "N to go on")
        if output is None and state.output:
            output, append = state.output, True
        state.params.update(params)
        if state.buses is None:
            note(f"resuming the run in {resume_path} at cycle {first} of {params['cycles']}")
    elif resume_path is not None:
        state = api.CycleState(resume_path, params)
    if report_path is not None:
        import importlib.util

        from ...outfile import check_path

        check_path(report_path, "--report")
        if importlib.util.find_spec("matplotlib") is None:
            from ...errors import MissingExtra

            raise MissingExtra("--report", "matplotlib", "plot")
    ident, between, path_file = params["id"], params["between"], params["path"]
    if between is not None and path_file is not None:
        raise UsageError("--between and --path: give one")
    if path_file is not None and (ident is not None or params["speed"] is not None):
        raise UsageError("--path: the path names its actuators and speeds; --id and --speed apply to --between")
    if path_file is None and ident is None:
        raise UsageError("--id: give the actuator to cycle (a write has no default ID)")
    if common["return_mode"] == "0":
        raise UsageError("--return-mode 0: the actuator's position is never answered in feedback-return-mode 0")
    scales = None
    plan = None
    from .motion import _wire

    wire = _wire(common)
    if path_file is not None:
        from ...api import motion
        from .motion import _path_ids

        scales = unit_scales(params["unit"], fleet_file,
                             _path_ids(path_file, wire=wire) if params["unit"] == "mm" else [])
        rows = motion.read_path(path_file, unit=params["unit"], scales=scales, protocol=wire)
        plan = motion.plan(rows, baud=common["baud"], stop_bits=common["stop_bits"], protocol=wire)
        ids = plan.ids
    else:
        from ...api.fleet import check_ident

        check_ident(wire.map, ident)
        ids = [ident]
        scales = unit_scales(params["unit"], fleet_file, ids)
        scale = (scales or {}).get(ident)
        if between is None:
            a = b = None                    # the stroke limits, read once the port is open
            raw_speed = _speed(scale, params["speed"], wire)
        elif scale is not None:
            a, b = (scale.counts(v, what="--between") for v in between)
            raw_speed = _speed(scale, params["speed"], wire)
        else:
            a, b = _counts(between[0], wire=wire), _counts(between[1], wire=wire)
            raw_speed = _speed(scale, params["speed"], wire)
        if between is not None and a == b:
            raise UsageError("--between: the two ends are the same position")
    record_fmt = output_format(fmt, output, ("jsonl", "json", "csv"))
    if record_fmt == "table":
        record_fmt = "jsonl"
    columns = list(api.PATH_COLUMNS if plan is not None else api.COLUMNS)
    if wire.log_columns:
        columns += api.RAW_VOLTAGE_COLUMNS
    if plan is None and scales:
        columns += api.MM_COLUMNS
    if several:
        return _cycle_buses(bus_names, fleet_file, plan, ident, (a, b) if plan is None else None,
                            raw_speed if plan is None else None, params, duration, record_fmt, columns, output,
                            append, common, state, report_path)
    stream, had = open_output(output, append, fmt=record_fmt, columns=columns)
    if state is not None:
        state.output = output if output and output != "-" else None
    from ...io.writers import make_writer

    writer = None
    started = time.monotonic()
    runner = None
    collected = None
    if report_path is not None:
        from ...io.cycle_report import CycleRun

        collected = CycleRun()
    with open_link(ids=ids, **_link_args(common)) as link:
        runner = _runner(link, plan, ident, (a, b) if plan is None else None, raw_speed if plan is None else None,
                         params, first, scales, duration)
        writer = make_writer(record_fmt, stream, columns, header=not had)
        try:
            for rec in runner.run():
                writer.write(rec)
                if collected is not None:
                    collected.add(rec)
                if state is not None and rec["status"] == "ok":
                    state.done = rec["cycle"]
                    state.save()
        except KeyboardInterrupt:
            runner.halt()                  # interrupted while a record was written: the rod too
            raise
        finally:
            close_output(writer, stream)
            _summary(runner, first, time.monotonic() - started, plan is None)
            if runner.reason == "duration":
                note(f"{runner.why}" + _held(runner) + (f"; resume with --resume {state.path}" if state else ""))
            elif runner.reason not in (None, "done", "interrupted"):
                warn(f"stopped: {runner.why}" + _held(runner))
            elif runner.reason in (None, "interrupted"):
                warn("interrupted" + _held(runner)
                     + (f"; resume with --resume {state.path}" if state is not None else ""))
            if report_path is not None:
                _report(report_path, output, collected, params, first)
    _raise_for(runner.reason, runner.why)


def _runner(link, plan, ident, ends, raw_speed, params, first, scales, duration, cancel=None, what=""):
    """The Cycler (--between) or PathCycler (--path) of one bus; the stroke limits read when no
    --between was given. ``cancel``: another bus's stop (see :mod:`zkzap.api.buses`)."""
    from ...api import cycle as api

    if plan is not None:
        return api.PathCycler(link, plan, cycles=params["cycles"], first=first, limit=params["limit"], scales=scales,
                              duration=duration, cancel=cancel)
    a, b = ends
    if a is None:
        a, b = link.read(ident, "short-stroke-limit"), link.read(ident, "long-stroke-limit")
        params["between"] = [a, b]
        note(f"{what}ID {ident}: cycling between its stroke limits, {a} and {b}")
    return api.Cycler(link, ident, a, b, dwell=params["dwell"], cycles=params["cycles"], first=first, speed=raw_speed,
                      stall=params["stall"], limit=params["limit"], timeout=params["timeout"],
                      scale=(scales or {}).get(ident), duration=duration, cancel=cancel,
                      cancel_why="another bus stopped")


def _raise_for(reason, why):
    """The exit of a run that ended for ``reason`` (none for done, a duration, a cancel)."""
    if reason == "device-error":
        from ...errors import DeviceError

        raise DeviceError(f"stopped: {why}")
    if reason == "no-reply":
        from ...errors import NoReply

        raise NoReply(f"stopped: {why}")
    if reason not in (None, "done", "duration", "cancelled"):
        raise CheckFailed(f"stopped: {why}")


def _cycle_buses(bus_names, fleet_file, plan, ident, ends, raw_speed, params, duration, record_fmt, columns, output,
                 append, common, state=None, report_path=None):
    """zap cycle on several buses (--buses, -p again): the same cycle run on each bus, each on its
    own thread (:mod:`zkzap.api.buses`); one record stream whose records name their bus. A bus
    that stops (a stall, a limit, an error bit, Ctrl-C) stops every bus, each rod held.
    ``state``: the run's :class:`~zkzap.api.cycle.CycleState`, keeping each bus's last cycle
    done (a resumed bus goes on at its next one; one that has done them all is not cycled);
    ``report_path``: one report of every bus's cycles (each bus its own series)."""
    from ...api import buses
    from ...io.writers import make_writer
    from .motion import bus_specs, open_spec

    specs = bus_specs(bus_names, fleet_file, common, params["unit"], plan.ids if plan is not None else [ident])
    firsts = {s.name: 1 for s in specs}
    if state is not None:
        if state.buses is None:               # a new run's state
            state.buses = {s.name: 0 for s in specs}
        elif set(state.buses) != set(firsts):
            raise UsageError(f"--resume: the run in {state.path} was on buses {', '.join(state.buses)}; given "
                             f"{', '.join(firsts)}")
        else:
            firsts = {name: state.buses[name] + 1 for name in firsts}
            note(f"resuming the run in {state.path}: " + ", ".join(
                f"bus {n} at cycle {f}" if f <= params["cycles"] else f"bus {n} done" for n, f in firsts.items())
                 + f" of {params['cycles']}")
        state.output = output if output and output != "-" else None
    collected = None
    if report_path is not None:
        from ...io.cycle_report import CycleRun

        collected = CycleRun()
    columns = ["bus"] + columns
    stream, had = open_output(output, append, fmt=record_fmt, columns=columns)
    runners = {}

    def work(link, spec, emit, cancel):
        if firsts[spec.name] > params["cycles"]:
            return                              # a resumed run's bus that has done every cycle
        runner = runners[spec.name] = _runner(link, plan, ident, ends, raw_speed, dict(params), firsts[spec.name],
                                              None, duration, cancel=cancel, what=f"bus {spec.name}: ")
        try:
            for rec in runner.run():
                emit(rec)
        finally:
            if runner.reason not in ("done", "duration", "cancelled"):
                cancel.set()                     # one bus stopped (or failed): every bus stops

    writer = make_writer(record_fmt, stream, columns, header=not had)
    started = time.monotonic()
    try:
        for rec in buses.run(specs, work, open_bus=open_spec(common)):
            writer.write(rec)
            if collected is not None:
                collected.add(rec)
            if state is not None and rec["status"] == "ok":
                state.buses[rec["bus"]] = rec["cycle"]
                state.done = min(state.buses.values())
                state.save()
    except KeyboardInterrupt:
        for runner in runners.values():
            runner.halt()
        if state is not None:
            warn(f"interrupted; resume with --resume {state.path}")
        raise
    finally:
        close_output(writer, stream)
        for spec in specs:
            runner = runners.get(spec.name)
            if runner is None:
                continue
            _summary(runner, firsts[spec.name], time.monotonic() - started, plan is None, f"bus {spec.name}: ")
            if runner.reason not in (None, "done", "duration"):
                warn(f"bus {spec.name}: stopped: {runner.why}" + _held(runner))
        if report_path is not None:
            _report(report_path, output, collected, params, max(firsts.values()), buses=len(specs))
    first = next((r for r in runners.values() if r.reason not in (None, "done", "duration", "cancelled")), None)
    if first is not None:
        _raise_for(first.reason, first.why)


def _speed(scale, speed, wire):
    if speed is None:
        return None
    if scale is not None:
        return scale.speed_raw(speed)
    reg = wire.speed
    return _counts(speed, "--speed", max(1, reg.lo or 0), reg.hi, wire)


def _counts(v, what="--between", lo=None, hi=None, wire=None):
    """A raw value of ``wire``'s goal-position range (or ``lo``..``hi``)."""
    reg = wire.position if wire is not None else None
    lo = lo if lo is not None else (reg.lo if reg is not None else 0)
    hi = hi if hi is not None else (reg.hi if reg is not None else 4095)
    if v != int(v) or not lo <= v <= hi:
        unit = "a position in counts" if what == "--between" else "a raw value"
        raise UsageError(f"{what}: {v:g} is not {unit} ({lo}..{hi}); millimetres need --unit mm")
    return int(v)


def _held(runner):
    held = runner.held
    if held is None:
        return ""
    if isinstance(held, dict):
        return "; " + ", ".join(f"ID {i} held at {p}" for i, p in held.items() if p is not None)
    return f"; held at {held}"


def _summary(runner, first, seconds, polled, what=""):
    last = runner.done
    n = max(0, last - first + 1)
    text = f"{n} cycle{'s' if n != 1 else ''} ({first}..{last}) in {seconds:.1f} s" if n else "no cycle finished"
    if polled and runner.polls:
        try:
            limit = runner.wire_limit()
            text += (f"; {runner.achieved:.1f} polls/s ({runner.achieved / limit:.2f}x the wire limit of "
                     f"{limit:.1f}/s)")
        except ZeroDivisionError:
            pass
    note(what + text)


def _report(path, output, collected, params, first, buses=1):
    """The report of the run; ``first`` above 1 (a resumed run): of the whole run, read back from
    its output file."""
    from ...io import cycle_report

    fmt = REPORT_PATH.format_of(path)
    run = collected
    if output and output != "-" and first > 1:           # a resumed run: the whole run, from its file
        run = cycle_report.load_records(output)
    if run is None or not len(run):
        note(f"no cycle to report; {path} not written")
        return
    if params["between"]:
        what = f"ID {params['id']} between {params['between'][0]:g} and {params['between'][1]:g} {params['unit']}"
    elif params["path"]:
        what = f"path {params['path']}"
    else:
        what = f"ID {params['id']} between its stroke limits"
    if buses > 1:
        what += f" on {buses} buses"
    import os

    from ...outfile import replacing

    with replacing(path, suffix=os.path.splitext(path)[1]) as tmp:     # whole or not at all, as zk report
        cycle_report.render(tmp, fmt, run, title=f"zkzap cycle report: {what}",
                            meta=[("dwell", f"{params['dwell']:g} s")] if params["between"] else [])
    note(f"report written to {path}")
