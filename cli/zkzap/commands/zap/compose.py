"""The eight mightyZAP instructions: ``echo``, ``load``, ``store``, ``send``, ``execute``,
``factory-reset``, ``restart``, ``sync-move`` and ``raw``.

With ``-n/--dry-run`` each prints its packet(s) as hex, one per line; otherwise it sends them
through :func:`deliver` (or, for ``echo`` and ``load``, prints what comes back). The link
options (:func:`link_options`) are shared with ``zap scan``/``dump``/``move``/``set-id``/
``set-baud``.
"""

from __future__ import annotations

import os
import sys

import click

from ...codec import zap
from ...codec.hexfmt import format_hex, parse_hex
from ...errors import UsageError
from .. import CONTEXT, Command
from ..options import (Choice, FiniteRange, IntRange, Lazy, SignedCommand, dry_run_option, force_option, port_options,
                       protocol_options, zap_map, zap_yes_option as yes_option)
from .params import INSTRUCTION, INT, REGISTER, TARGET, id_option

RETURN_MODES = ("0", "1", "2", "auto")


def _check_sim_ids(ctx, param, value):
    if value is None:
        return None
    from ...sim.zap_actuators import parse_ids

    try:
        parse_ids(value)
    except ValueError as e:
        raise UsageError(f"--sim-ids: {e}") from None
    return value


def link_options(f=None, *, baud_type=None, baud_help=None, several=False):
    """Port, baud, timeout, --sim, return mode, retries, --sim-ids and -v for every command that
    talks to actuators. ``baud_type``/``baud_help`` replace -b/--baud's type (``zap scan``
    takes a list); ``several``: -p may be given again, for several buses at once."""
    if f is None:
        return lambda g: link_options(g, baud_type=baud_type, baud_help=baud_help, several=several)
    f = click.option("-v", "--verbose", is_flag=True,
                     help="Say on stderr what was sent and how the actuator acknowledged it.")(f)
    f = click.option("--sim-ids", metavar="LIST", default=None, callback=_check_sim_ids,
                     help="With --sim: the IDs on the in-process simulated bus, like 1,2,5-8 "
                          "(default: the IDs the command addresses).")(f)
    f = click.option("--retries", type=IntRange(0, 20), default=2, show_default=True,
                     help="Retries after no reply or a corrupted reply.")(f)
    f = click.option("--low-latency", "low_latency", is_flag=True,
                     help="Ask the serial driver for its low-latency mode (Linux: an FTDI adapter then "
                          "uses a 1 ms latency timer); a note says so where the port has none.")(f)
    f = click.option("--latency", type=FiniteRange(0, 5000), default=None, metavar="MS", envvar="ZKZAP_ZAP_LATENCY",
                     help="How long the actuators are known to take to answer (ms, adapter included), "
                          "before any reply is measured: a known slow setup; the wait widens when it "
                          "needs more [env ZKZAP_ZAP_LATENCY].")(f)
    f = click.option("--return-mode", type=Choice(RETURN_MODES), default="1", show_default=True,
                     envvar="ZKZAP_ZAP_RETURN_MODE",
                     help="The actuators' feedback-return-mode: 0 answers Echo only, 1 Load Data and "
                          "Echo, 2 every command; 'auto' asks the actuator first "
                          "[env ZKZAP_ZAP_RETURN_MODE].")(f)
    f = port_options("zap", several=several)(f)
    for param in f.__click_params__:
        if param.name == "timeout":
            param.help = ("The late window: how long after a request its reply may still begin, in seconds "
                          "(default 0.15, what IR Robot's libraries allow); nothing is sent before it has "
                          "closed.")
    if baud_type is not None:
        for param in f.__click_params__:
            if param.name == "baud":
                param.type = baud_type
                param.help = baud_help or param.help
                param.metavar = baud_type.name.upper()
    return f


def wire_options(f):
    """Options every instruction shares."""
    f = yes_option(f)
    f = link_options(f)
    f = dry_run_option(f)
    return f


def _say(message: str) -> None:
    click.echo(message, err=True)


def _emit(line: str) -> None:
    """A line of data on stdout, written straight: click.echo resolves and wraps the stream on
    every call, which a batch of reads pays on every line (about 60 us, of a 5 ms round trip)."""
    out = sys.stdout
    out.write(line + "\n")
    out.flush()


def targets_of(packets) -> list:
    """The actuator IDs packets address (for the default simulated bus)."""
    ids = set()
    for p in packets:
        ids.update(zap.Command(p).target_ids())
    return sorted(ids) or [0]


def require_port(port, sim, sim_ids=None) -> None:
    """Refuse a command without a port (exit 2), and say what is wrong with the port's name
    (once per run: :func:`zkzap.commands.options.warn_port`)."""
    check_sim_args(port, sim, sim_ids)
    if not port and not sim:
        raise UsageError("no port: give -p PORT (or set ZKZAP_ZAP_PORT), --sim, or -n to print the packet")
    if port and not sim:
        from ..options import warn_port

        warn_port(port)


#: Options that mean something only when packets are sent (how replies are read and shown).
WIRE_ONLY = {"fmt": "format", "physical": "physical", "length": None, "count": "count", "interval": "interval",
             "verify": "verify", "retries": "retries", "return_mode": "return-mode", "timeout": "timeout",
             "verbose": "verbose", "latency": "latency", "low_latency": "low-latency"}


