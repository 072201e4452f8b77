"""``zkzap sim zk`` / ``zkzap sim zap``: run a built-in simulator on a pseudo-terminal or a TCP
socket, for scripts and tests without hardware.

The first line on stdout is the port to use (a pty path, or ``socket://HOST:PORT``), flushed at
once; the simulator serves until SIGINT or SIGTERM. The same devices run in-process behind
``sim://zk`` / ``sim://zap?ids=...`` URLs and the ``--sim`` option of the commands.
"""

from __future__ import annotations

import sys

import click

from ..errors import UsageError
from . import CONTEXT, Group
from .complete import fault_kinds


def _listen(ctx, param, value):
    """``HOST:PORT``, ``[V6]:PORT``, ``:PORT`` or ``PORT`` -> (host, port); port 0 picks a free one."""
    if value is None:
        return None
    text = value.strip()
    host, port = "127.0.0.1", text
    if text.startswith("["):
        host, _, port = text[1:].partition("]")
        port = port.lstrip(":")
    elif ":" in text:
        host, _, port = text.rpartition(":")
        host = host or "127.0.0.1"
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 <= number <= 65535:
        raise UsageError(f"--listen: {value!r}; expected HOST:PORT with PORT 0..65535 (0 picks a free port)")
    return host, number


def serve_options(f):
    f = click.option("--speed", type=click.FloatRange(0.001, 10000, min_open=False), default=1.0,
                     show_default=True, metavar="X",
                     help="Run model time X times faster than real time (tests use 10 or more).")(f)
    f = click.option("--link", "link", type=click.Path(dir_okay=False), default=None, metavar="PATH",
                     help="With --pty: also make the pty available as a symlink at PATH.")(f)
    f = click.option("--listen", callback=_listen, default=None, metavar="HOST:PORT",
                     help="Serve on a TCP socket instead (one client at a time, like a serial line: a "
                          "second is refused while the first is connected); port 0 picks a free "
                          "one. Connect with -p socket://HOST:PORT.")(f)
    f = click.option("--pty", "use_pty", is_flag=True,
                     help="Serve on a new pseudo-terminal (the default); connect with -p PATH.")(f)
    return f


def _serve(device, speed, use_pty, listen, link):
    from ..sim.base import Clock
    from ..sim.serve import serve_pty, serve_tcp

    if use_pty and listen:
        raise UsageError("--pty and --listen: choose one")
    if link and listen:
        raise UsageError("--link works with --pty only")
    clock = Clock(speed)
    if listen:
        host, port = listen
        try:
            serve_tcp(device, clock, host, port)
        except OSError as e:
            device.close()
            raise UsageError(f"--listen: cannot listen on {host}:{port}: {e.strerror or e}") from None
    else:
        serve_pty(device, clock, link=link)


def _make(kind, **options):
    from ..sim import make_device

    try:
        return make_device(kind, **{k: v for k, v in options.items() if v is not None})
    except (ValueError, TypeError) as e:
        raise UsageError(f"sim {kind}: {e}") from None


@click.group(cls=Group, context_settings=CONTEXT)
def sim():
    """Run the built-in ECU or actuator-bus simulator on a pty or a TCP socket.

    The first stdout line is the port to use; the simulator serves until Ctrl-C or SIGTERM.

    \b
    Examples:
      zkzap sim zap --ids 1,2,3 > sim.port &     # first line: the port
      zap scan -p "$(head -1 sim.port)"
      zkzap sim zk --listen 127.0.0.1:5760
    """


def _parse_set(ctx, param, values):
    out = {}
    for item in values:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"--set: {item!r} is not KEY=VALUE")
        out[key.strip().replace("-", "_")] = value.strip()
    return out


@sim.command("zk", context_settings=CONTEXT)
@click.option("--protocol-version", type=click.IntRange(1, 63), default=None, metavar="N",
              help="The protocol version the ECU reports (status ID 6).")
@click.option("--rate", type=click.Choice(["20", "50", "100"]), default=None,
              help="Status rate in Hz at power-up (the rate actions change it).")
