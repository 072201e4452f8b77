"""``zk detect``: find the ECU's baud rate, stop bits, protocol version and status rate by
listening (see :mod:`zkzap.api.detect`)."""

from __future__ import annotations

import sys

import click

from ...errors import NO_REPLY, OK, UsageError
from .. import CONTEXT, Command
from ..options import BaudList, Choice, FiniteRange, capture_option, exits, format_option, resolve_format

DETECT_COLUMNS = ["port", "found", "baud", "stop_bits", "protocol_version", "status_rate_hz", "frames_per_s",
                  "elapsed_s", "budget_s", "tried"]


def zk_bauds():
    """The baud rates of the ZK document (tried commonest first), or ``all``."""
    from ...api.detect import BAUDS

    return BaudList(BAUDS, label="baud", what="a baud rate of the ZK document", listed=sorted(BAUDS),
                    example="115200,9600")


def detect_options(f):
    f = click.option("--probe", is_flag=True,
                     help="Send keep-alives (control ID 0) at each setting while listening; by "
                          "default nothing is ever transmitted.")(f)
    f = click.option("--budget", type=FiniteRange(0.1, 600), default=None, metavar="SECONDS",
                     help="Longest the whole search may take (default 12 s).")(f)
    f = click.option("--window", type=FiniteRange(0.05, 60), default=None, metavar="SECONDS",
                     help="Longest listening time per setting (default 0.35 s: three frames at 20 Hz); "
                          "a setting that gives only garbage is left sooner.")(f)
    return f


def run_detection(url, bauds, stop_bits, window, budget, probe):
    """Open ``url`` and search; returns the Detection (the port is closed)."""
    from ...api import detect as D
    from ...link.port import close_port, open_port

    ser = open_port(url, bauds[0], timeout=0.02, stop_bits=stop_bits[0])
    try:
        return D.detect(ser, bauds=bauds, stop_bits=stop_bits, window=window or D.WINDOW_S,
                        budget=budget or D.BUDGET_S, probe=probe, port_name=url)
    except Exception as e:  # noqa: BLE001 - the port failed mid-search
        from ...errors import PortError, ZkzapError

        if isinstance(e, (ZkzapError, KeyboardInterrupt)):
            raise
        raise PortError(f"port {url} failed: {e}") from None
    finally:
        close_port(ser)


@exits({OK: "the ECU was found", NO_REPLY: "no setting gives status frames"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.option("-p", "--port", envvar="ZKZAP_ZK_PORT", metavar="PORT", default=None,
              help="Serial device or pyserial URL [env ZKZAP_ZK_PORT].")
@click.option("--sim", is_flag=True, help="Listen to the built-in simulator instead of a port.")
@click.option("-b", "--baud", "bauds", type=zk_bauds(), default="all", show_default=True, metavar="LIST",
              help="Baud rates to try, like 115200,9600, or all (2400, 4800, 9600, 19200, 38400, 57600, "
                   "115200; tried commonest first).")
@click.option("--stop-bits", type=Choice(["1", "2", "both"]), default="both", show_default=True,
              help="Stop-bit settings to consider.")
@detect_options
@capture_option("zk")
@format_option(choices=("table", "json", "jsonl"))
def detect(port, sim, bauds, stop_bits, probe, budget, window, fmt):
    """Find the ECU's line settings by listening: baud rate, stop bits, protocol version and
    status rate.

    Listens at each baud rate in turn (1 stop bit first, which reads any sender; then 2 to tell
    a 2-stop-bit ECU) until CRC-valid status frames arrive, then waits for a status ID 6 frame
    for the protocol version and status rate. Nothing is transmitted unless --probe is given.
    Prints one record (a table on a terminal, JSON otherwise) with what was found, the time it
    took against --budget and every setting tried. Exit status 3 when no setting gives status
    frames.

    \b
    Examples:
      zk detect -p /dev/ttyUSB0
      zk detect -p /dev/ttyUSB0 -b 115200,9600 --budget 5 -f json
      zk monitor -p /dev/ttyUSB0 --baud auto        # detect, then monitor
    """
    from .telemetry import resolve_port

    url = resolve_port(port, sim)
    bits = (1, 2) if stop_bits == "both" else (int(stop_bits),)
    result = run_detection(url, bauds, bits, window, budget, probe)
    rec = result.as_dict()
    fmt = resolve_format(fmt, tty_default="table", pipe_default="json")
    if fmt == "table":
        _table(rec)
    else:
        import json

        click.echo(json.dumps(rec, ensure_ascii=False, separators=(",", ":") if fmt == "jsonl" else None,
                              indent=None if fmt == "jsonl" else 2))
    if not result.found:
        from ...api.detect import no_answer

        raise no_answer(result)


def _table(rec):
    from rich.table import Table

    from ...io.term import console_for

    console = console_for(sys.stdout)
    t = Table(title=f"ZK line settings on {rec['port']}", title_justify="left", show_header=False)
    t.add_column("")
    t.add_column("")
    if rec["found"]:
        t.add_row("line", f"{rec['baud']} baud, 8 data bits, no parity, {rec['stop_bits']} stop bit"
                          f"{'s' if rec['stop_bits'] == 2 else ''}")
        t.add_row("protocol version", "-" if rec["protocol_version"] is None else str(rec["protocol_version"]))
        t.add_row("status rate", "-" if rec["status_rate_hz"] is None else f"{rec['status_rate_hz']} Hz"
                  + (f" ({rec['frames_per_s']:g} frames/s measured)" if rec["frames_per_s"] else ""))
    else:
        t.add_row("line", "no status frames at any setting tried")
    t.add_row("time", f"{rec['elapsed_s']:g} s of a {rec['budget_s']:g} s budget")
    t.add_row("tried", ", ".join(f"{a['baud']}/{a['stop_bits']}: {a['verdict']}" for a in rec["tried"]))
    console.print(t)


def parse_baud_auto(value):
    """``-b`` for commands that allow ``auto``: an int or the string ``auto``."""
    if isinstance(value, int) or value is None:
        return value
    text = str(value).strip().lower()
    if text == "auto":
        return "auto"
    try:
        return int(text)
    except ValueError:
        raise UsageError(f"baud: {value!r}; allowed a baud rate (300..4000000) or auto") from None