def refuse_with_dry_run() -> None:
    """With -n nothing is sent: an option about sending or replies, given on the command line,
    would be ignored, so it is refused (exit 2)."""
    ctx = click.get_current_context(silent=True)
    if ctx is None or ctx.get_parameter_source("dry_run") != click.core.ParameterSource.COMMANDLINE:
        return                # -n not given on the command line (a default_map, a program)
    for p in ctx.command.params:
        spelled = WIRE_ONLY.get(p.name, "")
        if spelled and ctx.get_parameter_source(p.name) == click.core.ParameterSource.COMMANDLINE:
            raise UsageError(f"{spelled}: not with -n/--dry-run (nothing is sent; the packet is printed)")


def check_sim_args(port, sim, sim_ids) -> None:
    """-p and --sim exclude each other (as in zk); --sim-ids means something only with --sim."""
    if sim and port and not _port_from_env():
        raise UsageError("port: give -p PORT or --sim, not both")
    if sim_ids is not None and not sim:
        raise UsageError("sim-ids: applies only with --sim (a sim://zap?ids=... URL takes ids= itself)")


def _port_from_env() -> bool:
    ctx = click.get_current_context(silent=True)
    if ctx is None:
        return False
    try:
        return ctx.get_parameter_source("port") == click.core.ParameterSource.ENVIRONMENT
    except Exception:      # noqa: BLE001 - a context without that parameter
        return False


def grant(packets, *, port, sim, yes, force) -> "Permission":
    """The permissions the packets need, granted as the command line maps them (--force, and
    --yes or a prompt on a real port; see :func:`zkzap.commands.options.authorize`)."""
    from ...link.zap_bus import is_simulated
    from ..options import authorize

    cmds = [zap.Command(p) for p in packets]
    names = []
    for c in cmds:
        names += [n for n in c.stored_writes if n not in names]
    what = cmds[0].describe() if len(cmds) == 1 else f"{cmds[0].describe()} (and {len(cmds) - 1} more packets)"
    text = None
    if names:
        text = (f"this writes stored settings on {port} ({', '.join(names)}); they survive power-off "
                "and each write wears the actuator's memory")
    return authorize(cmds, what=what, yes=yes, force=force, simulated=sim or is_simulated(port), consent_text=text,
                     brief=", ".join(names) or None)


#: Library modules used only when packets are sent (a dry run never imports them).
_API_ZAP = Lazy("zkzap.api.zap")
_CHECKING = Lazy("zkzap.checking")
_PERMISSIONS = Lazy("zkzap.codec.permissions")
_SHARED = Lazy("zkzap.link.shared")
_ZAP_BUS = Lazy("zkzap.link.zap_bus")


def _lent():
    """The bus a batch or a shell lends its lines (:mod:`zkzap.link.shared`), or None; without
    importing the link layer when nothing lends one."""
    return None if "zkzap.link.shared" not in sys.modules else _SHARED().shared("zap")


def open_link(*, port, baud, timeout, sim, sim_ids, return_mode, retries, ids=(0,), probe=None, stop_bits=1,
              latency=None, low_latency=False, allow=None, protocol=None, regmap=None, **_):
    """Open the bus for a command; ``return_mode='auto'`` asks actuator ``probe`` first;
    ``allow``: the permissions its packets are given (see :func:`authorize`). When the command
    ends, a note says once how to lower a USB adapter's latency timer if the measured latency
    shows it."""
    lent = _lent()
    if protocol is None:                  # a command that speaks the IR protocol only
        from ..options import PROTOCOL_ENV

        if os.environ.get(PROTOCOL_ENV, "ir").strip().lower() not in ("", "ir"):
            raise UsageError(f"{PROTOCOL_ENV}={os.environ[PROTOCOL_ENV]}: this command speaks the IR protocol only "
                             "(not yet Modbus RTU); unset it for this command")
        protocol = "ir"
    modbus = protocol == "modbus"
    mode = 1 if return_mode == "auto" or modbus else int(return_mode)
    latency = None if latency is None else latency / 1000.0      # --latency is in ms
    if lent is not None:            # a batch: every command over the one open port
        # (the batch checked its port, and said so once)
        lent_protocol = getattr(getattr(lent, "family", None), "name", "ir")
        if lent_protocol != protocol:
            raise UsageError(f"--protocol {protocol}: this batch's port speaks {lent_protocol} (give the batch "
                             f"--protocol {protocol})")
        if modbus and regmap is not None and regmap.path != lent.regmap.path:
            raise UsageError("--map: give it to the batch or shell (its port reads one register map)")
        _CHECKING().effect("port", ids=list(ids))
        bus = _SHARED().Borrowed(lent, return_mode=lent.return_mode if modbus else mode,
                                 retries=_ZAP_BUS().RETRIES if retries is None else retries,
                                 timeout=timeout, latency=latency if latency is not None else lent.latency,
                                 allow=_PERMISSIONS().as_permission(allow))
        if not modbus and return_mode == "auto" and probe is not None and probe != zap.BROADCAST:
            lent.detect_return_mode(probe)
        return bus
    require_port(port, sim, sim_ids)
    _CHECKING().effect("port", ids=list(ids))
    if sim and port:
        port = None                      # an explicit --sim beats the environment's default port
    default_ids = ",".join(str(i) for i in ids if i or not modbus)
    sim_opts = {"return_mode": return_mode} if sim and return_mode in ("0", "2") else None
    bus = _ZAP_BUS().open_bus(port, baud, sim=sim, sim_ids=sim_ids or default_ids, timeout=timeout,
                              return_mode=mode, retries=retries, sim_options=sim_opts, stop_bits=stop_bits,
                              latency=latency, low_latency=low_latency, allow=allow, protocol=protocol,
                              regmap=regmap)
    from ..hints import adapter_notes

    adapter_notes(bus)
    if not modbus and return_mode == "auto" and probe is not None and probe != zap.BROADCAST:
        try:
            bus.detect_return_mode(probe)
        except BaseException:
            bus.close()
            raise
    return bus


