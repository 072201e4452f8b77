"""``zk send KIND ...``: one sub-command per control command, generated from the codec's table.

Each field of :data:`zkzap.codec.zk.CONTROL` declares how the CLI takes it (``cli="--state"``
is an option, ``cli="VOLTS"`` an argument), its choices and its help, so this module holds no
protocol knowledge: it turns options into ``encode_control`` keywords and hands the frame to
:func:`deliver`.
"""

from __future__ import annotations

import click

from ...codec import zk
from ...errors import DeviceError, UsageError
from .. import CONTEXT, Command, Group
from ..complete import raw_fields
from ..options import (Choice, FiniteFloat, FiniteRange, Integer, IntRange, SignedCommand, abort_option, apply_options,
                       authorize, dry_run_option, note, port_options, protocol_version_option, rate_option, warn,
                       yes_option)
from .stand import (alarm_options, alarm_settings, build_stand, check_output_dir, limit_options, logbook_option,
                    raise_for_status, report, sensor_options, session_sensors, summarizer, summary_option)
from .telemetry import (TIMEOUT_HELP, errors_text, log_options, reconnect_option, resolve_port, session_exits,
                        zk_timeout_help)

#: Defaults for fields that are options; arguments are always required.
_OPTION_DEFAULTS = {("control", "sw"): None, ("control", "throttle_pct"): 0.0,
                    ("mode", "sw"): "none", ("mode", "rpm_factor"): 0}

EXAMPLES = {
    "keepalive": ["zk send keepalive -n                      # FF 00 00 00",
                  "zk send keepalive -p /dev/ttyUSB0 --for 0 -o log.csv   # keep a pre-v5 ECU's link alive"],
    "control": ["zk send control --state run --throttle 50 -n   # FF 1D F4 70",
                "zk send control --state stop -p /dev/ttyUSB0",
                "zk send control --state run --throttle 30 --for 60 -p /dev/ttyUSB0 --yes -o run.csv",
                "zk send control --state run --throttle 30 --for 30 -p 'sim://zk?speed=10'"],
    "action": ["zk send action rate-50hz -n", "zk send action test-pump -p /dev/ttyUSB0 --yes"],
    "unlock": ["zk send unlock -n"],
    "ignition-voltage": ["zk send ignition-voltage 3.2 -n"],
    "accel-curve": ["zk send accel-curve 40 -n"],
    "mode": ["zk send mode --state run --rpm-factor 3 -n"],
    "rpm": ["zk send rpm 100000 --rpm-factor 3 -n          # value 3333 -> 99990 rpm"],
    "pressure": ["zk send pressure 1013 -n"],
}


#: Options that only mean something with --for, by parameter name -> how the user spells it.
_FOR_ONLY = {"rate": "--rate", "abort": "--abort", "end": "--end", "fmt": "--format", "output": "--output",
             "append": "--append", "snapshot": "--snapshot/--frames", "ids": "--ids", "raw_log": "--raw-log",
             "limit": "--limit", "limits_files": "--limits", "on_limit": "--on-limit", "logbook": "--logbook",
             "summary_json": "--summary-json", "reconnect": "--reconnect", "aux": "--aux",
             "thrust_from": "--thrust-from", "fuel_flow_from": "--fuel-flow-from", "ambient_temp": "--ambient-temp",
             "ambient_pressure": "--ambient-pressure", "air_pressure": "--air-pressure", "engine": "--engine",
             "restart_egt": "--restart-egt", "hung_start": "--hung-start", "hot_start": "--hot-start"}


def format_hex(frame) -> str:
    from ...codec.hexfmt import format_hex as fmt    # imported when used: a faster start

    return fmt(frame)


