"""``zk check``: a pre-flight check — watch the ECU for N frames or S seconds, test every limit on
every frame that carries its field, and give a verdict (exit 0 pass, 3 silent, 5 failed)."""

from __future__ import annotations

import os
import sys

import click

from ...errors import CHECK_FAILED, DEVICE_ERROR, NO_REPLY, OK, DeviceError, UsageError, ZkzapError
from .. import CONTEXT, Command
from ..options import Choice, IntRange, exits, port_options, protocol_version_option
from .stand import Finite, limit_options
from .telemetry import resolve_port, zk_timeout_help


COLUMNS = ["check", "verdict", "checked", "extreme", "first_violation_t", "first_warning_t", "violations",
           "warnings"]


@exits({OK: "every limit held and the ECU reported no error code",
        CHECK_FAILED: "a limit no frame carried: its field never arrived (nothing to check it on), or the ECU "
                      "error code when no status ID 1 came",
        NO_REPLY: "no status frame within --timeout, or none at all (a silent ECU never passes)",
        DEVICE_ERROR: "a limit was violated or the ECU reported an error code"},
       tail=" Each check's 'checked' counts the frames that carried its field.")
@click.command(cls=Command, context_settings=CONTEXT)
@port_options("zk", baud_auto=True)
@click.option("-c", "--count", type=IntRange(1), default=None, metavar="N",
              help="Check N status frames (default 50 unless --duration is given).")
@click.option("--duration", type=Finite(0, 86400, min_open=True), default=None, metavar="SECONDS",
              help="Check for SECONDS.")
@limit_options
@click.option("--keepalive", is_flag=True, help="Send keep-alives (ID 0) meanwhile, for ECUs before protocol "
                                                 "version 5.")
@click.option("--allow-ecu-error", is_flag=True, help="Do not fail on an ECU error code (limits only).")
@protocol_version_option
@click.option("-f", "--format", "fmt", type=Choice(["table", "json", "jsonl", "csv"]), default=None,
              help="The verdict: a table on a terminal, one JSON document in a pipe; jsonl/csv give a row "
                   "per check.")
def check(port, baud, stop_bits, timeout, sim, count, duration, limit, limits_files, on_limit, keepalive, allow_ecu_error,
          protocol_version, fmt):
    """Pre-flight check: watch the ECU and test limits, then give a verdict.

    Reads --count status frames (default 50) or --duration seconds, evaluates every --limit
    (and --limits FILE) on every frame that carries its field, and checks that the ECU reports
    no error code. The verdict names each check, the frames it was tested on, the extreme value
    reached and the first violation time; the exit status says pass (0), ECU silent (3) or
    failed (5), so a script branches on it.

    \b
    Examples:
      zk check -p /dev/ttyUSB0 --limit 'power_voltage_v>=7.4' --limit 'egt_c<=100'
      zk check --sim --duration 2 --limits engine.limits -f json | jq .verdict
      zk check -p /dev/ttyUSB0 --keepalive --count 100 && echo ready
      zk check -p /dev/ttyUSB0 --baud auto --limits engine.limits    # find the line settings first
    """
    from ...api.limits import LimitSet, read_limits
    from ...io.term import is_tty

    if on_limit is not None:
        raise UsageError("on-limit: zk check always tests every frame and gives a verdict at the end")
    conditions = read_limits(limit, limits_files)
    if count is None and duration is None:
        count = 50
    url = resolve_port(port, sim)
    from ...codec import zk

    if fmt is None:
        fmt = "table" if is_tty(sys.stdout) else "json"
    limits = LimitSet(conditions, "warn")
    from ...api.stand import Stand
    from .monitor import detect_line, run_telemetry

    if baud == "auto":
        baud, stop_bits = detect_line(url)

    stand = Stand(limits if conditions else None)
    control = None
    if keepalive:
        frame = zk.encode_control("keepalive")[0]

        def control(t):
            return frame

    outcome, tel, session = run_telemetry(
        url=url, baud=baud, stop_bits=stop_bits, fmt="jsonl", output=os.devnull,
        protocol_version=protocol_version, timeout=timeout,
        count=count, duration=duration, control=control, stand=stand)
    if not outcome.ok:
        outcome.raise_for_status()
    rows = []
    for s in limits.summary():
        rows.append({"check": s["limit"], "verdict": s["verdict"], "checked": s["checked"], "extreme": s["extreme"],
                     "first_violation_t": s["first_violation_t"], "first_warning_t": s["first_warning_t"],
                     "violations": s["violations"], "warnings": s["warnings"]})
    errs = tel.summary()["errors"]
    first = min((e["t"] for e in errs), default=None)
    carried = tel.frames_with("error_code")       # the frames that carry the code: ID 1's only
    rows.append({"check": "ECU error code",
                 "verdict": ("violated" if errs and not allow_ecu_error else "warn" if errs
                             else "ok" if carried else "unchecked"),
                 "checked": carried, "extreme": ", ".join(f"{e['code']} {e['name']}" for e in errs) or
                 (0 if carried else None),
                 "first_violation_t": first, "first_warning_t": None, "violations": len(errs), "warnings": 0})
    failed = [r for r in rows if r["verdict"] == "violated"]
    unchecked = [r for r in rows if r["verdict"] == "unchecked"]
    verdict = "fail" if failed else "unchecked" if unchecked else "pass"
    status = 5 if failed else 1 if unchecked else 0
    doc = {"verdict": verdict, "exit_status": status, "port": url, "frames": tel.frames,
           "duration_s": round(session.ended_t or 0.0, 3), "checks": rows}
    _print(doc, rows, fmt)
    if failed:
        raise DeviceError("check failed: " + "; ".join(f"{r['check']} (extreme {r['extreme']})" for r in failed))
    if unchecked:
        raise ZkzapError("check incomplete: no frame carried " + ", ".join(r["check"] for r in unchecked), 1)


zk_timeout_help(check)


def _print(doc, rows, fmt):
    if fmt == "json":
        import json

        click.echo(json.dumps(doc, ensure_ascii=False, indent=2))
        return
    from ..options import write_rows

    if fmt == "table":
        title = f"pre-flight check on {doc['port']}: {doc['verdict'].upper()} ({doc['frames']} frames)"
        write_rows(rows, COLUMNS, "table", title=title,
                   table_columns=[("check", "check"), ("verdict", "verdict"), ("checked", "frames"),
                                  ("extreme", "extreme"), ("first_violation_t", "first violation s"),
                                  ("first_warning_t", "first warning s")])
        return
    write_rows(rows, COLUMNS, fmt)
