"""``zkzap web zap|zk``: a browser console for an actuator bus or an ECU (extra ``web``).

Thin: options -> the port, opened as every command opens it -> :mod:`zkzap.web` (the consoles
and their server) -> the URL on stdout.
"""

from __future__ import annotations

import re
import sys

import click

from ..errors import UsageError
from . import CONTEXT, Command, Group
from .options import Choice, FiniteRange, InputPath, port_options, protocol_version_option

#: Where a console listens unless told: loopback only; a busy port is followed by the next ones.
DEFAULT_LISTEN = "127.0.0.1:8470"
FALLBACK_PORTS = 10
TOKEN_RE = re.compile(r"^[A-Za-z0-9._~-]{8,200}$")
#: The actuators of ``--sim`` without ``--sim-ids``.
SIM_IDS = "1,2,3"


def parse_listen(text: str):
    """``HOST:PORT`` (``[::1]:8470`` for IPv6) -> (host, port); UsageError naming --listen."""
    m = re.match(r"^(?:\[([0-9A-Fa-f:.]+)\]|([^:\[\]]+)):(\d{1,5})$", text.strip())
    port = int(m.group(3)) if m else -1
    if not m or not 0 <= port <= 65535:
        raise UsageError(f"listen: {text!r} is not HOST:PORT (like 127.0.0.1:8470, 0.0.0.0:8470 or [::1]:0; "
                         f"port 0: a free one)")
    return (m.group(1) or m.group(2)), port


def read_token(token, token_file):
    """The token given: ``--token`` (or ZKZAP_WEB_TOKEN), or the first line of ``--token-file``
    (not both: exit 2)."""
    if token_file is None:
        return token
    if token is not None:
        raise UsageError("token-file: give --token or --token-file, not both (ZKZAP_WEB_TOKEN is --token)")
    from ..api.textfile import read_text

    lines = read_text(token_file, "token-file", limit=4096)[0].splitlines()
    first = lines[0].strip() if lines else ""
    if not first:
        raise UsageError(f"token-file: {token_file} has no token on its first line")
    return first


def check_access(listen, token):
    """(host, port, token, fallback): a non-loopback address needs a token (exit 2 without one);
    ``auto`` (or none, on loopback) generates one."""
    from ..web.server import is_loopback, new_token

    host, port = parse_listen(listen or DEFAULT_LISTEN)
    if token is None and not is_loopback(host):
        raise UsageError(f"listen: {host} is reachable from other machines: give --token SECRET (8 or more "
                         f"characters of A-Z a-z 0-9 . _ ~ -), or --token auto for a generated one")
    if token is None or token == "auto":
        token = new_token()
    elif not TOKEN_RE.match(token):
        raise UsageError("token: 8 to 200 characters of A-Z a-z 0-9 . _ ~ - (it goes into the URL)")
    return host, port, token, FALLBACK_PORTS if listen is None else 0


def web_options(f):
    opts = [
        click.option("--listen", metavar="HOST:PORT", default=None,
                     help=f"Address to serve on (default {DEFAULT_LISTEN}, or the next free port after it; "
                          "port 0: a free one). Any address other machines reach needs --token."),
        click.option("--token", metavar="SECRET", envvar="ZKZAP_WEB_TOKEN", default=None,
                     help="The secret every page and request must carry (in the printed URL, then a cookie); "
                          "'auto' generates one. Default on loopback: generated. On the command line it is "
                          "visible to every user of the machine (ps): give it in ZKZAP_WEB_TOKEN or with "
                          "--token-file instead."),
        click.option("--token-file", type=InputPath("token"), default=None, metavar="FILE",
                     help="Read the token from FILE (its first line; '-': stdin), where other users cannot "
                          "see it."),
        click.option("--open", "open_browser", is_flag=True, help="Open the console in the default browser."),
    ]
    for opt in reversed(opts):
        f = opt(f)
    return f


def _serve(console, listen, token, kind, port_label):
    from ..web import server

    host, port, token, fallback = check_access(listen, token)

    def announce(url):
        click.echo(url)
        try:
            sys.stdout.flush()
        except OSError:
            pass
        shown = "every interface" if host in ("0.0.0.0", "::") else host
        server.stderr(f"zkzap web {kind}: the console of {port_label} is served on {shown}; open the URL above "
                      f"(it carries the token). Ctrl-C ends it.")
        if console.hub is not None and _open_requested():
            import webbrowser

            webbrowser.open(url)

    console.on_log = lambda entry: server.stderr(f"web: {entry['text']}")
    server.serve(console, host=host, port=port, token=token, announce=announce, fallback_ports=fallback)
    if console.failure is not None:
        raise console.failure


