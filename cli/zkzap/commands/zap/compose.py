"""The eight mightyZAP instructions: ``echo``, ``load``, ``store``, ``send``, ``execute``,
``factory-reset``, ``restart``, ``sync-move`` and ``raw``.

With ``-n/--dry-run`` each prints its packet(s) as hex, one per line; otherwise it sends them
through :func:`deliver`.
"""

from __future__ import annotations

import click

from ...codec import zap
from ...codec.hexfmt import format_hex, parse_hex
from ...errors import UsageError
from .. import CONTEXT
from ..options import dry_run_option, port_options, yes_option
from .params import INT, REGISTER, id_option


def wire_options(f):
    """Options every instruction shares."""
    f = yes_option(f)
    f = port_options("zap")(f)
    f = dry_run_option(f)
    return f


def deliver(packets, *, dry_run, port, baud, timeout, sim, yes, **wire):
    """Print the packets (dry run) or send them."""
    if dry_run:
        for p in packets:
            click.echo(format_hex(p))
        return
    if not port and not sim:
        raise UsageError("no port: give -p PORT (or set ZKZAP_ZAP_PORT), --sim, or -n to print the packet")
    raise UsageError("sending needs the link layer, which this build does not include; use -n")


@click.command(context_settings=CONTEXT)
@id_option()
@wire_options
def echo(ident, **common):
    """Echo (0xF1): the actuator answers with a feedback packet.

    \b
    Examples:
      zap echo -n                 # FF FF FF 00 02 F1 0C
      zap echo --id 3 -p /dev/ttyUSB0
    """
    deliver([zap.echo(ident)], **common)


@click.command(context_settings=CONTEXT)
@click.argument("reg", metavar="REGISTER", type=REGISTER)
@click.option("-l", "--length", type=click.IntRange(1, 255), default=None,
              help="Bytes to read (default: the register's size).")
@id_option()
@wire_options
def load(reg, length, ident, **common):
    """Load Data (0xF2): read REGISTER.

    \b
    Examples:
      zap load present-position -n        # FF FF FF 00 04 F2 8C 02 7B
      zap load present-voltage --id 1 -p /dev/ttyUSB0
      pos=$(zap load present-position -p /dev/ttyUSB0)
    """
    deliver([zap.load(ident, reg, length)], **common)


def _write_command(name, builder, doc):
    @click.command(name, context_settings=CONTEXT, help=doc)
    @click.argument("reg", metavar="REGISTER", type=REGISTER)
    @click.argument("value", metavar="VALUE", type=INT)
    @id_option()
    @click.option("--force", is_flag=True, help="Allow protocol-type 0 (leaves the IR protocol).")
    @wire_options
    def command(reg, value, ident, force, **common):
        if reg.name == "protocol-type" and value == 0 and not force:
            raise UsageError("protocol-type: 0 switches the actuator to Modbus RTU and this tool can no "
                             "longer reach it; pass --force to do it anyway")
        deliver([builder(ident, reg, value)], **common)

    return command


store = _write_command("store", zap.store, """Store Data (0xF3): write VALUE to REGISTER.

VALUE is an integer in the register's units ('zap registers' lists ranges), written
little-endian in the register's size. Read-only registers and values out of range are refused.

\b
Examples:
  zap store goal-position 2047 --id 1 -n     # FF FF FF 01 05 F3 86 FF 07 7A
  zap store goal-speed 512 --id 1 -n         # FF FF FF 01 05 F3 88 00 02 7C
  zap store short-stroke-limit 100 --id 1 -p /dev/ttyUSB0 --yes
""")

send_data = _write_command("send", zap.send_data, """Send Data (0xF4): stage VALUE for REGISTER; 'zap execute' applies it.

\b
Examples:
  zap send goal-position 2047 --id 1 -n      # FF FF FF 01 05 F4 86 FF 07 79
  zap execute --id broadcast -n
""")


@click.command(context_settings=CONTEXT)
@id_option(default="broadcast")
@wire_options
def execute(ident, **common):
    """Execution (0xF5): apply the writes staged by 'zap send' (default: every actuator).

    \b
    Examples:
      zap execute -n              # FF FF FF FE 02 F5 0A
      zap execute --id 1 -n       # FF FF FF 01 02 F5 07
    """
    deliver([zap.execute(ident)], **common)