def describe(pkt: bytes) -> str:
    """One human line for a command packet: 'store goal-position=2047 to ID 1'."""
    return zap.Command(pkt).describe()


def acknowledgement(pkt: bytes, reply, bus) -> str:
    if reply is not None:
        return f"acknowledged in {reply.rtt * 1000:.1f} ms" + (f", errors: {', '.join(reply.errors)}"
                                                               if reply.error else "")
    if pkt[3] == zap.BROADCAST:
        return "not acknowledged (a broadcast is never answered)"
    mode = bus.mode_of(pkt[3])
    meaning = zap.REGISTER_BY_NAME["feedback-return-mode"].choices.get(mode, "?")
    return f"not acknowledged (feedback-return-mode {mode}: {meaning})"


def _print_dry(packets, port, sim, sim_ids) -> None:
    """-n: the packets as hex, one a line, nothing sent (options about sending refused)."""
    check_sim_args(port, sim, sim_ids)
    refuse_with_dry_run()
    for p in packets:
        _emit(format_hex(p))


def deliver(packets, *, dry_run, port, baud, timeout, sim, yes, verbose=False, sim_ids=None, return_mode="1",
            retries=2, force=False, show_reply=False, verify=False, protocol=None, regmap=None, **wire):
    """Print the packets (dry run) or send them, each waiting for the reply the return mode
    gives. Error bits in a reply end with exit status 5 after every packet went out. ``verify``
    reads every written value back (exit 3 when nothing answers: the write is unconfirmed).
    ``protocol`` "modbus": the packets are Modbus RTU frames (:func:`deliver_modbus`)."""
    if protocol == "modbus":
        return deliver_modbus(packets, dry_run=dry_run, port=port, baud=baud, timeout=timeout, sim=sim, yes=yes,
                              verbose=verbose, sim_ids=sim_ids, return_mode=return_mode, retries=retries,
                              force=force, show_reply=show_reply, verify=verify, regmap=regmap, **wire)
    if dry_run:
        return _print_dry(packets, port, sim, sim_ids)
    require_port(port, sim, sim_ids)                     # before any consent
    if verify:
        from ...link.zap_safety import check_verifiable

        check_verifiable(packets)
    allow = grant(packets, port=port, sim=sim, yes=yes, force=force)
    from ...link.zap_bus import device_error

    probe = next((p[3] for p in packets if p[3] != zap.BROADCAST), None)
    bad = None
    with open_link(port=port, baud=baud, timeout=timeout, sim=sim, sim_ids=sim_ids, return_mode=return_mode,
                   retries=retries, ids=targets_of(packets), probe=probe,
                   stop_bits=wire.get("stop_bits", 1), latency=wire.get("latency"),
                   low_latency=wire.get("low_latency", False), allow=allow, protocol=protocol) as bus:
        for p in packets:
            reply = bus.command(p, check=False)
            if show_reply and reply is not None:
                _emit(format_hex(reply.packet))
            if verbose or (reply is not None and reply.error):
                _say(f"sent {describe(p)}: {acknowledgement(p, reply, bus)}")
            if reply is not None and reply.error and bad is None:
                bad = reply
        if verify and bad is None:
            from ...link.zap_safety import verify_writes

            for ident, name, value in verify_writes(bus, packets):
                if verbose:
                    _say(f"ID {ident}: {name} reads back {value}")
    if bad is not None:
        raise device_error(bad)