def send_options(f):
    """Options every ``zk send`` sub-command shares (on a click Command or a function)."""
    opts = [
        dry_run_option,
        port_options("zk"),
        yes_option,
        protocol_version_option,
        click.option("--for", "for_s", type=FiniteRange(0), default=None, metavar="SECONDS",
                     help="Keep sending at --rate for SECONDS (0: until Ctrl-C), writing the status "
                          "frames received meanwhile as 'zk monitor' does."),
        rate_option(help="With --for: frames per second (default 20)."),
        abort_option(help="With --for: what to send on Ctrl-C, SIGTERM, a port failure, a silent ECU, an "
                          "ECU error or a violated limit when the command controls the engine (default "
                          "standby: throttle 0, a hot engine cools); none sends nothing and says on stderr "
                          "that the engine is left running."),
        click.option("--end", type=Choice(["standby", "stop", "hold"]), default=None,
                     help="With --for SECONDS: what to send when the time is up, if the command controls "
                          "the engine (default standby: the abort sequence, throttle 0); hold sends nothing "
                          "more and leaves the engine at the command."),
        click.option("--no-wait", is_flag=True,
                     help="Send once and exit without waiting for a status frame (TX-only wiring)."),
        log_options,
        limit_options,
        alarm_options,
        sensor_options,
        logbook_option,
        summary_option,
        reconnect_option,
    ]
    f = apply_options(f, opts)
    if isinstance(f, click.Command):
        zk_timeout_help(f)
    else:
        for p in getattr(f, "__click_params__", ()):
            if p.name == "timeout":
                p.help = TIMEOUT_HELP
    return f


def deliver(frame: bytes, *, dry_run: bool, port, baud, timeout, sim, yes, protocol_version, stop_bits=1, for_s=None,
            rate=None, abort=None, end=None, no_wait=False, fmt=None, output=None, append=False, snapshot=None,
            ids=None, stale_after=3, raw_log=None, limit=(), limits_files=(), on_limit=None, logbook=None,
            summary_json=None, reconnect=None, aux=(), thrust_from=None, fuel_flow_from=None, ambient_temp=None,
            ambient_pressure=None, air_pressure=None, engine=None, rpm_factor=None, restart_egt=None, hung_start=None,
            hot_start=None):
    """Print the frame (dry run), send it once, or keep sending it ``for_s`` seconds while logging
    the status frames (as ``zk monitor``). Everything is checked before the port is opened; on a
    real port a frame that can start the engine or run hardware needs consent; a frame that needs
    the ECU's limits (an RPM target, a newer protocol version) is checked against what the ECU
    reports before it is sent (``rpm_factor``: the RPM_X of an ID 7 target)."""
    given = {k: v for k, v in (("rate", rate), ("abort", abort), ("end", end), ("fmt", fmt), ("output", output),
                               ("append", append or None), ("snapshot", snapshot), ("ids", ids),
                               ("raw_log", raw_log), ("limit", limit or None),
                               ("limits_files", limits_files or None), ("on_limit", on_limit),
                               ("logbook", logbook), ("summary_json", summary_json),
                               ("reconnect", reconnect), ("aux", aux or None), ("thrust_from", thrust_from),
                               ("fuel_flow_from", fuel_flow_from), ("ambient_temp", ambient_temp),
                               ("ambient_pressure", ambient_pressure), ("air_pressure", air_pressure),
                               ("engine", engine), ("restart_egt", restart_egt), ("hung_start", hung_start),
                               ("hot_start", hot_start)) if v is not None}
    if dry_run:
        if for_s is not None:
            raise UsageError("for: not with -n/--dry-run (nothing is sent)")
        for name in given:
            raise UsageError(f"{_FOR_ONLY[name].lstrip('-')}: not with -n/--dry-run (the frame is printed "
                             f"on stdout; nothing is sent)")
        if no_wait:
            raise UsageError("no-wait: not with -n/--dry-run (nothing is sent)")
        from .bridging import refuse_without

        refuse_without("--for (not with -n/--dry-run)")
        click.echo(format_hex(frame))
        return
    if for_s is None and given:
        raise UsageError(f"{_FOR_ONLY[next(iter(given))].lstrip('-')}: applies only with --for")
    if for_s is None:
        from .bridging import refuse_without

        refuse_without("--for")
    if for_s is not None and no_wait:
        raise UsageError("no-wait: not with --for")
    if end is not None and not for_s:
        raise UsageError("end: applies only with --for SECONDS (--for 0 runs until Ctrl-C; then --abort applies)")
    url = resolve_port(port, sim)
    from ...api.session import DEFAULT_ABORT, DEFAULT_END, controls_engine
    from ...api.telemetry import parse_ids
    from ...link.zk_port import is_simulator

    if end is not None and not controls_engine(frame):
        raise UsageError(f"end: {zk.decode_control(frame)['command']} does not control the engine, so its "
                         f"session ends without a command; --end applies to sessions that do")

    if ids is not None:
        parse_ids(ids)
    controls = controls_engine(frame)
    stand = None
    if for_s is not None:
        sensors = session_sensors(aux, thrust_from, fuel_flow_from, ambient_temp, ambient_pressure, air_pressure)
        stand = build_stand(limit=limit, limits_files=limits_files, on_limit=on_limit, logbook=logbook,
                            controls=controls, sensors=sensors, engine=engine,
                            alarms=alarm_settings(restart_egt, hung_start, hot_start))
        check_output_dir(summary_json, "summary-json", records_to_stdout=output in (None, "-"))
    allow = authorize([zk.ControlFrame(frame)], what=f"{format_hex(frame)} to {url}", yes=yes, force=False,
                      simulated=is_simulator(url))
    from ...api.prestart import Plan

    command = zk.decode_control(frame)["command"] or f"ID {frame[1] >> 4}"
    plan = Plan([frame], rpm_factor=rpm_factor, what=command)
    if for_s is None:
        _send_once(url, baud, frame, timeout, no_wait, stop_bits, plan, protocol_version, rpm_factor, allow)
        return
    from .monitor import run_telemetry

    title = f"zk send {describe_frame(frame)} on {url}"
    outcome, tel, session = run_telemetry(
        url=url, baud=baud, fmt=fmt, output=output, append=append, snapshot=snapshot, ids=ids,
        stale_after=stale_after, raw_log=raw_log, protocol_version=protocol_version, timeout=timeout,
        stop_bits=stop_bits, duration=for_s or None, control=lambda t: frame, rate=rate,
        abort=abort or DEFAULT_ABORT, stop_on_error=controls, title=title,
        end=(end or DEFAULT_END) if controls else None, end_label="end of --for",
        stand=stand, reconnect=reconnect, extra_outputs={"--summary-json": summary_json}, plan=plan, allow=allow,
        summarize=summarizer(stand, command=f"zk send {zk.decode_control(frame)['command']}", port=url))
    click.echo(summary_line(title.split(" on ")[0], outcome, tel, session), err=True)
    report(stand, command=f"zk send {zk.decode_control(frame)['command']}", port=url, files=(output, raw_log),
           outcome=outcome, tel=tel, session=session, summary_json=summary_json)
    raise_for_status(outcome, stand)
    if tel.errors:
        # an error the ECU latched before (or one seen while nothing controlled the engine): the
        # command did not do what it was asked, so the exit status says so
        raise DeviceError(errors_text(tel))


