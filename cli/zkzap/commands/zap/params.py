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
        return zap.register(value)   # FieldValueError names the field and what is allowed

    def shell_complete(self, ctx, param, incomplete):
        from click.shell_completion import CompletionItem

        return [CompletionItem(r.name, help=r.help) for r in zap.REGISTERS if r.name.startswith(incomplete)]


class IdType(click.ParamType):
    """An actuator ID 0..253, or 254/'broadcast' where allowed."""

    name = "id"

    def __init__(self, allow_broadcast=True):
        self.allow_broadcast = allow_broadcast

    def convert(self, value, param, ctx):
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


REGISTER = RegisterType()
INT = IntValue()


def id_option(default=0, allow_broadcast=True, help=None):
    """``-i/--id`` (defined once, in :func:`zkzap.commands.options.id_option`)."""
    from ..options import id_option as option

    return option(default, allow_broadcast, help)
