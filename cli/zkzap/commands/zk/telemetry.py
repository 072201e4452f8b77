"""Options and helpers that ``zk monitor``, ``zk send --for`` and ``zk profile`` share: where
and how status records are written, the port to open, the exit status text.

Kept apart from the monitor command so that composing a frame (``zk send ... -n``) does not
build the monitor command; the logging machinery itself (:mod:`.monitor`'s ``run_telemetry``)
is imported only when a command really logs.
"""

from __future__ import annotations

import click

from ...errors import DEVICE_ERROR, NO_REPLY, OK, PORT_ERROR, USAGE, UsageError
from ...io import SESSION_FORMATS
from ..options import FiniteRange, IntRange, OutputPath, apply_options, exits, format_option
from .bridging import bridge_options


def session_exits(done: str, device: str, usage: "str | None" = None):
    """The exit statuses of a logging command (:func:`zkzap.commands.options.exits`): ``done`` is
    what 0 means for it, ``device`` when it exits 5, ``usage`` when 2 means more than bad usage
    for it; the other outcomes are the same for all."""
    meanings = {OK: done,
                NO_REPLY: "no status frame within --timeout (at the start or later), or none at all however short "
                          "the run (a silent ECU never passes; bytes that are no ECU's frames, line noise or a "
                          "wrong baud rate, count as none)",
                PORT_ERROR: "the port failed or vanished, or the abort could not be sent (with --reconnect: a "
                            "session that controlled the engine and lost the port, however it ends)",
                DEVICE_ERROR: device + "; a violated --limit (with --on-limit warn: after the run went on to its "
                                       "end); a hung or hot start; a start refused while an alarm of the shell "
                                       "or batch is latched or the engine is not yet at rest and cool after a "
                                       "trip (nothing sent)"}
    if usage is not None:
        meanings[USAGE] = usage
    return exits(meanings, tail=" Every record already written stays whole.")


def log_options(f):
    """Options for where and how status records are written (monitor, send --for, profile)."""
    opts = [
        format_option(choices=SESSION_FORMATS,
                      help="Output format: table is the live dashboard on a terminal; influx is InfluxDB line "
                           "protocol; mcap an MCAP file (a channel per status ID and control command, needs "
                           "zkzap[mcap]); xlsx a workbook with sheets records, steps and summary (needs "
                           "zkzap[xlsx]); parquet Apache Parquet (zkzap[parquet]) and mf4 ASAM MDF 4 (streamed, no extra), "
                           "with units; default table on a terminal, jsonl in a pipe, or by the suffix of -o."),
        click.option("-o", "--output", type=OutputPath("records", formats=SESSION_FORMATS),
                     help="Write records to FILE, in the format its suffix names (.csv, .json, .jsonl, .lp, .mcap, "
                          ".xlsx, .parquet, .mf4; JSON Lines without one), created or replaced by the first record: a run that "
                          "writes none leaves it as it was (the dashboard stays on a terminal)."),
        click.option("--append", is_flag=True,
                     help="Append to --output and --raw-log (a CSV gets no second header)."),
        click.option("--snapshot/--frames", "snapshot", default=None,
                     help="Snapshot rows (every field's latest value on each row) or one record per "
                          "frame. Default: snapshot for csv, frames for jsonl/json."),
        click.option("--ids", metavar="LIST", default=None,
                     help="Only these status IDs (1,2,6 or 1-3); CSV columns shrink to their fields."),
        click.option("--stale-after", type=IntRange(1, 1000), default=3, show_default=True,
                     metavar="N", help="An ID is stale after N of its periods without a frame."),
        click.option("--raw-log", type=OutputPath("bytes"), default=None,
                     metavar="FILE", help="Keep the exact bytes received in FILE (for --replay, "
                                          "or 'zk decode --binary')."),
        bridge_options,
    ]
    return apply_options(f, opts)


#: --reconnect without a value: keep trying this long (seconds).
RECONNECT_DEFAULT = 30.0

reconnect_option = click.option(
    "--reconnect", type=FiniteRange(0.1, 86400), default=None, is_flag=False,
    flag_value=RECONNECT_DEFAULT, metavar="[S]",
    help="When the port fails or vanishes (a USB adapter dropping out), keep reopening the same "
         f"device for up to S seconds (default {RECONNECT_DEFAULT:g} without a value; off without the "
         "option), write a gap record and go on writing the same files. S counts from the first "
         "failure until bytes come again (a port that opens and fails again is the same outage); "
         "after S the run ends with exit status 4, at most one reopen attempt later. A session that controls the "
         "engine sends the abort the moment the port is back, before anything else, and only logs "
         "from then on: it ends with exit status 4 however it ends (its time, Ctrl-C, SIGTERM).")

TIMEOUT_HELP = ("Longest silence tolerated from the ECU, at the start and while running (default 2 s, on the "
                "session's clock: model seconds on sim://zk?speed=N, as every duration); longer means exit 3.")


def zk_timeout_help(cmd):
    """Give a command's --timeout (from port_options) its meaning for a ZK status stream."""
    for p in cmd.params:
        if p.name == "timeout":
            p.help = TIMEOUT_HELP
    return cmd


def port_from_env() -> bool:
    """Whether -p/--port came from ZKZAP_ZK_PORT rather than the command line."""
    ctx = click.get_current_context(silent=True)
    if ctx is None:
        return False
    return ctx.get_parameter_source("port") == click.core.ParameterSource.ENVIRONMENT


def resolve_port(port, sim, **sim_options) -> str:
    """The URL to open: --sim's in-process simulator, else -p PORT (or ZKZAP_ZK_PORT)."""
    from ...link.port import sim_url

    if sim and port and port_from_env():
        port = None                      # an explicit --sim beats the environment's default port
    if sim and port:
        raise UsageError("port: give -p PORT or --sim, not both")
    if sim:
        return sim_url("zk", **sim_options)
    if not port:
        raise UsageError("no port: give -p PORT (or set ZKZAP_ZK_PORT) or --sim")
    from ..options import warn_port

    warn_port(port)
    return port


def check_log_options(ids, snapshot, fmt):
    """Validate the log options before anything is opened; returns the parsed ID set."""
    from ...api.telemetry import parse_ids

    return parse_ids(ids) if ids is not None else None


def errors_text(tel) -> str:
    """Every ECU error a session saw, worded as everywhere (``ECU error 3 (egt-high: ...) at t=...``)."""
    from ...api.telemetry import describe_error

    return "; ".join(describe_error(e["code"], e["name"], e["t"]) for e in tel.summary()["errors"])