def deliver_modbus(frames, *, dry_run, port, baud, timeout, sim, yes, verbose=False, sim_ids=None, retries=2,
                   force=False, show_reply=False, verify=False, regmap=None, needs=None, **wire):
    """:func:`deliver` for Modbus RTU frames (``--protocol modbus``), against the map
    (``--map``, else the 17Lf's): printed with -n, else their permissions decided before the
    port opens (``needs``: the command's own, ``{Permission: reason}``, beside the frames'), then
    sent one at a time, each unicast reply checked. An exception reply ends with exit status 5
    after every frame went out; ``verify`` reads every unicast write back."""
    from ...codec import modbus

    if dry_run:
        return _print_dry(frames, port, sim, sim_ids)
    require_port(port, sim, sim_ids)                     # before any consent
    regmap = regmap or zap_map()
    from ...link.zap_bus import is_simulated
    from ..options import authorize

    reqs = [modbus.Request(f) for f in frames]
    if verify:
        for r in reqs:
            if not r.writes or r.malformed:
                raise UsageError(f"--verify: {r.describe(regmap)} writes nothing that can be read back")
            if r.broadcast:
                raise UsageError("--verify: a broadcast (ID 0) write cannot be read back from every actuator; "
                                 "give the IDs")
    wanted = dict(needs or {})
    for r in reqs:
        for p, why in r.needs(regmap).items():
            wanted.setdefault(p, why)
    stored = []
    for r in reqs:
        for address, values in r.blocks():
            for a in range(address, address + len(values)):
                reg = regmap.owner.get(a)
                if reg is not None and reg.stored and reg.name not in stored:
                    stored.append(reg.name)
    what = reqs[0].describe(regmap) + (f" (and {len(reqs) - 1} more frames)" if len(reqs) > 1 else "")
    allow = authorize(wanted, what=what, yes=yes, force=force, simulated=sim or is_simulated(port),
                      consent_text=(f"this writes stored settings on {port} ({', '.join(stored)}); they survive "
                                    "power-off and each write wears the actuator's memory") if stored else None,
                      brief=", ".join(stored) or None)
    ids = sorted({r.ident for r in reqs if not r.broadcast}) or [0]
    bad = None
    with open_link(port=port, baud=baud, timeout=timeout, sim=sim, sim_ids=sim_ids, return_mode="1",
                   retries=retries, ids=ids, stop_bits=wire.get("stop_bits", 1), latency=wire.get("latency"),
                   low_latency=wire.get("low_latency", False), allow=allow, protocol="modbus",
                   regmap=regmap) as bus:
        for r in reqs:
            # a frame whose reply cannot be foretold (an unknown function) may go unanswered
            reply = bus.command(r.frame, check=False, optional=True if r.reply_length() is None else None)
            if show_reply and reply is not None:
                _emit(format_hex(reply.packet))
            if reply is not None and reply.exception:
                if verbose or len(reqs) > 1:
                    _say(f"sent {r.describe(regmap)}: exception {reply.error} "
                         f"({modbus.exception_meaning(reply.error)})")
                bad = bad or (reply, r)
            elif verbose:
                _say(f"sent {r.describe(regmap)}: " + (
                    "not acknowledged (a broadcast is never answered)" if r.broadcast
                    else "no reply" if reply is None else f"acknowledged in {reply.rtt * 1000:.1f} ms"))
        if verify and bad is None:
            from ...errors import CheckFailed

            for r in reqs:
                for address, values in r.blocks():
                    back = bus.read_values(r.ident, address, len(values))
                    for i, (want, got) in enumerate(zip(values, back)):
                        reg = regmap.owner.get(address + i)
                        name = reg.name if reg is not None else str(address + i)
                        if want != got:
                            raise CheckFailed(f"ID {r.ident}: {name} reads back {got}, not {want}", ident=r.ident,
                                              register=name, value=got)
                        if verbose:
                            _say(f"ID {r.ident}: {name} reads back {got}")
    if bad is not None:
        reply, r = bad
        raise modbus.ExceptionReply(reply.ident, r.function, reply.error)


# -- echo ----------------------------------------------------------------------------------------

ECHO_COLUMNS = ["id", "seq", "error", "errors", "rtt_ms"]


def _format(default, choices, what):
    from ..options import format_option

    return format_option(choices=choices, default=default, help=f"Output format: {what}.")


def _link_args(common):
    out = {k: common[k] for k in LINK_KEYS}
    out.update((k, common[k]) for k in PROTOCOL_KEYS if k in common)
    return out


def line_defaults(common) -> dict:
    """The defaults a batch or a shell gives each of its lines: its link options, its
    ``--protocol`` and its ``--map`` (by path)."""
    out = {k: common[k] for k in ("port", "baud", "timeout", "sim", "sim_ids", "return_mode", "retries", "verbose",
                                  "latency")}
    out["protocol"] = common.get("protocol") or "ir"
    regmap = common.get("regmap")
    if regmap is not None:
        out["regmap"] = regmap.path
    return out


def shared_bus_args(common, ids) -> dict:
    """open_link's arguments for the one bus a batch or a shell lends its lines."""
    args = _link_args(common)
    args["return_mode"] = "1" if common["return_mode"] == "auto" else common["return_mode"]
    if args.get("protocol") == "modbus":
        ids = [i for i in ids if i] or [1]
    args["ids"] = ids
    return args


#: The link options of every zap command, as open_link takes them (and --protocol, --map where the
#: command has them).
LINK_KEYS = ("port", "baud", "timeout", "sim", "sim_ids", "return_mode", "retries", "stop_bits", "latency",
             "low_latency")
PROTOCOL_KEYS = ("protocol", "regmap")


@click.command(cls=Command, context_settings=CONTEXT)
@id_option()
@click.option("-c", "--count", type=IntRange(0, None), default=1, show_default=True,
              help="Echo this many times, like ping (0: until Ctrl-C); a summary goes to stderr.")
@click.option("--interval", type=FiniteRange(0, 3600), default=0.0, metavar="SECONDS",
              help="Pause between echoes with --count.")
