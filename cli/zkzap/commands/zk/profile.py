"""``zk profile``: run a throttle schedule on the engine while its telemetry is logged."""

from __future__ import annotations

import sys

import click

from ...errors import USAGE, UsageError, ZkzapError
from .. import CONTEXT, Command
from ..options import (Choice, InputPath, OutputPath, abort_option, authorize, close_output,
                       dry_run_option, note, port_options, protocol_version_option, rate_option, yes_option)
from .stand import (Finite, alarm_options, alarm_settings, build_stand, check_output_dir, limit_options,
                    logbook_option, raise_for_status, report, sensor_options, session_sensors, stand_entries)
from .telemetry import log_options, reconnect_option, resolve_port, session_exits, zk_timeout_help

EPILOG = ("On a real port a schedule that can start the engine (any row in state run) needs --yes or "
          "a prompt on a terminal; sim:// and --sim never ask.")


#: The shipped examples (``--example [KIND]``).
EXAMPLES = {"throttle": "example-profile.csv", "rpm": "example-rpm-profile.csv", "limits": "example.limits"}


def example_text(kind="throttle") -> str:
    from importlib.resources import files

    return files("zkzap.data").joinpath(EXAMPLES[kind]).read_text(encoding="utf-8")


@session_exits("the schedule ran to its end", "a new ECU error code (the abort command was sent)",
               "bad usage or input, or a schedule the ECU's reported limits refuse (an RPM target above its max "
               "rpm, a command newer than its protocol version): nothing was sent")
@click.command(cls=Command, context_settings=CONTEXT, epilog=EPILOG)
@click.argument("schedule", required=False, metavar="SCHEDULE.csv", type=InputPath("schedule"))
@click.option("--example", type=Choice(list(EXAMPLES)), is_flag=False, flag_value="throttle", default=None,
              help="Print an example and exit: throttle (default: a start, steps up to 100 %, cool-down), rpm "
                   "(RPM-mode steps for steady-state averages) or limits (a limits file).")
@click.option("--interpolate", type=Choice(["step", "linear"]), default="step", show_default=True,
              help="step: each row holds until the next; linear: the throttle ramps between rows.")
@rate_option()
@abort_option(default="standby",
              help="Sent on Ctrl-C, SIGTERM, a port failure, a silent ECU, an ECU error, a violated limit, "
                   "and at the end of a schedule that ends in state run: that state with throttle 0 "
                   "(standby lets a hot engine cool); none sends nothing and says on stderr that the "
                   "engine is left running.")
@click.option("--summary-json", type=OutputPath("document"), default=None,
              metavar="FILE", help="Also write the summary as JSON to FILE ('-': stdout).")
@click.option("--settle", type=Finite(0, 86400), default=None, metavar="SECONDS",
              help="Per-step averages: let each step settle SECONDS before averaging (default 3 with "
                   "--average or --steps-csv).")
@click.option("--average", type=Finite(0, 86400, min_open=True), default=None, metavar="SECONDS",
              help="Per-step averages over the SECONDS after --settle (default: up to the step's end).")
@click.option("--steps-csv", type=OutputPath("document"), default=None, metavar="FILE",
              help="Write one row per step to FILE: window, mean/min/max of rpm, egt_c, thrust_kg, "
                   "fuel_flow_l_min, pump_voltage_v, throttle_pct, TSFC, and whether it settled.")
@click.option("--fuel-density", type=Finite(0.5, 1.2, unit="kg/L", hint=lambda v: (
                  f"{v:g} kg/m³ would be {v / 1000:g} kg/L" if 500 <= v <= 1200 else None)),
              default=None, metavar="KG_PER_L",
              help="Fuel density for TSFC, in kg/L (default 0.8: Jet A-1; kerosene 0.80, diesel 0.84; "
                   "800 kg/m³ is 0.8 kg/L).")