def summary_line(what, outcome, tel, session) -> str:
    """One line a person reads at the end of ``--for``: how long, how many frames, the peaks, the
    states passed through and the errors seen."""
    from ...api.telemetry import describe_error

    s = tel.summary()
    why = {"duration": "done", "interrupted": "interrupted", "terminated": "terminated",
           "port": "port failure", "silence": "ECU silent", "ecu-error": "ECU error",
           "pipe": "output closed"}.get(outcome.reason, outcome.reason)
    parts = [f"{what}: {session.ended_t or 0.0:.1f} s, {why}",
             f"{s['frames']} status frame{'' if s['frames'] == 1 else 's'}"]
    if s["max_rpm"] is not None:
        parts.append(f"max {s['max_rpm']:,} rpm")
    if s["max_egt_c"] is not None:
        parts.append(f"max EGT {s['max_egt_c']} °C")
    if s["fuel_used_l"] is not None:
        parts.append(f"fuel {s['fuel_used_l']:g} L")
    line = ", ".join(parts)
    if s["states"]:
        line += "; states " + " > ".join(s["states"])
    errors = "; ".join(describe_error(e["code"], e["name"], e["t"]) for e in s["errors"]) or "none"
    return line + f"; errors: {errors}"


def describe_frame(frame) -> str:
    """``control run 30 %`` for a dashboard title: the command and its fields, not raw hex."""
    rec = zk.decode_control(frame)
    parts = [rec.get("command") or f"id {rec['id']}"]
    for key, value in rec.items():
        if key in ("kind", "id", "command", "frame", "sw", "param", "reserved") or value is None:
            continue
        if key == "throttle_pct":
            parts.append(f"{value:g} %")
        elif isinstance(value, str):
            parts.append(value)
        else:
            parts.append(f"{key}={value:g}" if isinstance(value, float) else f"{key}={value}")
    return " ".join(parts)