@_format("text", ("text", "table", "json", "jsonl", "csv"),
         "'text' prints one line per reply; the others give records with id, seq, error, errors, rtt_ms")
@wire_options
@protocol_options
def echo(ident, count, interval, fmt, **common):
    """Echo (0xF1): the actuator answers with a feedback packet (connection check).

    Every return mode answers Echo; a broadcast never. Prints one line per reply. With
    --count N it keeps going past lost replies, like ping, and ends with a summary on stderr;
    the exit status is 0 only if every echo was answered (3 if one was lost, 6 if one was
    garbled), 5 if a reply carried error bits.

    \b
    Examples:
      zap echo -n                 # FF FF FF 00 02 F1 0C
      zap echo --id 3 -p /dev/ttyUSB0
      zap echo --id 3 --count 100 -p /dev/ttyUSB0 -f jsonl | jq .rtt_ms
      zap echo --protocol modbus --id 1 -p /dev/ttyUSB0

    With --protocol modbus (no Echo there) the connection check is a read of the map's first
    register (the model number); an exception reply is an answer, its name in errors.
    """
    modbus = common["protocol"] == "modbus"
    if modbus:
        from ...codec import modbus as mb

        pkt = mb.read_registers(ident, zap_map().registers[0].address, 1) if ident else b""
    else:
        pkt = zap.echo(ident)
    if common["dry_run"] and pkt:
        return deliver([pkt], **{k: v for k, v in common.items() if k not in PROTOCOL_KEYS})
    if ident == (0 if modbus else zap.BROADCAST):
        raise UsageError("id: a broadcast Echo is never answered; give one actuator's ID")
    from ...errors import BadReply, NoReply
    from ...io.writers import make_writer
    from ...link import stop
    from ...link.zap_bus import device_error

    writer = None if fmt == "text" else make_writer(fmt, sys.stdout, ECHO_COLUMNS)
    sent = answered = lost = garbled = 0
    rtts = []
    failure = flagged = None
    try:
        with open_link(ids=[ident], **_link_args(common)) as bus:
            while count == 0 or sent < count:
                if sent and interval:
                    stop.pause(interval)       # a batch's stop request ends the wait early
                stop.check()                   # ... or ends it before the next echo
                sent += 1
                try:
                    r = bus.echo(ident, check=False, retries=None if count == 1 else 0)
                except (NoReply, BadReply) as e:
                    if count == 1:
                        raise
                    failure = e
                    if isinstance(e, NoReply):
                        lost += 1
                    else:
                        garbled += 1
                    _say(f"seq {sent}: {e}")
                    continue
                answered += 1
                if r.doubt is None:
                    rtts.append(r.rtt)
                if r.error and flagged is None:
                    flagged = r
                # a reply that may answer an earlier echo: answered, its round trip not known
                rec = {"id": r.ident, "seq": sent, "error": r.error, "errors": r.errors,
                       "rtt_ms": None if r.doubt else round(r.rtt * 1000, 3)}
                if writer is None:
                    state = ", ".join(r.errors) if r.error else "ok"
                    took = f"{rec['rtt_ms']:.1f} ms" if r.doubt is None else f"round trip unknown ({r.doubt})"
                    _emit(f"reply from ID {r.ident}: seq={sent} {state} {took}")
                else:
                    writer.write(rec)
    finally:                   # Ctrl-C (130) and SIGTERM (143) too: the summary, then the status
        if writer is not None:
            writer.close()
        if count != 1 and sent:
            summary = f"{sent} sent, {answered} answered, {lost} lost, {garbled} garbled"
            if rtts:
                summary += (f"; round trip min/avg/max {min(rtts) * 1000:.2f}/"
                            f"{sum(rtts) / len(rtts) * 1000:.2f}/{max(rtts) * 1000:.2f} ms")
            _say(summary)
    if flagged is not None:
        raise device_error(flagged)
    if failure is not None:
        raise failure.__class__(f"{lost + garbled} of {sent} echoes failed; last: {failure}")


# -- load ----------------------------------------------------------------------------------------

LOAD_COLUMNS = ["id", "register", "address", "value", "physical", "unit", "meaning", "errors"]


@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("regs", nargs=-1, required=True, metavar="REGISTER...", type=REGISTER)
@click.option("-l", "--length", type=IntRange(1, 253), default=None,
              help="Bytes to read from one REGISTER (default: its size); more bytes read the registers that "
                   "follow.")
@click.option("--physical", is_flag=True, help="Print scaled registers in their unit (present-voltage 12.0, not 120).")
@_format("value", ("value", "table", "json", "jsonl", "csv"),
         "'value' prints the bare value (for pos=$(zap load ...)); the others give records")
