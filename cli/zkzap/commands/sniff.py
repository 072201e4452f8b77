"""``zkzap sniff zk|zap``: watch a live link without taking part in it (nothing is ever written
to a port). The logic is :mod:`zkzap.api.sniff`; this module parses options and renders."""

from __future__ import annotations

import sys

import click

from ..errors import BAD_REPLY, DEVICE_ERROR, NO_REPLY, OK, OUTPUT_ERROR, PORT_ERROR
from . import CONTEXT, Command, Group
from .options import (DEFAULT_BAUD, ENV, STOP_BITS_HELP, BaudType, Choice, FiniteRange, IntRange,
                      OutputPath, capture_option, close_output, exits, open_output, protocol_options)


#: A sniffer only listens: it never waits for a reply, and decodes what it hears (no 5, 6); it
#: ends with 3 when what it heard is no device's.
SNIFF_EXITS = exits({OK: "done (--count, --duration)",
                     NO_REPLY: "no frame at all by the end (a silent line), or bytes that are noise, not frames, "
                               "for 2 s (a wrong baud rate or stop bits)",
                     PORT_ERROR: "a port cannot be opened, or failed or vanished",
                     DEVICE_ERROR: None, BAD_REPLY: None,
                     OUTPUT_ERROR: "the output or the capture could not be written"},
                    tail=" Every record already written stays whole.")

#: What sniff writes (``-f``, or named by the suffix of ``-o``).
SNIFF_FORMATS = ("table", "jsonl", "json", "csv")


@click.group(cls=Group, context_settings=CONTEXT)
def sniff():
    """Watch a live link passively: decode both directions, pair replies with requests.

    The sniffer only reads: no byte is ever written to a port. Records go to stdout (a table on a
    terminal, JSON Lines in a pipe, -f csv|json) or -o FILE; --capture FILE keeps every chunk
    in pcapng; on a terminal a live summary shows on stderr; --stats prints it at the end.

    \b
    Examples:
      zkzap sniff zap -p /dev/ttyUSB0 --stats
      zkzap sniff zk -p /dev/ttyUSB0 -p /dev/ttyUSB1 -o link.jsonl --capture link.pcapng
    """


def _common(protocol):
    env = ENV[protocol]

    def deco(f):
        opts = [
            click.option("-p", "--port", "ports", multiple=True, metavar="PORT",
                         help=("Serial device or pyserial URL; for a tapped link give two: the host's TX "
                               "line, then the ECU's; one port takes whatever mixture arrives."
                               if protocol == "zk" else
                               "Serial device or pyserial URL of an adapter on the bus (one: it sees both "
                               "directions).") + f" [env {env['port']}]"),
            click.option("-b", "--baud", type=BaudType(), envvar=env["baud"],
                         default=DEFAULT_BAUD[protocol], show_default=True, help=f"Baud rate [env {env['baud']}]."),
            click.option("--stop-bits", "stop_bits", type=Choice(["1", "2"]), envvar=env["stop_bits"],
                         default="1", show_default=True, callback=lambda ctx, param, v: int(v),
                         help=f"{STOP_BITS_HELP[protocol]} [env {env['stop_bits']}]."),
            capture_option(protocol),
            click.option("-f", "--format", "fmt", type=Choice(SNIFF_FORMATS), default=None,
                         help="Output format (default: table on a terminal, jsonl otherwise, or by the "
                              "extension of -o)."),
            click.option("-o", "--output", type=OutputPath("records", formats=SNIFF_FORMATS), default=None,
                         help="Write records to FILE (.csv, .json, .jsonl by its suffix; JSON Lines without one)."),
            click.option("--append", is_flag=True, help="Append to --output (a CSV gets no second header)."),
            click.option("-c", "--count", type=IntRange(1), default=None, metavar="N",
                         help="Stop after N records."),
            click.option("--duration", type=FiniteRange(0, min_open=True), default=None, metavar="SECONDS",
                         help="Stop after SECONDS."),
            click.option("--stats", "show_stats", is_flag=True,
                         help="Print the summary (frames/s per direction and ID, CRC errors, gaps, "
                              "slowest replies) on stderr at the end."),
            click.option("--stats-json", type=OutputPath("document"), default=None, metavar="FILE",
                         help="Write the summary as JSON to FILE at the end."),
        ]
        for o in reversed(opts):
            f = o(f)
        return f

    return deco