@click.command("factory-reset", context_settings=CONTEXT)
@click.option("--reset-id", is_flag=True, help="Also reset the ID to 0 (option bit 0).")
@click.option("--reset-baud", is_flag=True, help="Also reset the baud rate to 57600 (option bit 1).")
@id_option()
@wire_options
def factory_reset(reset_id, reset_baud, ident, **common):
    """Factory Reset (0xF6): restore the factory settings.

    \b
    Examples:
      zap factory-reset --id 1 --reset-id -n     # FF FF FF 01 03 F6 01 04
    """
    deliver([zap.factory_reset(ident, reset_id, reset_baud)], **common)


@click.command(context_settings=CONTEXT)
@id_option()
@wire_options
def restart(ident, **common):
    """Restart (0xF8) the actuator.

    \b
    Examples:
      zap restart -n              # FF FF FF 00 02 F8 05
    """
    deliver([zap.restart(ident)], **common)


def parse_targets(pairs):
    """``["1:1023", "2:2047"]`` -> ``[(1, 1023), (2, 2047)]``."""
    out = []
    for item in pairs:
        ident, sep, value = item.partition(":")
        if not sep:
            raise UsageError(f"target: {item!r} is not ID:VALUE (for example 1:2047)")
        try:
            v = int(value, 0)
        except ValueError:
            raise UsageError(f"target: value {value!r} of {item!r} is not an integer") from None
        out.append((zap.check_id(ident, allow_broadcast=False), v))
    return out


@click.command("sync-move", context_settings=CONTEXT)
@click.argument("targets", nargs=-1, required=True, metavar="ID:VALUE...")
@click.option("-r", "--register", "reg", type=REGISTER, default="goal-position", show_default=True,
              help="Register written on every actuator.")
@wire_options
def sync_move(targets, reg, **common):
    """Symmetric Store (0x73) to broadcast: write one register of several actuators at once.

    One packet carries at most (255 - 4) / (1 + size) actuators (83 for a 2-byte register);
    more are split over as many packets as needed.

    \b
    Examples:
      zap sync-move 1:1023 2:2047 -n    # FF FF FF FE 0A 73 86 02 01 FF 03 02 FF 07 F1
      zap sync-move 1:300 2:300 3:300 --register goal-speed -p /dev/ttyUSB0
    """
    deliver(zap.symmetric_store(reg, parse_targets(targets)), **common)


@click.command(context_settings=CONTEXT)
@click.argument("instruction", metavar="INSTRUCTION")
@click.argument("params", nargs=-1, metavar="[PARAM...]")
@id_option()
@wire_options
def raw(instruction, params, ident, **common):
    """Send any instruction with raw parameter bytes, for one-off crafting.

    INSTRUCTION is a name (echo, load, store, send, execute, factory-reset, restart, sync-move)
    or a code (0xF2, F2). PARAMs are hex bytes in any notation (8C 02, 0x8C,0x02).

    \b
    Examples:
      zap raw load 8C 02 -n          # FF FF FF 00 04 F2 8C 02 7B
      zap raw 0xF3 03 01 -n          # FF FF FF 00 04 F3 03 01 04
    """
    code = _instruction_code(instruction)
    data = parse_hex(" ".join(params), what="params") if params else b""
    deliver([zap.packet(ident, code, data)], **common)


def _instruction_code(text: str) -> int:
    key = text.strip().lower()
    ins = zap.INSTRUCTION_BY_NAME.get(key)
    if ins is not None:
        return ins.code
    try:
        code = int(key, 16) if not key.startswith("0x") else int(key, 0)
    except ValueError:
        names = ", ".join(i.cli for i in zap.INSTRUCTIONS)
        raise UsageError(f"instruction: unknown {text!r}; allowed {names} or a code 0x00..0xFF") from None
    if not 0 <= code <= 0xFF:
        raise UsageError(f"instruction: code {text} is out of range; allowed 0x00..0xFF")
    return code