def _open_requested() -> bool:
    ctx = click.get_current_context(silent=True)
    return bool(ctx and ctx.params.get("open_browser"))


@click.group(cls=Group, context_settings=CONTEXT)
def web():
    """A browser console for an actuator bus (zap) or an engine (zk), with live plots.

    The console prints its URL on stdout (the first line) and serves until Ctrl-C or SIGTERM.
    Every page and request needs the URL's token; the first page controls, the others watch.
    Needs the extra 'web' (pip install 'zkzap[web]').

    \b
    Examples:
      zkzap web zap -p /dev/ttyUSB0
      zkzap web zk --sim
      zkzap web zk -p /dev/ttyUSB0 --listen 0.0.0.0:8470 --token auto --limit 'egt_c<=850'
    """


def _make_zap():
    from .options import buses_option, fleet_option, protocol_options
    from .zap.compose import link_options

    @click.command("zap", cls=Command, context_settings=CONTEXT)
    @click.option("--rate", type=FiniteRange(0.5, 1000), default=30.0, show_default=True, metavar="HZ",
                  help="Polls of the actuators per second at most (the line may allow fewer).")
    @click.option("--scan-ids", "scan_ids", default=None, metavar="LIST",
                  help="The IDs the first scan searches, like 1-8 ('none': no scan at the start) [default: "
                       "0-253; 1-247 on Modbus RTU].")
    @web_options
    @buses_option("Serve one console")
    @lambda f: fleet_option(f, help="The fleet file naming the buses of --buses (name -> port, baud, ids) "
                                    "[env ZKZAP_ZAP_FLEET].")
    @link_options(several=True)
    @protocol_options
    def zap_web(rate, scan_ids, listen, token, token_file, open_browser, bus_names, fleet_file, **common):
        """Serve a browser console for the actuators on one port, or on several buses at once.

        It scans the bus (IDs and baud rates, with progress), lists the actuators with their
        identity and error bits, plots position, current and voltage live, moves each one with
        a slider or a number (several at once by Symmetric Store), shows the register table
        (volatile and stored, with units and ranges) and edits it, backs the fleet up to a
        file, compares a file with the bus and applies one, and runs each actuator's self-check.

        Consent is the command line's: on a real port a stored write, an apply, an ID or baud
        change and a check's full-stroke move ask for confirmation on the page; id, baud-rate,
        protocol-type and feedback-return-mode need 'force' ticked too (on every port). The
        page that controls is named on every page; the others watch.

        \b
        Examples:
          zkzap web zap -p /dev/ttyUSB0
          zkzap web zap --sim --sim-ids 1-6
          zkzap web zap -p /dev/ttyUSB0 --listen 0.0.0.0:8470 --token auto
          zkzap web zap --protocol modbus -p /dev/ttyUSB0      # 17Lf actuators
          zkzap web zap -p /dev/ttyUSB0 -p /dev/ttyUSB1        # two buses, one page
          zkzap web zap --fleet machine.json --buses left,right

        With --protocol modbus the page says so and its register table is the map's (--map, else
        the 17Lf's control table), edited with the same consent rules.

        With -p given more than once, or --buses and a --fleet file naming the buses, one console
        shows every bus: each bus's actuators listed under its name (an actuator is its bus and
        ID: two buses may both have an ID 1), each bus polled on its own thread, so a slow or
        dead bus holds up no other (a bus whose port fails is shown failed; the others go on).
        The bus chosen on the page is the one its register table, moves, packet panel, fleet
        file, check, play, teach and cycle act on, each bus with its own consent; STOP ALL stops
        every bus. The buses speak the one --protocol (a fleet file's buses, its protocol); a
        fleet file's bus first scans its own IDs unless --scan-ids is given.
        """
        from .. import web as webpkg
        from .zap.compose import _link_args, open_link
        from .zap.motion import several_buses

        modbus = common["protocol"] == "modbus"
        if modbus:
            from ..api.zap_modbus import ModbusBus as Bus
        else:
            from ..api.zap import Bus
        webpkg.require()
        token = read_token(token, token_file)
        check_access(listen, token)
        given = scan_ids is not None
        if scan_ids is None:
            scan_ids = "1-247" if modbus else "0-253"
        ids = None if scan_ids.strip().lower() == "none" else _ids(scan_ids)
        if several_buses(bus_names):
            console = _buses_console(Bus, bus_names, fleet_file, common, rate, ids, given)
            _serve(console, listen, token, "zap", "the buses " + ", ".join(
                p if n == p else f"{n} ({p})" for n, p in console.ports.items()))
            return
        if fleet_file:                    # read all the same: a bad file is refused, not ignored
            from ..api.fleet import read_document

            read_document(fleet_file)
        args = _link_args(common)
        if args["sim"] and not args["sim_ids"]:
            args["sim_ids"] = SIM_IDS
        link = open_link(ids=[1], **args)
        from ..web.zap_console import ZapConsole

        console = ZapConsole(Bus.over(link), rate=rate, scan_ids=ids, retries=common["retries"])
        _serve(console, listen, token, "zap", "sim" if common["sim"] else link.url)

    return zap_web