@SNIFF_EXITS
@sniff.command("zk", cls=Command, context_settings=CONTEXT)
@_common("zk")
@click.option("--protocol-version", type=IntRange(1, 63), default=None, metavar="N",
              help="ECU protocol version assumed until a status ID 6 frame reveals it (default 4).")
def zk(ports, baud, stop_bits, fmt, output, append, count, duration, show_stats, stats_json, protocol_version):
    """Sniff a ZK flight-controller <-> ECU link.

    With two receive-only adapters (-p HOST_TX -p ECU_TX) both directions are merged by time into
    one stream; with one port, control and status frames are told apart as they arrive. Records
    are 'zk decode' records with 'time', 't' (seconds since the start) and 'dir' (h2d: host to
    ECU, d2h: ECU to host); status frames decode in the ECU's own protocol version. A gap is a
    silence in the status stream longer than 3 status periods.

    \b
    Examples:
      zkzap sniff zk -p /dev/ttyUSB0 -p /dev/ttyUSB1
      zkzap sniff zk -p /dev/ttyUSB0 --duration 60 -f csv -o flight.csv --stats
    """
    from ..api.sniff import ZkSniffer
    from .zk.decode import columns, summary

    spec = _checked("zk", ports)
    sniffer = ZkSniffer(spec, baud, capture=_capture(), protocol_version=protocol_version, stop_bits=stop_bits)
    cols = ["time", "t", "dir"] + columns()
    _run(sniffer, cols, fmt, output, append, count, duration, show_stats, stats_json,
         table=lambda r: summary(r))


@SNIFF_EXITS
@sniff.command("zap", cls=Command, context_settings=CONTEXT)
@_common("zap")
@click.option("--reply-timeout", type=FiniteRange(0.001, 10), default=0.15, show_default=True,
              metavar="SECONDS", help="The late window: a request that expects an answer and gets none for "
                                      "this long is a missing reply (the window a host waits).")
@protocol_options
def zap(ports, baud, stop_bits, fmt, output, append, count, duration, show_stats, stats_json, reply_timeout,
        protocol, regmap):
    """Sniff a mightyZAP bus (one adapter sees both directions; nothing is sent).

    Every feedback is paired with the request it answers (the latest one to its ID whose late
    window is open, even when the host has moved on): 'latency_ms', 'request' and 'pairing'
    (ok, unexpected-id with 'expected_id', or unsolicited: an answer nobody asked for, like the
    acknowledgements official libraries leave unread in return mode 2). A request that expects
    an answer (Echo, Load Data, and anything to an ID seen acknowledging writes) and gets none
    within --reply-timeout gives a record of kind 'missing' with 'waited_ms'.

    With --protocol modbus the bus speaks Modbus RTU (the 17Lf): requests, replies and
    exception replies named by the register map (--map, else the 17Lf's), every unicast request
    expecting an answer; 'request' is the function answered, and --capture records the port as
    Modbus RTU (link type 149), which 'zap decode' and Wireshark follow.

    \b
    Examples:
      zkzap sniff zap -p /dev/ttyUSB0 --stats
      zkzap sniff zap -p /dev/ttyUSB0 -f csv -o bus.csv --capture bus.pcapng
      zkzap sniff zap --protocol modbus -p /dev/ttyUSB0 --capture bus.pcapng
    """
    from ..api.sniff import ModbusSniffer, ZapSniffer

    spec = _checked("zap", ports)
    tail = ["frame", "pairing", "request", "expected_id", "latency_ms", "waited_ms"]
    if protocol == "modbus":
        from ..codec import modbus
        from .options import zap_map

        sniffer = ModbusSniffer(spec, baud, capture=_capture(), reply_timeout=reply_timeout, stop_bits=stop_bits,
                                regmap=zap_map())
        cols, cell = ["time", "t", "dir"] + list(modbus.MODBUS_KEYS) + tail, _modbus_cell
    else:
        from ..codec import zap as zapc

        sniffer = ZapSniffer(spec, baud, capture=_capture(), reply_timeout=reply_timeout, stop_bits=stop_bits)
        cols, cell = ["time", "t", "dir"] + list(zapc.ZAP_KEYS) + tail, _zap_cell
    _run(sniffer, cols, fmt, output, append, count, duration, show_stats, stats_json, table=cell)


