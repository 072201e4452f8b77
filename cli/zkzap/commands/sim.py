"""``zkzap sim zk`` / ``zkzap sim zap``: run a built-in simulator on a pseudo-terminal or a TCP
socket, for scripts and tests without hardware.

The first line on stdout is the port to use (a pty path, or ``socket://HOST:PORT``), flushed at
once; the simulator serves until SIGINT or SIGTERM. The same devices run in-process behind
``sim://zk`` / ``sim://zap?ids=...`` URLs and the ``--sim`` option of the commands.
"""

from __future__ import annotations

import sys

import click

from ..errors import INTERRUPTED, OK, OUTPUT_ERROR, TERMINATED, UsageError
from . import CONTEXT, Group
from .complete import fault_kinds
from .options import Choice, FiniteRange, InputPath, IntRange, OutputPath, exits, protocol_option


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


def _check_link(ctx, param, value):
    if value and not ctx.resilient_parsing:
        from ..outfile import check_link

        check_link(value)            # before anything starts: only a symlink is ever replaced
    return value


def serve_options(f):
    f = click.option("--speed", type=FiniteRange(0.001, 10000, min_open=False), default=1.0,
                     show_default=True, metavar="X",
                     help="Run model time X times faster than real time (tests use 10 or more).")(f)
    f = click.option("--link", "link", type=OutputPath("link"), default=None, metavar="PATH", callback=_check_link,
                     help="With --pty: also make the pty available as a symlink at PATH (a new path, or an "
                          "old symlink: nothing else is replaced).")(f)
    f = click.option("--listen", callback=_listen, default=None, metavar="HOST:PORT",
                     help="Serve on a TCP socket instead (one client at a time, like a serial line: a "
                          "second is refused while the first is connected); port 0 picks a free "
                          "one. Connect with -p socket://HOST:PORT.")(f)
    f = click.option("--pty", "use_pty", is_flag=True,
                     help="Serve on a new pseudo-terminal (the default); connect with -p PATH.")(f)
    return f


def _serve(device, speed, use_pty, listen, link):
    from .. import checking
    from ..sim.base import Clock, keep_wire_time

    checking.effect("serve")
    from ..sim.serve import PtyUnsupported, serve_pty, serve_tcp

    if use_pty and listen:
        raise UsageError("--pty and --listen: choose one")
    if link and listen:
        raise UsageError("--link works with --pty only")
    clock = Clock(speed)
    keep_wire_time(device, clock)
    if listen:
        host, port = listen
        try:
            serve_tcp(device, clock, host, port)
        except OSError as e:
            device.close()
            raise UsageError(f"--listen: cannot listen on {host}:{port}: {e.strerror or e}") from None
    else:
        try:
            serve_pty(device, clock, link=link)
        except PtyUnsupported as e:
            device.close()
            raise UsageError(f"--pty: {e}") from None


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


#: A simulator serves until it is stopped: that is its normal end.
SIM_EXITS = exits({OK: "stopped by Ctrl-C or SIGTERM", INTERRUPTED: None, TERMINATED: None,
                   OUTPUT_ERROR: "the log (-o) could not be written"})


@SIM_EXITS
@sim.command("zk", context_settings=CONTEXT)
@click.option("--protocol-version", type=IntRange(1, 63), default=None, metavar="N",
              help="The protocol version the ECU reports (status ID 6).")
@click.option("--rate", type=Choice(["20", "50", "100"]), default=None,
              help="Status rate in Hz at power-up (the rate actions change it).")
@click.option("-b", "--baud", type=Choice(["2400", "4800", "9600", "19200", "38400", "57600", "115200"]),
              default=None,
              help="The ECU's UART speed (the document's list): a pty host at another speed reads "
                   "misframed garbage. Default: whatever the host uses.")
@click.option("--stop-bits", type=Choice(["1", "2"]), default=None,
              help="The ECU's stop bits (8 data bits, no parity; default 1): a pty host at another "
                   "setting reads garbage (the host's receiver is modelled strictly).")
@click.option("--set", "extra", multiple=True, callback=_parse_set, metavar="KEY=VALUE",
              help="Any other ECU simulator option (max_rpm, idle_rpm, battery, faults, ...); repeatable.")
@click.option("--replay", type=InputPath("zk capture"), default=None, metavar="CAPTURE",
              help="Play the ECU's status frames of a pcapng capture (--capture) at their recorded "
                   "times instead of the engine model.")
@click.option("--loop", is_flag=True, help="With --replay: start again at the end.")
@click.option("-o", "--output", type=OutputPath("records", formats=("jsonl", "csv")), default=None, metavar="FILE",
              help="With --replay: log the host's control frames, decoded, to FILE (JSON Lines; CSV "
                   "for *.csv).")
