"""``zap registers``: the mightyZAP 12Lf register map at the prompt, from :data:`zkzap.codec.zap.REGISTERS`."""

from __future__ import annotations

import click

from ...codec import zap
from .. import CONTEXT, Command
from ..options import Choice, format_option, protocol_options, resolve_format, write_rows, zap_map
from .params import REGISTER

COLUMNS = ["name", "address", "address_hex", "size", "access", "memory", "range", "lo", "hi", "unit", "scale",
           "default", "description"]
TABLE_COLUMNS = [("name", "name"), ("address_hex", "address"), ("size", "size"), ("access", "access"),
                 ("memory", "NV/V"), ("range", "range"), ("_unit", "unit"), ("default", "default"),
                 ("description", "description")]


def register_row(reg) -> dict:
    return {
        "name": reg.name, "address": reg.address, "address_hex": f"0x{reg.address:02X}", "size": reg.size,
        "access": reg.access, "memory": reg.memory or None, "range": reg.describe_range(), "lo": reg.lo,
        "hi": reg.hi, "unit": reg.unit or None, "scale": reg.scale, "default": reg.default,
        "description": reg.help,
    }


def _table_row(reg) -> dict:
    row = register_row(reg)
    # the terminal view gives the unit of one raw step ("0.1 V") where there is a scale
    row["_unit"] = (f"{reg.scale:g} {reg.unit}" if reg.scale != 1 else reg.unit) or None
    return row


@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("which", nargs=-1, metavar="[REGISTER...]", type=REGISTER)
@click.option("-w", "--writable", is_flag=True, help="Only registers that can be written.")
@click.option("--memory", type=Choice(["NV", "V"], case_sensitive=False), default=None,
              help="Only stored (NV, survive power off; writes wear memory) or volatile (V) registers.")
@format_option()
@protocol_options
def registers(which, writable, memory, fmt, protocol, regmap):
    """List the register map (12Lf, firmware 2.0 or later): name, address, size, access,
    NV (stored) or V (volatile), range, unit, default.

    REGISTER picks rows by name or address. Names are what 'zap load', 'zap store' and
    'zap decode' use; 2-byte values are little-endian. Registers with a scale (0.1 V) hold
    raw values: multiply by the scale for the unit. D7/D12/L12 actuators share most of the map.
    --protocol modbus lists the 17Lf's control table (16-bit registers, big-endian, one
    address each); --map FILE lists a map file's registers, after checking it.

    \b
    Examples:
      zap registers
      zap registers goal-position present-position
      zap registers --writable --memory NV -f csv
      zap registers -f jsonl | jq -r 'select(.access == "RW") | .name'
      zap registers --protocol modbus goal-position
    """
    regmap = zap_map()
    regs = list(which) if which else list(regmap.registers)
    if writable:
        regs = [r for r in regs if r.writable]
    if memory:
        regs = [r for r in regs if r.memory == memory.upper()]
    fmt = resolve_format(fmt)
    make = _table_row if fmt == "table" else register_row
    write_rows((make(r) for r in regs), COLUMNS, fmt, title=f"mightyZAP {regmap.model} registers"
               + ("" if regmap.protocol == "ir" else f" ({regmap.protocol})"),
               table_columns=TABLE_COLUMNS)