def _send_once(url, baud, frame, timeout, no_wait, stop_bits, plan, protocol_version, rpm_factor, allow=None):
    """Write one frame (through the API's :class:`~zkzap.Ecu`, so the pre-start check applies,
    with the permissions ``allow``); unless ``no_wait``, wait for a status frame to show the ECU
    is there. An engine left running is said on stderr: a one-shot command sends no abort."""
    from ...api.session import DEFAULT_SILENCE_S
    from ...api.zk import Ecu
    from ...errors import NoReply

    cf = zk.ControlFrame(frame)
    with Ecu(url, baud=baud, stop_bits=stop_bits, protocol_version=protocol_version, abort="none",
             silence=timeout if timeout is not None else DEFAULT_SILENCE_S, allow=allow) as ecu:
        ecu.check(plan, listen=not no_wait)
        ecu.send(cf, listen=not no_wait)
        left = cf.leaves(rpm_factor)
        if left:
            note(f"the engine is left {left}: a one-shot command sends no abort")
        if no_wait:
            return
        try:
            next(ecu.status(count=1))
        except NoReply as e:
            what = str(e) if e.facts.get("noise") else (
                f"no status frame came back from {url} within {e.timeout:g} s (check the port, baud rate "
                f"and wiring)")
            raise NoReply(f"sent {format_hex(frame)}, but {what}; --no-wait skips this check", **e.facts) from None


SEND_EPILOG = ("Once, the frame is sent and zk waits for one status frame (exit 3 if none comes within "
               "--timeout, default 2 s); a frame that leaves the engine running (state run, RPM mode, the "
               "pump on) says so on stderr, since a one-shot command sends no abort. With --for it is sent "
               "at --rate and the status frames are written as 'zk monitor' writes them; when SECONDS are "
               "up, a command that controls the engine ends with --end (default standby). A frame the ECU "
               "cannot follow (an RPM target above the max rpm it reports in status ID 6, a command newer "
               "than its protocol version) is refused before it is sent (exit 2): zk listens for status "
               "ID 6 first. On a real port a frame that can start the engine or run ECU hardware needs "
               "--yes (or a prompt on a terminal); sim:// and --sim never ask.")
#: The exit statuses of every 'zk send' command.
SEND_EXITS = session_exits("sent and a status frame came back, or --for ran its time",
                           "an ECU error code was seen during --for (a new one while the command controls the "
                           "engine ends it with the abort)",
                           "bad usage or input, or a frame the ECU's reported limits refuse (an RPM target above "
                           "its max rpm, a command newer than its protocol version): nothing was sent")


def _check_version(cmd, raw_param, protocol_version):
    if protocol_version is None:
        return
    need = cmd.since
    if cmd.name == "action":
        need = max(need, zk.ACTION_SINCE.get(raw_param, 1))
    if protocol_version < need:
        warn(f"{cmd.name} needs protocol version {need} or later; the ECU was given as {protocol_version}")


class FieldFloat(FiniteFloat):
    """A number for a control field with a scale (``throttle``, ``ignition-voltage``): finite;
    the field (``field``, its range and steps) is checked by the codec, which names it."""

    def __init__(self, field):
        self.field = field


class FieldInt(Integer):
    """An integer for a control field (``accel-curve``, ``pressure``); the codec checks it
    against ``field``'s range and names it."""

    def __init__(self, field):
        self.field = field


def _field_type(f):
    return FieldFloat(f) if f.decimals or callable(f.scale) or f.scale != 1 else FieldInt(f)


def _make(cmd):
    fields = [f for f in cmd.fields if f.cli]

    def callback(**kw):
        common = {k: kw.pop(k) for k in ("dry_run", "port", "baud", "timeout", "sim", "yes", "protocol_version",
                                         "stop_bits")}
        values = {}
        for f in fields:
            v = kw.pop(f.key)
            if v is None:
                raise UsageError(f"{f.label}: required; allowed {f.describe_range()}")
            values[f.key] = v
        for p in cmd.params:
            values[p.key] = kw.pop(p.key)
        frame, notes = zk.encode_control(cmd.name, **values)
        for n in notes:
            note(n)
        _check_version(cmd, frame[2], common["protocol_version"])
        deliver(frame, **common, **kw, rpm_factor=values.get("rpm_factor"))

    params = []
    for f in fields:
        if f.cli.startswith("--"):
            default = _OPTION_DEFAULTS.get((cmd.name, f.key))
            if f.names is not None:
                choices = [n for v, n in f.names.items() if f.lo <= v <= f.hi]
                ptype = Choice(choices, case_sensitive=False)
                default = default if default is None else default
            else:
                ptype = FieldFloat(f) if f.decimals else FieldInt(f)
            params.append(click.Option([f.cli, f.key], type=ptype, default=default,
                                       required=default is None, show_default=default is not None,
                                       help=f"{f.help} [{f.describe_range()}]"))
        else:
            if f.names is not None:
                choices = [n for v, n in f.names.items() if f.lo <= v <= f.hi]
                ptype = Choice(choices, case_sensitive=False)
            else:
                ptype = _field_type(f)
            params.append(click.Argument([f.key], type=ptype, metavar=f.cli, required=True))
    for p in cmd.params:
        params.append(click.Option([p.cli, p.key], type=IntRange(p.lo, p.hi), required=True,
                                   help=p.help))
    doc = _doc(cmd, fields)
    command = SignedCommand(cmd.name, callback=callback, params=params, help=doc,
                            short_help=cmd.help.split(" (")[0].rstrip("."), context_settings=CONTEXT,
                            no_args_is_help=False, epilog=SEND_EPILOG)
    return SEND_EXITS(send_options(command))