@id_option(allow_broadcast=True)
@wire_options
@protocol_options
def load(regs, length, physical, fmt, ident, **common):
    """Load Data (0xF2): read REGISTER (one Load Data each, when several are given).

    Prints the bare value of one register, or one NAME=VALUE line per register when several
    are given or --length spans several; --format json|jsonl|csv|table gives records with id,
    register, address, value (and physical/unit for scaled registers, meaning for coded ones).
    Error bits in a reply are reported on stderr and give exit status 5 after the values are
    printed.

    \b
    Examples:
      zap load present-position -n        # FF FF FF 00 04 F2 8C 02 7B
      zap load present-voltage --id 1 -p /dev/ttyUSB0 --physical
      pos=$(zap load present-position --id 1 -p /dev/ttyUSB0)
      zap load present-position present-current moving --id 1 --sim
      zap load model-number --length 17 --id 1 --sim -f json
      zap load --protocol modbus present-position --id 1 -n   # 01 03 00 D2 00 01 24 33

    With --protocol modbus: Read Holding Registers (0x03); --length counts registers (1..125).
    """
    if common["protocol"] == "modbus":
        return _modbus_load(regs, length, physical, fmt, ident, common)
    if length is not None and len(regs) > 1:
        raise UsageError(f"--length: reads from one REGISTER; {len(regs)} are given (each is read whole)")
    reads = []
    for reg in regs:
        size = reg.size if length is None else length
        if reg.address + size > 0x100:
            raise UsageError(f"--length: {size} bytes from 0x{reg.address:02X} run past address 0xFF; "
                             f"allowed 1..{0x100 - reg.address}")
        reads.append((reg, size))
    pkts = [zap.load(ident, reg, size) for reg, size in reads]
    if common["dry_run"]:
        return deliver(pkts, **common)
    if ident == zap.BROADCAST:
        raise UsageError("id: a broadcast Load Data is never answered; give one actuator's ID")
    if common["return_mode"] == "0":
        raise UsageError("--return-mode 0: Load Data is never answered in feedback-return-mode 0")
    with open_link(ids=[ident], probe=ident, **_link_args(common)) as bus:
        if bus.mode_of(ident) == 0:
            raise UsageError(f"ID {ident} is in feedback-return-mode 0: it answers Echo only, never Load Data")
        replies = [(reg, size, *bus.read_registers(ident, reg.address, size, check=False)) for reg, size in reads]
    register_records = _API_ZAP().register_records

    records, partial = [], []
    for reg, size, reply, values in replies:
        got = register_records(reply.ident, values, reply.errors)
        partial += _mark_partial(got, reg.address, size)
        records += got
    _load_output(records, fmt, physical, partial)
    if common["verbose"]:
        for pkt, (_, _, reply, _) in zip(pkts, replies):
            _say(f"sent {describe(pkt)}: {acknowledgement(pkt, reply, bus)}")
    for _, _, reply, _ in replies:
        if reply.error:
            raise _ZAP_BUS().device_error(reply)


def _load_output(records, fmt, physical, partial):
    """The records of a read: bare values (``fmt`` value) or records in ``fmt``."""
    if fmt == "value":
        for rec in records:
            v = rec["physical"] if physical and "physical" in rec else rec["value"]
            # a cut value is never printed bare, as if it were the register's whole value
            _emit(str(v) if len(records) == 1 and not partial else f"{rec['register']}={v}")
    else:
        from ...io.writers import make_writer

        writer = make_writer(fmt, sys.stdout, LOAD_COLUMNS)
        for rec in records:
            writer.write(rec)
        writer.close()


def _modbus_load(regs, length, physical, fmt, ident, common):
    from ...codec import modbus

    if length is not None and len(regs) > 1:
        raise UsageError(f"--length: reads from one REGISTER; {len(regs)} are given (each is read whole)")
    if length is not None and length > modbus.MAX_READ:
        raise UsageError(f"--length: {length} registers; one read carries 1..{modbus.MAX_READ}")
    regmap = zap_map()
    if ident == modbus.BROADCAST:
        raise UsageError("id: a broadcast read is never answered; give one actuator's ID (1..247)")
    count = 1 if length is None else length
    frames = [modbus.read(ident, reg, count, regmap) for reg in regs]
    if common["dry_run"]:
        return deliver(frames, **common)
    records = []
    with open_link(ids=[ident], **_link_args(common)) as bus:
        for reg in regs:
            _, values = bus.read_registers(ident, reg.address, count)
            records += _API_ZAP().register_records(ident, values, [])
    _load_output(records, fmt, physical, [])


def _mark_partial(records, address, length) -> list:
    """Records of registers that --length cut short get ``partial: true`` (their one byte read
    is the register's low byte), with a note on stderr. Returns them."""
    cut = [r for r in records if r["register"].endswith("(partial)")]
    if cut:
        from ..options import note
    for rec in cut:
        name = rec["register"][:-len("(partial)")]
        size = zap.REGISTER_BY_NAME[name].size
        rec["partial"] = True
        note(f"--length {length} from 0x{address:02X} reads 1 of {name}'s {size} bytes (its low byte): "
             f"the value shown is not the register's value")
    return cut
def _verify_option(name):
    """``--verify`` for the commands whose writes can be read back (store, sync-move)."""
    if name not in ("store", "sync-move"):
        return lambda f: f
    return click.option("--verify", is_flag=True,
                        help="Read every written value back: exit 3 when nothing answers (the write is "
                             "unconfirmed), 1 when it reads back different.")