def _buses_console(Bus, bus_names, fleet_file, common, rate, ids, given):
    """The console of several buses: the buses of -p given more than once or of --buses (as
    every zap command takes them), each opened as those commands open theirs, with a console
    of its own; a fleet file's bus scans its IDs first unless --scan-ids says otherwise."""
    from ..web.zap_buses import BusesConsole
    from ..web.zap_console import ZapConsole
    from .zap.motion import bus_specs, open_spec

    specs = bus_specs(bus_names, fleet_file, common, "counts")
    opener = open_spec(common)
    consoles, ports = {}, {}
    try:
        for spec in specs:
            link = opener(spec)
            consoles[spec.name] = ZapConsole(Bus.over(link), rate=rate, retries=common["retries"],
                                             scan_ids=spec.ids if spec.ids and not given else ids)
            ports[spec.name] = spec.port
    except BaseException:
        for c in consoles.values():
            c.shutdown()
        raise
    return BusesConsole(consoles, ports)


def _ids(text):
    from ..codec import zap

    try:
        return zap.parse_id_list(text, "--scan-ids")
    except zap.FieldValueError as e:
        raise UsageError(str(e)) from None


LIMIT_HELP = ("A limit the engine must stay within: FIELD OP NUMBER with an optional warning band "
              "(egt_c<=850,warn=800; power_voltage_v>=7.2), as on the command line (FIELD/s: its change per "
              "second; ,when=running: only in those engine states; an --aux field). Shown on the page; a "
              "violation while the console runs the engine ends it with the abort (see --on-limit). Repeatable.")


def _recording_options(f):
    """Where a console's records go and what it records them with, as on the command line."""
    from ..io import SESSION_FORMATS
    from .options import OutputPath, apply_options
    from .zk.stand import alarm_options, logbook_option, sensor_options

    opts = [
        click.option("-o", "--output", type=OutputPath("records", formats=SESSION_FORMATS), default=None,
                     metavar="FILE",
                     help="Write every status record the console receives to FILE, in the format its suffix names "
                          "(.csv, .json, .jsonl, .lp, .mcap, .xlsx; JSON Lines without one), as 'zk monitor -o' "
                          "does: created or replaced by the first record, trips and rundowns marked."),
        click.option("--append", is_flag=True, help="Append to --output (a CSV gets no second header)."),
        alarm_options,
        sensor_options,
        logbook_option,
    ]
    return apply_options(f, opts)