@click.option("--set", "extra", multiple=True, callback=_parse_set, metavar="KEY=VALUE",
              help="Any other ECU simulator option (max_rpm, idle_rpm, battery, faults, ...); repeatable.")
@serve_options
def zk(protocol_version, rate, extra, speed, use_pty, listen, link):
    """The ZK turbine ECU simulator: status frames at the configured rate, an engine model
    that starts, runs, follows the throttle and cools down.

    \b
    Examples:
      zkzap sim zk                               # prints /dev/pts/N
      zkzap sim zk --listen 127.0.0.1:0 --speed 10
      zkzap sim zk --protocol-version 4 --set max_rpm=120000
    """
    device = _make("zk", protocol_version=None if protocol_version is None else str(protocol_version),
                   rate=rate, **extra)
    _serve(device, speed, use_pty, listen, link)


@sim.command("zap", context_settings=CONTEXT)
@click.option("--ids", default="0", show_default=True, metavar="LIST",
              help="Actuator IDs on the bus, like 1,2,5-8; ID@BAUD puts one at another baud rate; "
                   "an ID given twice makes two actuators that collide.")
@click.option("-b", "--baud", type=click.Choice(["9600", "19200", "38400", "57600", "115200"]), default="57600",
              show_default=True, help="The actuators' baud rate (a pty host at another rate is not heard).")
@click.option("--state", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Keep stored registers (and rod positions) in FILE across runs; when FILE exists "
                   "it defines the bus and --ids/--baud/--return-mode are not applied.")
@click.option("--return-mode", type=click.Choice(["0", "1", "2"]), default=None,
              help="Every actuator's feedback-return-mode at first start (default 1).")
@click.option("--voltage", type=click.FloatRange(0, 25.5), default=None, metavar="VOLTS",
              help="Supply voltage (default 12.0; outside 7.0..13.0 sets the voltage error bit).")
@click.option("--echo", is_flag=True, help="Echo the host's bytes back, like a half-duplex adapter.")
@click.option("--fault", "faults", multiple=True, metavar="[ID:]KIND[=VALUE][/COUNT]", shell_complete=fault_kinds,
              help="Inject a fault (repeatable): overload, voltage[=V], silent, corrupt, truncate[=N], "
                   "wrong-id[=ID], delay=MS, stuck, echo. ID 'all' or none: every actuator; /COUNT: "
                   "only the next COUNT replies.")
@serve_options
def zap(ids, baud, state, return_mode, voltage, echo, faults, speed, use_pty, listen, link):
    """The mightyZAP actuator-bus simulator: 12Lf actuators with the full register map, moving
    at goal speed, answering as their feedback-return mode says.

    \b
    Fault examples:
      --fault 2:overload        ID 2 reports overload (bit 5) and cuts its force until restart
      --fault 3:silent          ID 3 never answers
      --fault 1:corrupt/1       ID 1's next reply has a bad checksum (then it recovers)
      --fault all:delay=30      every reply 30 ms late
      --fault 2:voltage=6.5     ID 2's supply at 6.5 V: voltage error bit in every reply

    \b
    Examples:
      zkzap sim zap --ids 1,2,3                  # prints /dev/pts/N
      zkzap sim zap --ids 1,2 --listen 127.0.0.1:0 --state bus.json
      zkzap sim zap --ids 1 --echo --fault 1:delay=5
    """
    from ..sim.zap_bus import parse_fault

    for text in faults:
        try:
            parse_fault(text)
        except ValueError as e:
            raise UsageError(f"--fault: {e}") from None
    device = _make("zap", ids=ids, baud=baud, state=state, return_mode=return_mode,
                   voltage=None if voltage is None else str(voltage), echo="1" if echo else "0",
                   faults=",".join(faults))
    if state and getattr(device, "restored", False):
        shown = ", ".join(str(a.ident) for a in device.actuators)
        click.echo(f"note: {state}: {len(device.actuators)} actuator(s) restored (IDs {shown}); "
                   "--ids, --baud and --return-mode apply only to a new state file", err=True)
    _serve(device, speed, use_pty, listen, link)
    sys.stdout.flush()