@serve_options
def zk(protocol_version, rate, baud, stop_bits, extra, replay, loop, output, speed, use_pty, listen, link):
    """The ZK turbine ECU simulator: status frames at the configured rate, an engine model
    that starts, runs, follows the throttle and cools down.

    With --replay CAPTURE it plays a recorded session instead: the ECU's frames of the capture at
    their recorded times (scaled by --speed; --loop to repeat), to whatever host connects; the
    host's control frames are decoded and, with -o FILE, logged.

    \b
    Examples:
      zkzap sim zk                               # prints /dev/pts/N
      zkzap sim zk --listen 127.0.0.1:0 --speed 10
      zkzap sim zk --protocol-version 4 --set max_rpm=120000
      zkzap sim zk --baud 9600 --stop-bits 2          # for 'zk detect'
      zkzap sim zk --replay flight.pcapng --loop -o host.jsonl
    """
    if replay is None:
        for name, value in (("loop", loop), ("output", output)):
            if value:
                raise UsageError(f"--{name}: only with --replay")
        for key, value in (("baud", baud), ("stop_bits", stop_bits)):
            if value is not None and key in extra:
                raise UsageError(f"--{key.replace('_', '-')} and --set {key}=...: give one")
        device = _make("zk", protocol_version=None if protocol_version is None else str(protocol_version),
                       rate=rate, baud=baud, stop_bits=stop_bits, **extra)
        _serve(device, speed, use_pty, listen, link)
        return
    if protocol_version is not None or rate is not None or extra or baud is not None or stop_bits is not None:
        raise UsageError("--replay plays a recording: --protocol-version, --rate, --baud, --stop-bits and --set "
                         "do not apply")
    from ..sim.replay import ZkReplay

    _check_capture(replay, "zk")
    log, close = _host_log(output)
    try:
        try:
            device = ZkReplay(replay, loop=loop, log=log)
        except ValueError as e:
            raise UsageError(f"--replay: {e}") from None
        _serve(device, speed, use_pty, listen, link)
    finally:
        close()


def _check_capture(path, protocol):
    from ..link.pcapng import check_capture

    check_capture(path, protocol)


def _host_log(output):
    """(log function, close function) for -o FILE: records flushed one by one."""
    if not output:
        return None, lambda: None
    from ..io.writers import make_writer
    from ..io import format_for_path
    from .options import open_output
    from .zk.decode import columns

    stream, had = open_output(output)
    fmt = format_for_path(output, ("jsonl", "csv"))
    writer = make_writer(fmt, stream, ["t", "dir"] + columns("control"), header=not had)

    def close():
        try:
            writer.close()
        finally:
            stream.close()

    return writer.write, close


def _say_collision(event) -> None:
    """One line on stderr for each collision on the simulated line."""
    who = " and ".join(f"ID {i}" for i in event["ids"]) or "an actuator"
    if event["kind"] == "host":
        what = f"the host transmitted while {who} {'was' if len(event['ids']) == 1 else 'were'} replying"
    else:
        what = f"{who} replied at once"
    click.echo(f"collision at {event['t']:.6f} s: {what} (both garbled)", err=True)


@SIM_EXITS
@sim.command("zap", context_settings=CONTEXT)
@click.option("--ids", default=None, metavar="LIST",
              help="Actuator IDs on the bus, like 1,2,5-8; ID@BAUD puts one at another baud rate; "
                   "an ID given twice makes two actuators that collide (default 0; 1 with --protocol modbus).")
@click.option("-b", "--baud", type=Choice(["9600", "19200", "38400", "57600", "115200"]), default="57600",
              show_default=True, help="The actuators' baud rate (a pty host at another rate is not heard).")
@click.option("--state", type=OutputPath("state"), default=None, metavar="FILE",
              help="Keep stored registers (and rod positions) in FILE across runs; when FILE exists "
                   "it defines the bus and --ids/--baud/--return-mode are not applied.")
@click.option("--return-mode", type=Choice(["0", "1", "2"]), default=None,
              help="Every actuator's feedback-return-mode at first start (default 1).")
@click.option("--voltage", type=FiniteRange(0, 25.5), default=None, metavar="VOLTS",
              help="Supply voltage (default 12.0; outside 7.0..13.0 sets the voltage error bit).")
@click.option("--echo", is_flag=True, help="Echo the host's bytes back, like a half-duplex adapter.")
@click.option("--turnaround", type=FiniteRange(0, 1000), default=None, metavar="MS",
              help="Milliseconds from a command's last byte to the reply's first (default 2, a 12Lf's "
                   "own; with a USB adapter's buffering 20-40 are ordinary).")
