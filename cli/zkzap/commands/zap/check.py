"""``zap check``: a self-check of each actuator, with a verdict table."""

from __future__ import annotations

import sys

import click

from ...errors import CHECK_FAILED, CheckFailed, DEVICE_ERROR, DeviceError, OK, UsageError
from .. import CONTEXT, Command
from ..options import (Choice, FiniteRange, consent, exits, protocol_options, resolve_format,
                       zap_move_yes_option as yes_option)
from .compose import _link_args, link_options, open_link
from .scan import IdList

TABLE = [("id", "id"), ("check", "check"), ("verdict", "verdict"), ("value", "value"), ("limit", "limit"),
         ("detail", "detail")]


@exits({OK: "every check passes", CHECK_FAILED: "a check fails",
        DEVICE_ERROR: "an actuator reports error bits"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.option("--ids", "ids", type=IdList(), default="0", show_default=True, metavar="LIST",
              help="Actuators to check, one after the other, like 1-4.")
@click.option("--no-move", is_flag=True, help="Check without moving: echo, identity, voltage and error bits only.")
@click.option("--move-timeout", type=FiniteRange(0.1, 600), default=10.0, show_default=True,
              metavar="SECONDS", help="The longest a stroke may take.")
@click.option("-f", "--format", "fmt", type=Choice(("table", "json", "jsonl", "csv")), default=None,
              help="Output format (default: table on a terminal, jsonl otherwise).")
@yes_option
@link_options
@protocol_options
def check(ids, no_move, move_timeout, fmt, yes, **common):
    """Self-check actuators: echo, model and firmware, supply voltage within the actuator's
    limits, error bits, a full-stroke move, force off and on, and the original goal restored.

    The move goes to the short stroke limit, then the full stroke to the long one (timed, with
    the peak current); a rod that stops advancing while still 'moving' is reported as a stall
    with the current it drew. Whatever happens, the original goal position is written back.
    One row per check and actuator: id, check, verdict (pass, fail, error, skipped), value,
    limit, detail, and a 'verdict' row per actuator. Exit status 0 when every check passes,
    1 when one fails, 5 when an actuator reports error bits. On a real port the moves need
    consent (--yes); --no-move checks without moving.

    \b
    Examples:
      zap check --ids 1-4 -p /dev/ttyUSB0 --yes
      zap check --ids 1 --no-move -p /dev/ttyUSB0 -f json
      zap check --protocol modbus --ids 1-2 -p /dev/ttyUSB0 --yes

    With --protocol modbus (the 17Lf) the error bits are its hardware-error register's, and the
    voltage check is skipped: its map gives no voltage limits (the raw value is shown).
    """
    from ...api.selfcheck import COLUMNS, check_actuator
    from ...io.writers import make_writer
    from ...link.zap_bus import is_simulated

    if common["return_mode"] == "0" and common.get("protocol", "ir") == "ir":
        raise UsageError("--return-mode 0: Load Data is never answered, so nothing can be checked")
    if not no_move and not (common["sim"] or is_simulated(common["port"])):
        consent(f"check moves actuator{'s' if len(ids) > 1 else ''} {', '.join(map(str, ids))} on {common['port']} "
                "through their full stroke", yes)
    fmt = resolve_format(fmt)
    writer = make_writer(fmt, sys.stdout, COLUMNS, table_columns=TABLE, title="mightyZAP self-check")
    verdicts = {}
    try:
        with open_link(ids=ids, **_link_args(common)) as bus:
            for ident in ids:
                for row in check_actuator(bus, ident, move=not no_move, move_timeout=move_timeout):
                    if row["check"] == "verdict":
                        verdicts[ident] = row["verdict"]
                    if fmt == "table":
                        row = dict(row, value="-" if row["value"] is None else row["value"],
                                   limit="-" if row["limit"] is None else row["limit"])
                    writer.write(row)
    finally:
        writer.close()
    errors = [i for i, v in verdicts.items() if v == "error"]
    failed = [i for i, v in verdicts.items() if v == "fail"]
    if errors:
        several = len(errors) > 1
        raise DeviceError(f"ID{'s' if several else ''} {', '.join(map(str, errors))} "
                          f"{'report' if several else 'reports'} error bits"
                          + (f"; ID{'s' if len(failed) > 1 else ''} {', '.join(map(str, failed))} failed a check"
                             if failed else ""))
    if failed:
        raise CheckFailed(f"ID{'s' if len(failed) > 1 else ''} {', '.join(map(str, failed))} failed a check")
