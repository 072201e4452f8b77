"""``zk send KIND ...``: one sub-command per control command, generated from the codec's table.

Each field of :data:`zkzap.codec.zk.CONTROL` declares how the CLI takes it (``cli="--state"``
is an option, ``cli="VOLTS"`` an argument), its choices and its help, so this module holds no
protocol knowledge: it turns options into ``encode_control`` keywords and hands the frame to
:func:`deliver`.
"""

from __future__ import annotations

import click

from ...codec import zk
from ...codec.hexfmt import format_hex
from ...errors import UsageError
from .. import CONTEXT
from ..options import dry_run_option, note, port_options, protocol_version_option, warn, yes_option

#: Defaults for fields that are options; arguments are always required.
_OPTION_DEFAULTS = {("control", "sw"): None, ("control", "throttle_pct"): 0.0,
                    ("mode", "sw"): "none", ("mode", "rpm_factor"): 0}

EXAMPLES = {
    "keepalive": ["zk send keepalive -n                      # FF 00 00 00"],
    "control": ["zk send control --state run --throttle 50 -n   # FF 1D F4 70",
                "zk send control --state stop -p /dev/ttyUSB0"],
    "action": ["zk send action rate-50hz -n", "zk send action test-pump -p /dev/ttyUSB0 --yes"],
    "unlock": ["zk send unlock -n"],
    "ignition-voltage": ["zk send ignition-voltage 3.2 -n"],
    "accel-curve": ["zk send accel-curve 40 -n"],
    "mode": ["zk send mode --state run --rpm-factor 3 -n"],
    "rpm": ["zk send rpm 100000 --rpm-factor 3 -n          # value 3333 -> 99990 rpm"],
    "pressure": ["zk send pressure 1013 -n"],
}


def send_options(f):
    """Options every ``zk send`` sub-command shares."""
    f = protocol_version_option(f)
    f = yes_option(f)
    f = port_options("zk")(f)
    f = dry_run_option(f)
    return f


def deliver(frame: bytes, *, dry_run: bool, port, baud, timeout, sim, yes, protocol_version, **wire):
    """Print the frame (dry run) or send it."""
    if dry_run:
        click.echo(format_hex(frame))
        return
    if not port and not sim:
        raise UsageError("no port: give -p PORT (or set ZKZAP_ZK_PORT), --sim, or -n to print the frame")
    raise UsageError("sending needs the link layer, which this build does not include; use -n")


def _check_version(cmd, raw_param, protocol_version):
    if protocol_version is None:
        return
    need = cmd.since
    if cmd.name == "action":
        need = max(need, zk.ACTION_SINCE.get(raw_param, 1))
    if protocol_version < need:
        warn(f"{cmd.name} needs protocol version {need} or later; the ECU was given as {protocol_version}")


def _make(cmd):
    fields = [f for f in cmd.fields if f.cli]

    def callback(**kw):
        common = {k: kw.pop(k) for k in ("dry_run", "port", "baud", "timeout", "sim", "yes", "protocol_version")}
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
        deliver(frame, **common, **kw)

    params = []
    for f in fields:
        if f.cli.startswith("--"):
            default = _OPTION_DEFAULTS.get((cmd.name, f.key))
            if f.names is not None:
                choices = [n for v, n in f.names.items() if f.lo <= v <= f.hi]
                ptype = click.Choice(choices, case_sensitive=False)
                default = default if default is None else default
            else:
                ptype = click.FLOAT if f.decimals else click.INT
            params.append(click.Option([f.cli, f.key], type=ptype, default=default,
                                       required=default is None, show_default=default is not None,
                                       help=f"{f.help} [{f.describe_range()}]"))
        else:
            if f.names is not None:
                choices = [n for v, n in f.names.items() if f.lo <= v <= f.hi]
                ptype = click.Choice(choices, case_sensitive=False)
            else:
                ptype = click.FLOAT if f.decimals or callable(f.scale) or f.scale != 1 else click.INT
            params.append(click.Argument([f.key], type=ptype, metavar=f.cli, required=True))
    for p in cmd.params:
        params.append(click.Option([p.cli, p.key], type=click.IntRange(p.lo, p.hi), required=True,
                                   help=p.help))
    doc = _doc(cmd, fields)
    command = click.Command(cmd.name, callback=callback, params=params, help=doc,
                            short_help=cmd.help.split(" (")[0].rstrip("."), context_settings=CONTEXT,
                            no_args_is_help=False)
    return send_options(command)


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


@click.group(context_settings=CONTEXT)
def send():
    """Compose a control command and send it, or print it as hex with -n/--dry-run.

    \b
    Examples:
      zk send control --state run --throttle 50 -n    # FF 1D F4 70
      zk send action rate-50hz -n
      zk send raw 1 sw=3 throttle_pct=500 -n          # raw field values
    """


for _cmd in zk.CONTROL:
    send.add_command(_make(_cmd))


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


@send.command("raw", context_settings=CONTEXT)
@click.argument("cmd_id", metavar="ID", type=click.IntRange(0, 8))
@click.argument("assignments", nargs=-1, metavar="FIELD=VALUE...")
@send_options
def raw(cmd_id, assignments, **common):
    """Compose a control frame from raw field values, for one-off crafting.

    ID is the command ID 0..8. FIELD is a field key of that command ('zk fields' lists them;
    'sw', 'throttle_pct', 'param', 'rpm_value', ...) and VALUE its raw integer (0x.. accepted)
    or, for enumerations, a name. reserved_b1=N and reserved_b2=N set reserved bits.

    \b
    Examples:
      zk send raw 1 sw=3 throttle_pct=500 -n     # FF 1D F4 70
      zk send raw 7 rpm_value=4095 -n
      zk send raw 0 reserved_b2=0x55 -n          # a keep-alive with reserved bits set
    """
    frame = zk.encode_control_raw(cmd_id, **_parse_assignments(assignments))
    deliver(frame, **common)