#: Why an IR instruction has no Modbus RTU form (``--protocol modbus`` refused with it).
NO_MODBUS = {
    "send": "Modbus RTU has no Send Data (writes apply at once: zap store --protocol modbus)",
    "execute": "Modbus RTU has no Execution (writes apply at once: zap store --protocol modbus)",
    "factory-reset": "no source gives the 17Lf's factory reset a register or function",
    "restart": "no source gives the 17Lf's restart a register or function (a new baud rate applies at once)",
}


def _write_command(name, builder, doc):
    @click.command(name, cls=SignedCommand, context_settings=CONTEXT, help=doc)
    @click.argument("reg", metavar="REGISTER", type=REGISTER)
    @click.argument("value", metavar="VALUE", type=INT)
    @id_option(writes=True)
    @force_option
    @_verify_option(name)
    @wire_options
    @(protocol_options if name == "store" else protocol_options(ir_only=NO_MODBUS[name]))
    def command(reg, value, ident, force, verify=False, **common):
        if common.get("protocol") == "modbus":
            return _modbus_store(reg, value, ident, force, verify, common)
        deliver([builder(ident, reg, value)], force=force, verify=verify, **common)

    return command


def _modbus_store(reg, value, ident, force, verify, common):
    """``zap store --protocol modbus``: one Write Multiple Registers (see the manual's
    decisions), its permissions as on the IR protocol, the reply checked; ``--verify`` reads
    the value back."""
    from ...codec import modbus

    if verify and ident == modbus.BROADCAST:
        raise UsageError("--verify: a broadcast (ID 0) write cannot be read back; give one actuator's ID")
    frames = modbus.write_frames(ident, {reg.name: value}, zap_map(), force=force)
    deliver_modbus(frames, force=force, verify=verify, **{k: v for k, v in common.items() if k != "protocol"})


_WIRE_NOTE = """
Sent to a port, the write is acknowledged only in feedback-return-mode 2 (-v says how it went);
otherwise nothing confirms it, even with nothing attached to the port: 'zap store --verify' reads
the value back. Error bits in an acknowledgement give exit status 5. On a real port, writing a stored (NV)
register asks for consent (--yes); the simulator (--sim, sim://) and loop:// never ask (--force
is needed there too).
"""

store = _write_command("store", zap.store, """Store Data (0xF3): write VALUE to REGISTER.

VALUE is an integer in the register's units ('zap registers' lists ranges, bits and
choices), written little-endian in the register's size. Read-only registers and values outside
what the register documents are refused. Writing id, baud-rate or protocol-type needs --force
('zap set-id' and 'zap set-baud' check and verify instead), as does a value after which the
actuator stops answering (feedback-return-mode 0: Echo only) and addresses the map does not
document (0x05, lock) and an address inside a multi-byte register (0x87, goal-position's high
byte).
""" + _WIRE_NOTE + """
\b
Examples:
  zap store goal-position 2047 --id 1 -n     # FF FF FF 01 05 F3 86 FF 07 7A
  zap store goal-speed 512 --id 1 -n         # FF FF FF 01 05 F3 88 00 02 7C
  zap store short-stroke-limit 100 --id 1 -p /dev/ttyUSB0 --yes
""")

send_data = _write_command("send", zap.send_data, """Send Data (0xF4): stage VALUE for REGISTER; 'zap execute'
applies it.
""" + _WIRE_NOTE + """
\b
Examples:
  zap send goal-position 2047 --id 1 -n      # FF FF FF 01 05 F4 86 FF 07 79
  zap execute --id broadcast -n
""")


@click.command(cls=Command, context_settings=CONTEXT)
@id_option(writes=True)
@wire_options
@protocol_options(ir_only=NO_MODBUS["execute"])
def execute(ident, **common):
    """Execution (0xF5): apply the writes staged by 'zap send' (--id broadcast: every actuator
    at once; --id has no default).

    \b
    Examples:
      zap execute --id broadcast -n    # FF FF FF FE 02 F5 0A
      zap execute --id 1 -n            # FF FF FF 01 02 F5 07
    """
    deliver([zap.execute(ident)], **common)


@click.command("factory-reset", cls=Command, context_settings=CONTEXT)
@click.option("--reset-id", is_flag=True, help="Also reset the ID to 0 (option bit 0).")
@click.option("--reset-baud", is_flag=True, help="Also reset the baud rate to 57600 (option bit 1).")
@id_option(writes=True)
@force_option
@wire_options
@protocol_options(ir_only=NO_MODBUS["factory-reset"])
def factory_reset(reset_id, reset_baud, ident, force, **common):
    """Factory Reset (0xF6): restore the factory settings (the actuator then restarts).

    On a real port it asks for consent (--yes): every stored setting is overwritten. With
    --reset-id or --reset-baud it needs --force too (the actuator then answers at ID 0 or at
    57600 baud only, as a direct id or baud-rate write), and to every actuator at once (--id
    broadcast).

    \b
    Examples:
      zap factory-reset --id 1 --reset-id -n     # FF FF FF 01 03 F6 01 04
      zap factory-reset --id 1 -p /dev/ttyUSB0 --yes
    """
    deliver([zap.factory_reset(ident, reset_id, reset_baud)], force=force, **common)


