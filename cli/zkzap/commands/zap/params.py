"""Parameter types and options shared by the ``zap`` commands (register names, IDs)."""

from __future__ import annotations

import click

from ...codec import zap


class RegisterType(click.ParamType):
    """A register by name (completed from the map) or address."""

    name = "register"

    def convert(self, value, param, ctx):
        if isinstance(value, zap.Register):
            return value
        params = ctx.params if ctx is not None else {}
        if params.get("protocol", "ir") != "ir" or params.get("regmap") is not None:
            from ..options import zap_map

            return zap_map(ctx).register(value)   # the map --protocol/--map choose
        return zap.register(value)   # FieldValueError names the field and what is allowed

    def shell_complete(self, ctx, param, incomplete):
        from click.shell_completion import CompletionItem

        regs = zap.REGISTERS
        if ctx is not None and ctx.params.get("protocol") not in (None, "ir"):
            from ..options import zap_map

            regs = zap_map(ctx).registers
        return [CompletionItem(r.name, help=r.help) for r in regs if r.name.startswith(incomplete)]


class IdType(click.ParamType):
    """An actuator ID 0..253, or 254/'broadcast' where allowed."""

    name = "id"

    def __init__(self, allow_broadcast=True):
        self.allow_broadcast = allow_broadcast

    def convert(self, value, param, ctx):
        if ctx is not None and ctx.params.get("protocol") == "modbus":
            from ...codec import modbus

            return modbus.check_id(value, allow_broadcast=self.allow_broadcast)   # 1..247, 0 broadcast
        return zap.check_id(value, allow_broadcast=self.allow_broadcast)

    def shell_complete(self, ctx, param, incomplete):
        from click.shell_completion import CompletionItem

        return [CompletionItem("broadcast")] if self.allow_broadcast and "broadcast".startswith(incomplete) else []


class IntValue(click.ParamType):
    """An integer in decimal or 0x.. hex; the register decides the range."""

    name = "value"

    def convert(self, value, param, ctx):
        if isinstance(value, int):
            return value
        try:
            return int(str(value).strip(), 0)
        except ValueError:
            from ...codec.fields import FieldValueError

            label = param.human_readable_name.lower() if param else "value"
            raise FieldValueError(f"{label}: {value!r} is not an integer") from None


class NumberValue(IntValue):
    """An integer (decimal or 0x.. hex), or with ``--unit mm`` a finite decimal number: a
    position or speed the command converts (:func:`zkzap.commands.options.unit_scales`)."""

    name = "number"

    def convert(self, value, param, ctx):
        if isinstance(value, (int, float)):
            return value
        try:
            return super().convert(value, param, ctx)
        except click.BadParameter:
            raise
        except ValueError:
            import math

            try:
                v = float(str(value).strip())
            except ValueError:
                v = math.nan
            if not math.isfinite(v):
                from ...codec.fields import FieldValueError

                label = param.human_readable_name.lower() if param else "value"
                raise FieldValueError(f"{label}: {value!r} is not a number") from None
            return v


class InstructionType(click.ParamType):
    """An instruction by name (the documented eight and IR Robot's vendor codes) or code, read
    as register addresses are: ``0xF2`` and ``F2`` are hex, ``242`` decimal. Converts to the
    code."""

    name = "instruction"

    def convert(self, value, param, ctx):
        if isinstance(value, int):
            return value
        key = str(value).strip().lower()
        if ctx is not None and ctx.params.get("protocol") == "modbus":
            from ...codec import modbus

            by_name = {name: code for code, (name, _) in modbus.FUNCTIONS.items()}
            if key in by_name:
                return by_name[key]
            if key in zap.INSTRUCTION_BY_NAME:
                from ...errors import UsageError

                raise UsageError(f"instruction: {value!r} is an IR protocol instruction; a Modbus function is "
                                 f"{', '.join(by_name)} or a code 0x01..0x7F")
        ins = zap.INSTRUCTION_BY_NAME.get(key)
        if ins is not None:
            return ins.code
        try:
            # as register addresses: 0xF2 is hex, 242 decimal; bare hex with a letter (F2) is hex
            code = int(key, 10) if key.isdigit() else int(key, 0) if key.startswith("0x") else int(key, 16)
        except ValueError:
            from ...errors import UsageError

            names = ", ".join(i.cli for i in zap.INSTRUCTIONS + zap.VENDOR_INSTRUCTIONS)
            raise UsageError(f"instruction: unknown {value!r}; allowed {names} or a code 0x00..0xFF") from None
        if not 0 <= code <= 0xFF:
            from ...errors import UsageError

            raise UsageError(f"instruction: code {value} is out of range; allowed 0x00..0xFF")
        return code

    def shell_complete(self, ctx, param, incomplete):
        from click.shell_completion import CompletionItem

        if ctx is not None and ctx.params.get("protocol") == "modbus":
            from ...codec import modbus

            return [CompletionItem(name, help=f"{full} (0x{code:02X})") for code, (name, full) in
                    modbus.FUNCTIONS.items() if name.startswith(incomplete)]
        return [CompletionItem(i.cli, help=i.help) for i in zap.INSTRUCTIONS + zap.VENDOR_INSTRUCTIONS
                if i.cli.startswith(incomplete)]


class TargetType(click.ParamType):
    """``ID:VALUE`` (``2:2047``): an actuator (0..253) and a raw value; the register checks the
    value. Converts to ``(id, value)``."""

    name = "target"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        from ...errors import UsageError

        ident, sep, raw = str(value).partition(":")
        if not sep:
            raise UsageError(f"target: {value!r} is not ID:VALUE (for example 1:2047)")
        try:
            v = int(raw, 0)
        except ValueError:
            raise UsageError(f"target: value {raw!r} of {value!r} is not an integer") from None
        if ctx is not None and ctx.params.get("protocol") == "modbus":
            from ...codec import modbus

            return modbus.check_id(ident), v       # 1..247, 0 the broadcast (sync-move decides)
        return zap.check_id(ident, allow_broadcast=False), v


REGISTER = RegisterType()
INT = IntValue()
NUMBER = NumberValue()
INSTRUCTION = InstructionType()
TARGET = TargetType()


def id_option(default=0, allow_broadcast=True, help=None, *, writes=False):
    """``-i/--id`` (defined once, in :func:`zkzap.commands.options.id_option`)."""
    from ..options import id_option as option

    return option(default, allow_broadcast, help, writes=writes)
