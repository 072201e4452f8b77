"""Shell completion of values, from the tables that define them (nothing retyped here).

Each function is a click ``shell_complete`` callback ``(ctx, param, incomplete) -> items``;
click imports :mod:`click.shell_completion` only while completing, and so do these.
"""

from __future__ import annotations


def _items(values, incomplete, help=None):
    from click.shell_completion import CompletionItem

    return [CompletionItem(v, help=(help or {}).get(v)) for v in values if v.startswith(incomplete)]


def files(ctx, param, incomplete):
    """A file name (the shell completes paths)."""
    from click.shell_completion import CompletionItem

    return [CompletionItem(incomplete, type="file")]


def binary_inputs(ctx, param, incomplete):
    """``zk decode``/``zap decode`` inputs: files with --binary, hex (nothing to offer) without."""
    if ctx.params.get("binary"):
        return files(ctx, param, incomplete)
    return []


def raw_fields(ctx, param, incomplete):
    """``zk send raw ID FIELD=VALUE``: the field keys of command ID (``sw=``, ``throttle_pct=``) and
    the reserved-bit keys; after ``=``, an enumeration's names."""
    from ..codec import zk

    cmd_id = ctx.params.get("cmd_id")
    if cmd_id is None:
        return []
    cmd = zk.control_command(cmd_id)
    key, eq, _ = incomplete.partition("=")
    if eq:
        field = next((f for f in cmd.fields if key in (f.key, f.raw_key, f.name_key)), None)
        if field is None or field.names is None:
            return []
        return _items([f"{key}={n}" for v, n in field.names.items() if field.lo <= v <= field.hi], incomplete)
    keys = [f"{f.raw_key or f.key}=" for f in cmd.fields]      # raw values: the raw key where one exists
    for byte, name in ((1, "reserved_b1"), (2, "reserved_b2")):
        if cmd.layout.reserved[byte] & (0x0F if byte == 1 else 0xFF):
            keys.append(f"{name}=")
    return _items(keys, incomplete)


def fault_kinds(ctx, param, incomplete):
    """``--fault [ID:]KIND[=VALUE][/COUNT]``: the fault kinds, after an ``ID:`` prefix if given."""
    from ..sim.zap_actuators import FAULT_HELP

    prefix, colon, rest = incomplete.rpartition(":")
    head = prefix + colon
    kinds = [k.split("[")[0].split("=")[0].strip() for k in FAULT_HELP.split(",")]
    return _items([head + k for k in kinds], incomplete)


def bauds(values):
    """A completion callback offering ``values`` (baud rates) and ``all``."""

    def complete(ctx, param, incomplete):
        head, comma, rest = incomplete.rpartition(",")
        head = head + comma
        return _items([head + str(v) for v in values] + ([] if head else ["all"]), incomplete)

    return complete
