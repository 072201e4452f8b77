"""``zkzap ports``: the serial ports present, with adapter hints (:mod:`zkzap.link.adapters`)."""

from __future__ import annotations

import click

from . import CONTEXT, Command
from .options import format_option, note, resolve_format, write_rows

COLUMNS = ["device", "name", "description", "vid_pid", "vid", "pid", "serial_number", "manufacturer", "product",
           "location", "chip", "by_id", "latency_timer_ms", "permission", "group", "hints"]
TABLE_COLUMNS = [("device", "device"), ("description", "description"), ("vid_pid", "VID:PID"),
                 ("serial_number", "serial number"), ("latency_timer_ms", "latency timer (ms)"), ("_hints", "hints")]


@click.command(cls=Command, context_settings=CONTEXT)
@click.option("-u", "--usb", "usb_only", is_flag=True, help="Only USB adapters (leave out built-in UARTs).")
@format_option()
def ports(usb_only, fmt):
    """List the serial ports present: device, description, USB VID:PID, serial number, and
    hints where they matter.

    An FTDI adapter's latency timer (16 ms by default on Linux) delays every reply; the hint
    shows its value and how to set 1 ms. CH34x adapters (IR Robot's own USB adapter) have no
    such setting. A port you may not open gets a permission hint. Records also carry the chip,
    the stable /dev/serial/by-id name, the latency timer and the hints as a list. Any listed
    device, or a pyserial URL, goes to -p/--port.

    \b
    Examples:
      zkzap ports
      zkzap ports --usb -f json
      zkzap ports -f jsonl | jq -r 'select(.chip != null) | .device'
    """
    from ..link.adapters import port_records

    records = port_records(usb_only=usb_only)
    fmt = resolve_format(fmt)
    if not records:
        note("no serial ports found" + (" (USB)" if usb_only else ""))
    if fmt == "table":
        for r in records:
            r["_hints"] = "\n".join(r["hints"]) or None
    elif fmt == "csv":
        for r in records:
            r["hints"] = " | ".join(r["hints"])
    write_rows(records, COLUMNS, fmt, title="Serial ports", table_columns=TABLE_COLUMNS)