@dry_run_option
@port_options("zk")
@yes_option
@protocol_version_option
@log_options
@limit_options
@alarm_options
@sensor_options
@logbook_option
@reconnect_option
def profile(schedule, example, interpolate, rate, abort, summary_json, settle, average, steps_csv, fuel_density,
            dry_run, port, baud, stop_bits, timeout, sim, yes, protocol_version, fmt, output, append, snapshot, ids,
            stale_after, raw_log, limit, limits_files, on_limit, logbook, reconnect=None, aux=(), thrust_from=None,
            fuel_flow_from=None, ambient_temp=None, ambient_pressure=None, air_pressure=None, engine=None,
            restart_egt=None, hung_start=None, hot_start=None):
    """Run a throttle or RPM schedule on the engine while its telemetry is logged.

    SCHEDULE.csv has rows 'time_s,throttle_pct[,state]' or 'time_s,rpm=N[,state]' (an optional
    header names the columns time_s, throttle_pct, rpm, state; '-' reads stdin; spreadsheet
    exports with a byte order mark, quoted cells or ';' separators are read): from time_s on,
    that throttle (0..100 %) and state (pwm, stop, standby, run; a row without one keeps the
    previous, the first defaults to run) are sent at --rate Hz as control ID 1 frames. An rpm
    target puts the ECU in RPM mode (ID 6 with the RPM factor that fits the highest target, and
    ID 7 targets); zk profile listens for the ECU's status ID 6 first and refuses a schedule
    with a target above the max rpm it reports, or RPM rows for an ECU older than protocol
    version 4, before its first frame (exit 2, nothing sent); the end and the abort leave RPM
    mode. Nothing is sent before the first row's time; the schedule ends at the last row's time.

    --settle/--average/--steps-csv reduce each step to averages (and TSFC); --limit stops the run
    (the abort) when a field leaves its limit; --logbook records the run.

    Telemetry is written as 'zk monitor' writes it (the dashboard on a terminal, JSON Lines in a
    pipe, CSV snapshot rows with -f csv or -o FILE.csv, --raw-log). At the end a summary goes to
    stderr: duration, frames, max rpm, max EGT, fuel used, the engine states passed through and
    the ECU errors seen (--summary-json FILE for a script). -n prints the commands the schedule
    sends, when they change, without opening a port.

    \b
    Examples:
      zk profile --example > run.csv
      zk profile --example rpm > rpm.csv; zk profile --example limits > engine.limits
      zk profile run.csv -n
      zk profile run.csv -p 'sim://zk?speed=10' -o telemetry.csv
      zk profile run.csv -p /dev/ttyUSB0 --yes -o telemetry.csv --raw-log run.bin --summary-json summary.json
      zk profile run.csv --sim --limit 'egt_c<=850,warn=800' --settle 5 --average 5 --steps-csv steps.csv
    """
    from ...api.schedule import Schedule
    from ...api.session import DEFAULT_RATE
    from ...api.telemetry import parse_ids
    from ...link.zk_port import is_simulator

    if example:
        if schedule:
            raise UsageError("example: prints the example schedule; give no SCHEDULE with it")
        click.echo(example_text(example), nl=False)
        return
    if not schedule:
        raise UsageError("schedule: give SCHEDULE.csv ('-' for stdin), or --example to print one")
    name = "stdin" if schedule == "-" else schedule
    sched = Schedule.load(schedule, name=name, interpolate=interpolate)
    for n in sched.notes[:5]:
        note(n)
    if len(sched.notes) > 5:
        note(f"... and {len(sched.notes) - 5} more rounded values")
    averaging = settle is not None or average is not None or steps_csv is not None
    sensors = session_sensors(aux, thrust_from, fuel_flow_from, ambient_temp, ambient_pressure, air_pressure,
                              averaging=averaging, steps=True)
    if fuel_density is not None and not averaging and sensors.ambient is None:
        raise UsageError("fuel-density: applies with --settle, --average or --steps-csv (or --ambient-temp)")
    if dry_run:
        extra = [n for n, v in (("limit", limit), ("limits", limits_files), ("on-limit", on_limit),
                                ("logbook", logbook), ("steps-csv", steps_csv), ("settle", settle),
                                ("average", average), ("fuel-density", fuel_density), ("engine", engine),
                                ("restart-egt", restart_egt is not None), ("hung-start", hung_start is not None),
                                ("hot-start", hot_start is not None))
                 if v] + list(sensors.given())
        if extra:
            raise UsageError(f"{extra[0]}: not with -n/--dry-run (nothing is run)")
        from .bridging import refuse_without

        refuse_without("a run (not with -n/--dry-run)")
        _print_plan(sched, rate or DEFAULT_RATE, fmt, output, append, schedule)
        return
    sched.check_length()
    url = resolve_port(port, sim)
    if ids is not None:
        parse_ids(ids)
    averager = None
    if averaging:
        from ...api.steady import DEFAULT_DENSITY, StepAverager

        if steps_csv == "-" and (output in (None, "-")):
            raise UsageError("steps-csv: '-' needs -o FILE for the telemetry (both would go to stdout)")
        _check_dir(steps_csv, "steps-csv")
        averager = StepAverager(sched.steps(), 3.0 if settle is None else settle, average,
                                fuel_density or DEFAULT_DENSITY, thrust=sensors.thrust, flow=sensors.flow,
                                ambient=sensors.ambient)
    summary_file = _check_summary(summary_json, schedule, output, raw_log)
    stand = build_stand(limit=limit, limits_files=limits_files, on_limit=on_limit, logbook=logbook, controls=True,
                        averager=averager, force=True, sensors=sensors, engine=engine, density=fuel_density,
                        alarms=alarm_settings(restart_egt, hung_start, hot_start))
    from ...codec import zk

    allow = authorize([zk.ControlFrame(f) for f in sched.frames()], what=f"schedule {name} on {url}",
                      yes=yes, force=False, simulated=is_simulator(url))
    from .monitor import run_telemetry

    def summarize(outcome, tel, session):
        summary = _summary(name, url, sched, outcome, tel, session)
        summary.update(stand_entries(session, stand))
        summary["exit_status"] = stand.exit_status(outcome)
        if averager is not None:
            summary["steps"] = averager.rows()
            summary["rows_not_steps"] = [{"line": row.line, "target": row.target_text(), "from_s": a, "to_s": b,
                                          "why": why}
                                         for row, a, b, why in sorted(averager.skipped + sched.ramps(),
                                                                      key=lambda x: x[1])]
            summary["fuel_density_kg_l"] = averager.density
        steps = (averager.columns(), summary["steps"]) if averager is not None else None
        return steps, summary

    try:
        outcome, tel, session = run_telemetry(
            url=url, baud=baud, fmt=fmt, output=output, append=append, snapshot=snapshot, ids=ids,
            stale_after=stale_after, raw_log=raw_log, protocol_version=protocol_version, timeout=timeout,
            stop_bits=stop_bits, duration=sched.length, control=sched.frame_at, rate=rate, abort=abort,
            stop_on_error=True, abort_at_end=sched.final_state == "run" or sched.ends_in_rpm_mode,
            title=f"zk profile {name} on {url}", stand=stand, reconnect=reconnect, plan=sched.plan_check(),
            inputs={"SCHEDULE": schedule}, extra_outputs={"--summary-json": summary_json, "--steps-csv": steps_csv},
            summarize=summarize, allow=allow)
    except ZkzapError as e:
        # a run that failed to start (no port, ...) still replaces an older summary: with its failure
        if summary_file and e.code != USAGE:
            _write_json(summary_file, {"schedule": name, "port": url, "outcome": "error", "exit_status": e.code,
                                       "error": str(e), "aborted": None, "duration_s": 0.0,
                                       "schedule_s": sched.length})
        raise
    steps, summary = summarize(outcome, tel, session)
    _print_summary(summary)
    report(stand, command="zk profile", port=url, schedule=name, files=(output, raw_log, steps_csv, summary_json),
           outcome=outcome, tel=tel, session=session)
    if steps_csv:
        _write_steps(steps_csv, *steps)
    if summary_json:
        _write_json(summary_file or summary_json, summary)
    raise_for_status(outcome, stand)