@click.command(cls=Command, context_settings=CONTEXT)
@id_option(writes=True)
@wire_options
@protocol_options(ir_only=NO_MODBUS["restart"])
def restart(ident, **common):
    """Restart (0xF8) the actuator (a stored baud-rate change takes effect).

    \b
    Examples:
      zap restart --id 0 -n       # FF FF FF 00 02 F8 05
      zap restart --id 1 -p /dev/ttyUSB0
    """
    deliver([zap.restart(ident)], **common)


@click.command("sync-move", cls=Command, context_settings=CONTEXT)
@click.argument("targets", nargs=-1, required=True, metavar="ID:VALUE...", type=TARGET)
@click.option("-r", "--register", "reg", type=REGISTER, default="goal-position", show_default=True,
              help="Register written on every actuator.")
@force_option
@_verify_option("sync-move")
@wire_options
@protocol_options
def sync_move(targets, reg, force, verify, **common):
    """Symmetric Store (0x73) to broadcast: write one register of several actuators at once.

    One packet carries at most (255 - 4) / (1 + size) actuators (83 for a 2-byte register);
    more are split over as many packets as needed. A broadcast is never answered.

    With --protocol modbus (no multi-actuator write there) each ID gets one Write Multiple
    Registers, each answered and checked, every frame's permissions decided before the first
    goes out; 0:VALUE is one broadcast frame that moves every actuator on the bus, named or
    not, and is never answered: it needs --force.

    \b
    Examples:
      zap sync-move 1:1023 2:2047 -n    # FF FF FF FE 0A 73 86 02 01 FF 03 02 FF 07 F1
      zap sync-move 1:300 2:300 3:300 --register goal-speed -p /dev/ttyUSB0
      zap sync-move --protocol modbus 1:1000 2:2000 -n
      zap sync-move --protocol modbus 0:5000 --force --sim
    """
    if common["protocol"] == "modbus":
        from ...codec import modbus
        from ...codec.permissions import Permission

        regmap = zap_map()
        frames = modbus.sync_frames(reg, list(targets), regmap, force=force)
        needs = {}
        if any(i == modbus.BROADCAST for i, _ in targets):
            needs[Permission.BROADCAST] = ("0:VALUE is a broadcast: it reaches every actuator on the bus, named or "
                                           "not, and none answers")
        return deliver_modbus(frames, force=force, verify=verify, needs=needs,
                              **{k: v for k, v in common.items() if k != "protocol"})
    deliver(zap.symmetric_store(reg, list(targets)), force=force, verify=verify, **common)


@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("code", metavar="INSTRUCTION", type=INSTRUCTION)
@click.argument("params", nargs=-1, metavar="[PARAM...]")
@id_option(writes=True)
@force_option
@wire_options
@protocol_options
def raw(code, params, ident, force, **common):
    """Send any instruction with raw parameter bytes, for one-off crafting.

    INSTRUCTION is a name (echo, load, store, send, execute, factory-reset, restart, sync-move;
    the undocumented vendor codes system-write, status, sync-read, bulk-read, bulk-write) or a
    code: 0xF2 (hex), 242 (decimal, as register addresses are read) or F2. PARAMs are hex bytes
    in any notation (8C 02, 0x8C,0x02). Sent to a
    port, the reply packet (when one comes) is printed as hex; an unknown instruction waits for
    a reply but does not fail without one. The packet needs what it writes needs (see
    'zap store'): --yes on a real port for stored settings and for system-write (IR Robot's
    factory reset); --force for the id, baud-rate and protocol-type registers, addresses and
    values the map does not document, part of a multi-byte register, and any undocumented
    instruction but system-write.

    With --protocol modbus INSTRUCTION is a function: read (0x03), write (0x06),
    write-multiple (0x10) or any code 0x01..0x7F, and PARAMs are the bytes between the
    function and the CRC (which is appended). A frame that is not one of the three requests
    the actuator knows, or that writes what the map does not document, needs --force; the
    reply (an exception reply too, then exit 5) is printed as hex.

    \b
    Examples:
      zap raw load 8C 02 --id 0 -n   # FF FF FF 00 04 F2 8C 02 7B
      zap raw 0xF3 03 01 --id 0 -n   # FF FF FF 00 04 F3 03 01 04
      zap raw load 00 03 --id 1 -p /dev/ttyUSB0 | zap decode
      zap raw --protocol modbus read 00 D2 00 01 --id 1 -n   # 01 03 00 D2 00 01 24 33
      zap raw --protocol modbus 0x10 00 D0 00 02 04 03 E8 03 20 --id 1 -n
    """
    data = parse_hex(" ".join(params), what="params") if params else b""
    if common["protocol"] == "modbus":
        from ...codec import modbus

        if not 1 <= code <= 0x7F:
            raise UsageError(f"instruction: function 0x{code:02X} is out of range; a Modbus function is "
                             "0x01..0x7F (0x80 and up mark exception replies)")
        if len(data) + 4 > modbus.MAX_FRAME:
            raise UsageError(f"params: {len(data)} bytes; a Modbus RTU frame carries at most "
                             f"{modbus.MAX_FRAME - 4} between function and CRC")
        frame = modbus.frame(ident, bytes([code]) + data)
        return deliver_modbus([frame], force=force, show_reply=True,
                              **{k: v for k, v in common.items() if k != "protocol"})
    deliver([zap.packet(ident, code, data)], force=force, show_reply=True, **common)