def _make_zk():
    @click.command("zk", cls=Command, context_settings=CONTEXT)
    @click.option("--rate", type=FiniteRange(1, 200), default=20.0, show_default=True, metavar="HZ",
                  help="Control frames per second while the console runs the engine.")
    @click.option("--limit", "limit", multiple=True, metavar="EXPR", help=LIMIT_HELP)
    @click.option("--limits", "limits_files", multiple=True, type=InputPath("limits"), metavar="FILE",
                  help="Read limits from FILE: one EXPR per line, '#' comments. Repeatable.")
    @click.option("--on-limit", type=Choice(["abort", "warn"]), default=None,
                  help="A violated limit while the console runs the engine: abort (the default: the abort "
                       "command, standby) or warn (shown, the engine goes on).")
    @_recording_options
    @protocol_version_option
    @web_options
    @port_options("zk")
    def zk_web(rate, limit, limits_files, on_limit, protocol_version, listen, token, token_file, open_browser, port,
               baud, stop_bits, timeout, sim, output=None, append=False, restart_egt=None, hung_start=None, hot_start=None,
               aux=(), thrust_from=None, fuel_flow_from=None, ambient_temp=None, ambient_pressure=None,
               air_pressure=None, logbook=None, engine=None):
        """Serve a browser console for the ECU on one port.

        Every page shows the status stream live at the ECU's rate: gauges and time plots of
        rpm, EGT, thrust, throttle, fuel flow and voltages, the engine state and ECU errors, and
        the limits. The page that controls starts the engine (by throttle or in RPM mode),
        changes the throttle or target, and stops it; every page has the abort (standby,
        throttle 0). As at the end of every command's engine session, the engine is sent to
        standby when the controlling page closes or is silent for 1 s (the dead-man rule), when
        the ECU reports a new error or falls silent, when a limit is violated, and when the
        console ends.

        A trip (a violated limit, an ECU error, the abort, the dead-man rule, a hung or hot
        start) latches an alarm in the page's alarm list until the controlling page acknowledges
        it; meanwhile, and after a trip until the engine is at rest and cool (--restart-egt), a
        start is refused, and the first start after a trip is at setpoint 0.

        The console records as the command line does: -o FILE gets every status record (the
        rundown after a trip too, the trip marked), --logbook FILE the console's time as one run
        (--engine names the engine), --aux the external sensors merged into the records,
        --air-pressure the ECU's ESR request answered.

        On a real port a start asks for confirmation on the page (sim:// and --sim never ask);
        RPM mode needs protocol version 4 or later and a target within the ECU's max rpm.

        \b
        Examples:
          zkzap web zk -p /dev/ttyUSB0
          zkzap web zk -p 'sim://zk?speed=10'
          zkzap web zk -p /dev/ttyUSB0 --limit 'egt_c<=850,warn=800' --limit 'power_voltage_v>=7.2'
          zkzap web zk -p /dev/ttyUSB0 -o run.csv --logbook engine.db --engine K100-1234
        """
        from .. import web as webpkg
        from ..api.zk import Ecu
        from .zk.monitor import session_output
        from .zk.stand import alarm_settings, build_stand, session_sensors
        from .zk.telemetry import resolve_port

        webpkg.require()
        token = read_token(token, token_file)
        check_access(listen, token)
        sensors = session_sensors(aux, thrust_from, fuel_flow_from, ambient_temp, ambient_pressure, air_pressure)
        stand = build_stand(limit=limit, limits_files=limits_files, on_limit=on_limit, logbook=logbook,
                            controls=True, sensors=sensors, engine=engine, force=True,
                            alarms=alarm_settings(restart_egt, hung_start, hot_start))
        url = resolve_port(port, sim)
        silence = timeout if timeout is not None else 2.0
        stand.start(silence)             # the external sensors' first lines: a silent one is exit 3
        from ..api.stand import StandSession

        session = StandSession(stand)
        try:
            if output:
                record = session_output(None, output, append, None, None, f"zkzap web zk on {url}", stand,
                                        controls=True, view=False)
                record.path = output
                # the session's one sink of the records, written off the worker's path
                # (zkzap.offload): a stalled file never holds up the engine; a full queue ends the
                # session that runs (with its abort), never waits
                session.record(record, f"--output {output}", wait=False)
            ecu = Ecu(url, baud=baud, protocol_version=protocol_version, stop_bits=stop_bits, silence=silence)
        except BaseException:
            stand.close()
            session.close_output()
            raise
        from ..web.zk_console import ZkConsole

        console = ZkConsole(ecu, session=session, rate=rate, silence=silence)
        _serve(console, listen, token, "zk", "sim" if sim else url)

    for p in zk_web.params:
        if p.name == "timeout":
            p.help = ("Longest silence tolerated from the ECU while the console runs the engine (default 2 s); "
                      "longer ends the run with standby.")
    return zk_web


web.add_command(_make_zap())
web.add_command(_make_zk())