def _doc(cmd, fields):
    lines = [cmd.help, ""]
    for f in fields:
        if f.cli and not f.cli.startswith("--"):
            lines.append(f"{f.cli}: {f.help} [{f.describe_range()}].")
            lines.append("")
    if cmd.needs_unlock:
        lines += ["Send 'zk send unlock' first: the ECU ignores this command until unlocked.", ""]
    if cmd.since > 1:
        lines += [f"Needs ECU protocol version {cmd.since} or later.", ""]
    lines += ["\b", "Examples:"] + [f"  {e}" for e in EXAMPLES.get(cmd.name, [])]
    return "\n".join(lines)


class SendGroup(Group):
    """Builds a sub-command when it is first asked for: a control command from the codec table,
    or ``raw``; running one builds one (a faster start), help and completion list them all."""

    def list_commands(self, ctx):
        return sorted(set(super().list_commands(ctx)) | set(zk.CONTROL_BY_NAME) | {"raw"})

    def get_command(self, ctx, name):
        cmd = super().get_command(ctx, name)
        if cmd is None and (name in zk.CONTROL_BY_NAME or name == "raw"):
            cmd = _make(zk.CONTROL_BY_NAME[name]) if name != "raw" else _make_raw()
            self.add_command(cmd)
        return cmd


@click.group(cls=SendGroup, context_settings=CONTEXT)
def send():
    """Compose a control command and send it, or print it as hex with -n/--dry-run.

    \b
    Sent to a port (-p PORT, --sim), the frame goes once, or with --for SECONDS at --rate Hz while
    the ECU's status frames are written as 'zk monitor' writes them.

    \b
    Examples:
      zk send control --state run --throttle 50 -n    # FF 1D F4 70
      zk send action rate-50hz -n
      zk send raw 1 sw=3 throttle_pct=500 -n          # raw field values
      zk send control --state run --throttle 30 --for 20 --sim -f jsonl
    """


def _parse_assignments(pairs):
    out = {}
    for item in pairs:
        if "=" not in item:
            raise UsageError(f"field: {item!r} is not FIELD=VALUE")
        key, _, value = item.partition("=")
        value = value.strip()
        try:
            out[key.strip()] = int(value, 0)
        except ValueError:
            out[key.strip()] = value   # an enumeration name, checked by the codec
    return out


def _make_raw():
    return send_options(raw_command)


@SEND_EXITS
@click.command("raw", cls=Command, context_settings=CONTEXT, epilog=SEND_EPILOG)
@click.argument("cmd_id", metavar="ID", type=IntRange(0, 8))
@click.argument("assignments", nargs=-1, metavar="FIELD=VALUE...", shell_complete=raw_fields)
def raw_command(cmd_id, assignments, **common):
    """Compose a control frame from raw field values, for one-off crafting.

    ID is the command ID 0..8. FIELD is a field key of that command ('zk fields' lists them;
    'sw', 'throttle_pct', 'param', 'rpm_value', ...) and VALUE its raw integer (0x.. accepted)
    or, for enumerations, a name. reserved_b1=N and reserved_b2=N set reserved bits of bytes 1
    and 2: only bits no field of the command uses (others are refused).

    \b
    Examples:
      zk send raw 1 sw=3 throttle_pct=500 -n     # FF 1D F4 70
      zk send raw 7 rpm_value=4095 -n
      zk send raw 0 reserved_b2=0x55 -n          # a keep-alive with reserved bits set
    """
    frame = zk.encode_control_raw(cmd_id, **_parse_assignments(assignments))
    deliver(frame, **common)