zk_timeout_help(profile)


def _summary(name, url, sched, outcome, tel, session) -> dict:
    out = {"schedule": name, "port": url, "outcome": outcome.reason, "exit_status": outcome.exit_code,
           "aborted": outcome.aborted, "duration_s": round(session.ended_t or 0.0, 3),
           "schedule_s": sched.length, "crc_errors": session.source.framer.bad}
    out.update(tel.summary())
    if getattr(session, "bridges", None):
        out["bridges"] = session.bridges
    return out


_WHY = {"duration": "end of schedule", "interrupted": "interrupted", "terminated": "terminated",
        "port": "port failure", "silence": "ECU silent", "ecu-error": "ECU error", "pipe": "output closed",
        "limit": "limit violated", "output": "output failed", "refused": "refused by the ECU's limits"}


def _print_summary(s):
    from ...api.telemetry import describe_error

    def v(x, unit=""):
        return "-" if x is None else f"{x:g}{unit}" if isinstance(x, float) else f"{x}{unit}"

    lines = [
        f"profile {s['schedule']}: {s['duration_s']:g} s of {s['schedule_s']:g} s, "
        f"{_WHY.get(s['outcome'], s['outcome'])}"
        + (f", sent {s['aborted']}" if s["aborted"] else ""),
        f"  frames {s['frames']} ({s['crc_errors']} with a bad CRC), protocol version "
        f"{s['protocol_version']} ({s['version_source']})",
        f"  max rpm {v(s['max_rpm'])}, max EGT {v(s['max_egt_c'], ' °C')}, fuel used {v(s['fuel_used_l'], ' L')}"
        f" (ECU total {v(s['fuel_total_l'], ' L')})",
        f"  states: {' > '.join(s['states']) or '-'}",
        "  errors: " + ("; ".join(describe_error(e["code"], e["name"], e["t"]) for e in s["errors"]) or "none"),
    ]
    for st in s.get("steps") or ():
        lines.append(_step_line(st, v))
    for row in s.get("rows_not_steps") or ():
        lines.append(f"  line {row['line']} ({row['target']}, {row['from_s']:g}..{row['to_s']:g} s): "
                     f"{row['why']}, not a step")
    click.echo("\n".join(lines), err=True)