def _modbus_cell(rec):
    kind = rec["kind"]
    if kind == "missing":
        return f"no reply to {rec['request']} after {rec['waited_ms']:g} ms"
    parts = [rec.get("function") or rec.get("name") or kind]
    if kind == "exception":
        parts = [f"exception {rec.get('name')}"]
    if "register" in rec:
        parts.append(rec["register"] + (f"={rec['value']}" if "value" in rec else ""))
    if rec.get("latency_ms") is not None:
        parts.append(f"{rec['latency_ms']:g} ms")
    if rec.get("pairing") not in (None, "ok"):
        parts.append(rec["pairing"] + (f" (asked ID {rec['expected_id']})" if "expected_id" in rec else ""))
    return "  ".join(parts)


def _zap_cell(rec):
    kind = rec["kind"]
    if kind == "missing":
        return f"no reply to {rec['request']} after {rec['waited_ms']:g} ms"
    if kind == "command":
        what = rec["instruction"]
        if "register" in rec:
            what += f" {rec['register']}" + (f"={rec['value']}" if "value" in rec else "")
        return what
    parts = [",".join(rec["errors"]) or "ok"]
    if "register" in rec and "value" in rec:
        parts.append(f"{rec['register']}={rec['value']}")
    if rec.get("latency_ms") is not None:
        parts.append(f"{rec['latency_ms']:g} ms")
    if rec.get("pairing") not in (None, "ok"):
        parts.append(rec["pairing"] + (f" (asked ID {rec['expected_id']})" if "expected_id" in rec else ""))
    return "  ".join(parts)


def _checked(protocol, ports):
    """[(url, role)] of the -p values (or the environment's port), each port's name checked."""
    from ..api.sniff import check_ports
    from .options import warn_port

    spec = check_ports(protocol, _ports(ports, protocol))
    for url, _ in spec:
        warn_port(url)
    return spec


def _ports(ports, protocol):
    if ports:
        return ports
    import os

    env = os.environ.get(ENV[protocol]["port"])
    return [env] if env else []


def _capture():
    from ..link import capture

    req = capture.requested()
    capture.request(None, "zk")           # the sniffer taps its ports itself, with their directions
    return req[0] if req else None


class LineTable:
    """Records as aligned text lines on a terminal, one per record as it comes."""

    def __init__(self, stream, cell):
        self.stream = stream
        self.cell = cell
        self.count = 0

    def write_many(self, recs):
        lines = []
        for r in recs:
            lines.append(f"{r['t']:>10.3f}  {r.get('dir') or '?':<3}  {r['kind']:<8}  {r['id']:>3}  {self.cell(r)}")
        if lines:
            self.stream.write("\n".join(lines) + "\n")
            self.stream.flush()
            self.count += len(lines)

    def close(self):
        self.stream.flush()