@click.option("--gap", type=FiniteRange(0, 100), default=None, metavar="MS",
              help="Milliseconds between two reply bytes, like a device or USB adapter that "
                   "trickles its bytes (default 0).")
@click.option("--fault", "faults", multiple=True, metavar="[ID:]KIND[=VALUE][/COUNT]", shell_complete=fault_kinds,
              help="Inject a fault (repeatable): overload, voltage[=V], silent, corrupt, truncate[=N], "
                   "wrong-id[=ID], delay=MS, stuck, echo. ID 'all' or none: every actuator; /COUNT: "
                   "only the next COUNT replies.")
@click.option("--replay", type=InputPath("zap capture"), default=None, metavar="CAPTURE",
              help="Answer every request recorded in a pcapng capture (--capture) with its recorded "
                   "reply, after its recorded latency; other requests go to the model.")
@protocol_option
@serve_options
def zap(ids, baud, state, return_mode, voltage, echo, turnaround, gap, faults, replay, protocol, speed, use_pty,
        listen, link):
    """The mightyZAP actuator-bus simulator: 12Lf actuators with the full register map, moving
    at goal speed, answering as their feedback-return mode says.

    With --protocol modbus: 17Lf actuators speaking Modbus RTU (IDs 1..247), with the 17Lf's
    control table; they answer every unicast request, with an exception reply for an unknown
    function (1), an address outside the table or a read-only register written (2), a count or
    value out of range (3), or a stored register written while the 'locked' fault holds (6).

    \b
    Fault examples:
      --fault 2:overload        ID 2 reports overload (bit 5) and cuts its force until restart
      --fault 3:silent          ID 3 never answers
      --fault 1:corrupt/1       ID 1's next reply has a bad checksum (then it recovers)
      --fault all:delay=30      every reply 30 ms late
      --fault 2:voltage=6.5     ID 2's supply at 6.5 V: voltage error bit in every reply
      --fault 1:locked          (modbus) ID 1's parameters are locked: stored writes get exception 6

    \b
    Examples:
      zkzap sim zap --ids 1,2,3                  # prints /dev/pts/N
      zkzap sim zap --ids 1,2 --listen 127.0.0.1:0 --state bus.json
      zkzap sim zap --ids 1 --echo --fault 1:delay=5
      zkzap sim zap --ids 1-4 --turnaround 20 --gap 1    # a slow device that trickles its bytes
      zkzap sim zap --replay field.pcapng        # a recorded bus, answered as recorded

    Timing: a command is heard once its last byte has crossed the line at the host's baud
    rate; the reply starts --turnaround ms later (5 ms more after a stored write) and takes its
    time on the wire plus --gap ms between bytes. The line is half-duplex: a host that
    transmits while an actuator is replying garbles both, as do two actuators replying at
    once; each such collision is reported on stderr.

    With --replay CAPTURE, a request recorded in the capture (the same ID, instruction and
    parameters) gets the reply recorded for it, after the recorded latency (several replies to
    one request play in order, then the last again; a request recorded without a reply stays
    unanswered); any other request goes to the model, whose actuators are --ids or, by
    default, the IDs that answered in the capture.
    """
    from ..sim.zap_actuators import parse_fault

    if protocol == "modbus" and (replay is not None or return_mode is not None):
        raise UsageError(f"{'--replay' if replay is not None else '--return-mode'}: not with --protocol modbus "
                         "(a 17Lf answers every unicast request; captures are of the IR protocol)")

    for text in faults:
        try:
            parse_fault(text)
        except ValueError as e:
            raise UsageError(f"--fault: {e}") from None
    recorded = None
    if replay is not None:
        from ..sim.replay import recorded_replies

        _check_capture(replay, "zap")
        recorded = recorded_replies(replay)
        ctx = click.get_current_context()
        if ids is None and recorded[1]:
            ids = ",".join(str(i) for i in sorted(recorded[1]))
    device = _make("zap", ids=ids, baud=baud, state=state, return_mode=return_mode,
                   voltage=None if voltage is None else str(voltage), echo="1" if echo else "0",
                   turnaround=None if turnaround is None else str(turnaround),
                   gap=None if gap is None else str(gap), faults=",".join(faults), protocol=protocol)
    if replay is not None:
        from ..sim.replay import ZapReplay

        device = ZapReplay(replay, device, recorded)
    getattr(device, "model", device).on_collision = _say_collision
    if state and getattr(device, "restored", False):
        shown = ", ".join(str(a.ident) for a in device.actuators)
        click.echo(f"note: {state}: {len(device.actuators)} actuator(s) restored (IDs {shown}); "
                   "--ids, --baud and --return-mode apply only to a new state file", err=True)
    _serve(device, speed, use_pty, listen, link)
    sys.stdout.flush()