def _step_line(st, v):
    """A step on stderr: its means (± the standard deviation), the thrust TSFC was computed from
    (the sensor's, when --thrust-from), whether it settled."""
    mean = st["rpm_mean"]
    mark = {False: " NOT SETTLED", None: " (no verdict)"}.get(st.get("settled"), "")
    head = f"  step {st['step']} ({st['target']}){mark}: "
    if mean is None:
        return head + "no frames" + (f" [{st['note']}]" if st["note"] else "")

    def pm(key, digits):
        sd = st.get(key.replace("_mean", "_std"))
        return "" if sd is None else f" ±{sd:.{digits}f}"

    if st.get("thrust_from") is not None:
        thrust = (f"thrust {v(_r(st['thrust_from_kg_mean'], 2), ' kgf')}{pm('thrust_from_kg_mean', 2)} "
                  f"({st['thrust_from']}; ECU {v(_r(st['thrust_kg_mean'], 1), ' kgf')})")
    else:
        thrust = f"thrust {v(_r(st['thrust_kg_mean'], 2), ' kgf')}{pm('thrust_kg_mean', 2)}"
    text = (f"rpm {mean:.0f}{pm('rpm_mean', 0)}, EGT {v(_r(st['egt_c_mean'], 0), ' °C')}{pm('egt_c_mean', 1)}, "
            f"{thrust}"
            + (f", TSFC {st['tsfc_g_kn_s']:g} g/(kN·s)" if st["tsfc_g_kn_s"] is not None else ""))
    if st.get("thrust_corrected_kg") is not None and st.get("rpm_corrected") is not None:
        text += f"; corrected rpm {st['rpm_corrected']:.0f}, thrust {st['thrust_corrected_kg']:g} kgf"
    if st.get("tsfc_corrected_g_kn_s") is not None:
        text += f", TSFC {st['tsfc_corrected_g_kn_s']:g}"
    return head + text + (f" [{st['note']}]" if st["note"] else "")


def _r(x, digits):
    return None if x is None else round(x, digits)


def _check_summary(path, schedule, output, raw_log):
    """--summary-json FILE, checked before anything starts (None for '-' or none)."""
    from ...outfile import check_path, refuse_same_files

    if not path or path == "-":
        return None
    refuse_same_files({"--summary-json": path, "--output": output, "--raw-log": raw_log}, {"SCHEDULE": schedule})
    check_path(path, "summary-json")
    return path


def _write_json(path, summary):
    """The summary as JSON: to stdout for '-', else whole (:func:`zkzap.outfile.write_whole`)."""
    from ...io.writers import dumps
    from ...outfile import write_whole

    text = dumps(summary, indent=2) + "\n"
    if path == "-":
        click.echo(text, nl=False)
        return
    write_whole(path, text, what="summary-json")


def _check_dir(path, what):
    check_output_dir(path, what)


def _write_steps(path, columns, rows):
    """One row per step: to stdout for '-', else whole (one row per step: small)."""
    import io

    from ...io.writers import make_writer

    stream = sys.stdout if path == "-" else io.StringIO()
    writer = make_writer("csv", stream, columns)
    for r in rows:
        writer.write(r)
    writer.close()
    if path != "-":
        from ...outfile import write_whole

        write_whole(path, stream.getvalue(), what="steps-csv")


def _print_plan(sched, rate, fmt, output, append, path):
    from ...codec.hexfmt import format_hex
    from ...io.writers import make_writer
    from ..options import open_output, output_format

    fmt = output_format(fmt, output)
    cols = ["t", "mode", "state", "throttle_pct", "target_rpm", "frame"] if sched.has_rpm else \
        ["t", "state", "throttle_pct", "frame"]
    stream, had = open_output(output, append, fmt=fmt, columns=cols, inputs={"SCHEDULE": path})
    writer = make_writer(fmt, stream, cols, header=not had)
    try:
        for t, mode, state, value, frames in sched.plan(rate):
            rec = {"t": t, "state": state, "throttle_pct": value if mode == "throttle" else None,
                   "frame": " + ".join(format_hex(f) for f in frames)}
            if sched.has_rpm:
                rec["mode"], rec["target_rpm"] = mode, value if mode == "rpm" else None
            writer.write(rec)
    finally:
        close_output(writer, stream)