def _run(sniffer, cols, fmt, output, append, count, duration, show_stats, stats_json, table):
    import time

    from ..io.term import is_tty
    from ..io.writers import make_writer
    from ..signals import SignalGuard

    if fmt is None and output and output != "-":
        from ..io import format_for_path

        fmt = format_for_path(output, SNIFF_FORMATS)
    if stats_json:
        from ..outfile import check_path

        check_path(stats_json, "stats-json")
    stream, had = open_output(output, append)
    if fmt is None:
        fmt = "table" if is_tty(stream) else "jsonl"
    if fmt == "table":
        writer = LineTable(stream, table)
    else:
        writer = make_writer(fmt, stream, cols, header=not had)
    live = _live(sniffer) if is_tty(sys.stderr) else None
    written = 0
    reason = failure = None
    try:
        with sniffer, SignalGuard() as guard:
            end = None if duration is None else time.monotonic() + duration
            shown = ", ".join(f"{url} ({role})" if role != "both" else url for url, role in sniffer.ports_spec)
            click.echo(f"note: sniffing {shown} at {sniffer.baud} baud; nothing is sent", err=True)
            if live is not None:
                live.start()
            while True:
                recs = sniffer.poll(0.05)
                if recs:
                    if count is not None:
                        recs = recs[:count - written]
                    writer.write_many(recs)
                    written += len(recs)
                if live is not None:
                    live.refresh()
                if count is not None and written >= count:
                    reason = "count"
                    break
                if end is not None and time.monotonic() >= end:
                    reason = "duration"
                    break
                failure = sniffer.noise()
                if failure is not None:
                    reason = "noise"
                    break
                if guard.signum is not None:
                    from ..signals import INTERRUPT_SIGNALS

                    # Ctrl-C, or Ctrl-Break on Windows, as in every session
                    reason = "interrupted" if guard.signum in INTERRUPT_SIGNALS else "terminated"
                    break
            rest = sniffer.drain()
            if rest and reason != "count":
                writer.write_many(rest)
    finally:
        if live is not None:
            live.stop()
        close_output(writer, stream)
    summary = sniffer.stats.summary(sniffer.elapsed())
    if show_stats:
        for line in stats_lines(summary):
            click.echo(line, err=True)
    if stats_json:
        import json

        from ..outfile import write_whole

        write_whole(stats_json, json.dumps(summary, indent=2) + "\n", what="stats-json")
    if reason == "interrupted":
        raise KeyboardInterrupt
    if reason == "noise":
        raise failure
    if not sniffer.frames_trusted and reason != "terminated":
        raise sniffer.silent()         # a silent line never passes
    if reason == "terminated":
        from ..signals import Terminated

        raise Terminated(guard.signum)


def stats_lines(s) -> list:
    lines = [f"sniffed {s['duration_s']:g} s: " + ", ".join(
        f"{d} {n} frames ({s['frames_per_s'][d]:g}/s)" for d, n in s["frames"].items()) if s["frames"]
        else f"sniffed {s['duration_s']:g} s: no frames"]
    if s["by_id"]:
        lines.append("by ID: " + ", ".join(f"{k.replace(':', ' ID ')}: {n}" for k, n in s["by_id"].items()))
    lines.append(f"CRC errors: {s['crc_errors']} ({s['skipped_bytes']} bytes skipped); gaps: {s['gaps']}"
                 + (f" (longest {s['longest_gap_s']:g} s)" if s["gaps"] else ""))
    if "replies" in s:
        lines.append(f"replies: {s['replies']}" + (f", mean {s['mean_latency_ms']:g} ms" if s["mean_latency_ms"] is not None else "")
                     + f"; missing {s['missing_replies']}, unexpected ID {s['unexpected_id']}, "
                       f"unsolicited {s['unsolicited']}")
        if s["slowest"]:
            lines.append("slowest: " + ", ".join(f"{x['latency_ms']:g} ms ({x['instruction']} ID {x['id']} "
                                                 f"at t={x['t']:g})" for x in s["slowest"]))
    return lines


def _live(sniffer):
    """The live summary on stderr (a terminal): rich, imported only here."""
    from rich.console import Console
    from rich.live import Live
    from rich.text import Text

    console = Console(file=sys.stderr)

    def render():
        now = sniffer.elapsed() if sniffer.t0 is not None else 0.0
        s = sniffer.stats.summary(now)
        rates = sniffer.stats.rates(now)
        head = "  ".join(f"{d}: {rates.get(d, 0)}/s" for d in sorted(set(s["frames"]) | set(rates), key=str))
        lines = [f"sniffing {now:.0f} s  {head or 'waiting for frames'}"] + stats_lines(s)[1:]
        return Text("\n".join(lines), style="dim")

    class _L:
        def __init__(self):
            self.live = Live(render(), console=console, refresh_per_second=4, transient=True,
                             redirect_stdout=False, redirect_stderr=False)
            self.next = 0.0

        def start(self):
            self.live.start()

        def refresh(self):
            import time

            if time.monotonic() >= self.next:
                self.live.update(render())
                self.next = time.monotonic() + 0.25

        def stop(self):
            self.live.stop()

    return _L()
