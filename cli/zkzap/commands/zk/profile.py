"""``zk profile``: run a throttle schedule on the engine while its telemetry is logged."""

from __future__ import annotations

import json
import sys

import click

from ...errors import OutputError, UsageError
from .. import CONTEXT, Command
from ..options import FilePath, close_output, consent, dry_run_option, note, port_options, protocol_version_option, yes_option
from .telemetry import exit_help, log_options, resolve_port, zk_timeout_help

EPILOG = ("On a real port a schedule that can start the engine (any row in state run) needs --yes or "
          "a prompt on a terminal; sim:// and --sim never ask. "
          + exit_help("the schedule ran to its end", "a new ECU error code (the abort command was sent)"))


def example_text() -> str:
    from importlib.resources import files

    return files("zkzap.data").joinpath("example-profile.csv").read_text(encoding="utf-8")


def _read(path) -> str:
    if path == "-":
        return sys.stdin.read()
    try:
        with open(path, encoding="utf-8") as f:
            return f.read()
    except OSError as e:
        raise UsageError(f"schedule: cannot read {path}: {e.strerror}") from None
    except UnicodeDecodeError:
        raise UsageError(f"schedule: {path} is not UTF-8 text "
                         "(expected CSV rows time_s,throttle_pct[,state])") from None


@click.command(cls=Command, context_settings=CONTEXT, epilog=EPILOG)
@click.argument("schedule", required=False, metavar="SCHEDULE.csv", type=FilePath())
@click.option("--example", is_flag=True, help="Print the example schedule (a start, steps up to 100 %, "
                                              "cool-down) and exit.")
@click.option("--interpolate", type=click.Choice(["step", "linear"]), default="step", show_default=True,
              help="step: each row holds until the next; linear: the throttle ramps between rows.")
@click.option("--rate", type=click.FloatRange(1, 200), default=None, metavar="HZ",
              help="Control frames per second (default 20).")
@click.option("--abort", type=click.Choice(["standby", "stop", "none"]), default="standby", show_default=True,
              help="Sent on Ctrl-C, SIGTERM, a port failure, a silent ECU, an ECU error, and at the end of a "
                   "schedule that ends in state run: that state with throttle 0 (standby lets a hot "
                   "engine cool); none sends nothing.")
@click.option("--summary-json", type=click.Path(dir_okay=False, writable=True, allow_dash=True), default=None,
              metavar="FILE", help="Also write the summary as JSON to FILE ('-': stdout).")
@dry_run_option
@port_options("zk")
@yes_option
@protocol_version_option
@log_options
def profile(schedule, example, interpolate, rate, abort, summary_json, dry_run, port, baud, timeout, sim, yes,
            protocol_version, fmt, output, append, snapshot, ids, stale_after, raw_log):
    """Run a throttle schedule on the engine while its telemetry is logged.

    SCHEDULE.csv has rows 'time_s,throttle_pct[,state]' (an optional header names the columns;
    '-' reads stdin): from time_s on, that throttle (0..100 %) and state (pwm, stop, standby,
    run; a row without one keeps the previous, the first defaults to run) are sent at --rate
    Hz, as control ID 1 frames. Nothing is sent before the first row's time; the schedule ends
    at the last row's time.

    Telemetry is written as 'zk monitor' writes it (the dashboard on a terminal, JSON Lines in a
    pipe, CSV snapshot rows with -f csv or -o FILE.csv, --raw-log). At the end a summary goes to
    stderr: duration, frames, max rpm, max EGT, fuel used, the engine states passed through and
    the ECU errors seen (--summary-json FILE for a script). -n prints the commands the schedule
    sends, when they change, without opening a port.

    \b
    Examples:
      zk profile --example > run.csv
      zk profile run.csv -n
      zk profile run.csv -p 'sim://zk?speed=10' -o telemetry.csv
      zk profile run.csv -p /dev/ttyUSB0 --yes -o telemetry.csv --raw-log run.bin --summary-json summary.json
    """
    from ...link import zk_link

    if example:
        if schedule:
            raise UsageError("example: prints the example schedule; give no SCHEDULE with it")
        click.echo(example_text(), nl=False)
        return
    if not schedule:
        raise UsageError("schedule: give SCHEDULE.csv ('-' for stdin), or --example to print one")
    name = "stdin" if schedule == "-" else schedule
    sched = zk_link.Schedule.parse(_read(schedule), name=name, interpolate=interpolate)
    for n in sched.notes[:5]:
        note(n)
    if len(sched.notes) > 5:
        note(f"... and {len(sched.notes) - 5} more rounded throttle values")
    if dry_run:
        _print_plan(sched, rate or zk_link.DEFAULT_RATE, fmt, output, append)
        return
    if sched.length <= 0:
        raise UsageError(f"schedule: {name}: the last row is at 0 s; the last row's time_s is the "
                         f"schedule's length")
    url = resolve_port(port, sim)
    if ids is not None:
        zk_link.parse_ids(ids)
    if not zk_link.is_simulator(url):
        from ...codec import zk

        hazard = next((h for h in map(zk.control_hazard, sched.frames()) if h), None)
        if hazard:
            consent(f"schedule {name} on {url}: {hazard}", yes)
    from .monitor import run_telemetry

    outcome, tel, session = run_telemetry(
        url=url, baud=baud, fmt=fmt, output=output, append=append, snapshot=snapshot, ids=ids,
        stale_after=stale_after, raw_log=raw_log, protocol_version=protocol_version, timeout=timeout,
        duration=sched.length, control=sched.frame_at, rate=rate, abort=abort, stop_on_error=True,
        abort_at_end=sched.final_state == "run", title=f"zk profile {name} on {url}")
    summary = _summary(name, url, sched, outcome, tel, session)
    _print_summary(summary)
    if summary_json:
        _write_json(summary_json, summary)
    outcome.raise_for_status()


zk_timeout_help(profile)


def _summary(name, url, sched, outcome, tel, session) -> dict:
    out = {"schedule": name, "port": url, "outcome": outcome.reason, "exit_status": outcome.exit_code,
           "aborted": outcome.aborted, "duration_s": round(session.ended_t or 0.0, 3),
           "schedule_s": sched.length, "crc_errors": session.source.framer.bad}
    out.update(tel.summary())
    return out


_WHY = {"duration": "end of schedule", "interrupted": "interrupted", "terminated": "terminated",
        "port": "port failure", "silence": "ECU silent", "ecu-error": "ECU error", "pipe": "output closed"}


def _print_summary(s):
    from ...link.zk_link import describe_error

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
    click.echo("\n".join(lines), err=True)


def _write_json(path, summary):
    text = json.dumps(summary, ensure_ascii=False, indent=2) + "\n"
    if path == "-":
        click.echo(text, nl=False)
        return
    try:
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
    except OSError as e:
        raise OutputError(f"summary-json: cannot write {path}: {e.strerror}") from None


def _print_plan(sched, rate, fmt, output, append):
    from ...codec.hexfmt import format_hex
    from ...io.writers import make_writer
    from ..options import open_output, resolve_format

    stream, had = open_output(output, append)
    fmt = resolve_format(fmt, stream)
    cols = ["t", "state", "throttle_pct", "frame"]
    writer = make_writer(fmt, stream, cols, header=not had)
    try:
        for t, state, thr, frame in sched.plan(rate):
            writer.write({"t": t, "state": state, "throttle_pct": thr, "frame": format_hex(frame)})
    finally:
        close_output(writer, stream)
