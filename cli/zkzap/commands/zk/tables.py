"""``zk states``, ``zk errors``, ``zk fields``: the protocol's reference tables at the prompt.

Every row comes from the codec's tables (:mod:`zkzap.codec.zk`); nothing is retyped here.
"""

from __future__ import annotations

import click

from ...codec import zk
from ...codec.fields import bits_text, scale_text
from ...errors import UsageError
from .. import CONTEXT, Command
from ..options import Choice, IntRange, format_option, resolve_format, write_rows


def _lookup(table, text, what):
    """Rows of an appendix table picked by code or name (``11``, ``running``, ``egt``)."""
    out = []
    for item in text:
        key = item.strip().lower()
        try:
            code = int(key, 0)
        except ValueError:
            hits = [c for c, n in table.items() if n == key] or [c for c, n in table.items() if key in n]
            if not hits:
                raise UsageError(f"{what}: no {what} named {item!r}; 'zk {what}s' lists them") from None
            out += [c for c in hits if c not in out]
            continue
        if code not in table:
            raise UsageError(f"{what}: {code} is not in the table; allowed {min(table)}..{max(table)}")
        if code not in out:
            out.append(code)
    return out


class _TableName(click.ParamType):
    """A code or name of an appendix table (completes the names)."""

    name = "code|name"

    def __init__(self, table):
        self.table = table

    def shell_complete(self, ctx, param, incomplete):
        from click.shell_completion import CompletionItem

        return [CompletionItem(n, help=str(c)) for c, n in self.table.items() if n.startswith(incomplete)]


CODE_COLUMNS = ["code", "name", "description"]


def _write_codes(names, texts, which, what, fmt, title):
    """The rows of an appendix table (all, or those ``which`` picks) in ``fmt``."""
    codes = _lookup(names, which, what) if which else list(names)
    rows = ({"code": c, "name": names[c], "description": texts.get(c, "")} for c in codes)
    write_rows(rows, CODE_COLUMNS, fmt, title=title)


@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("which", nargs=-1, metavar="[CODE|NAME...]", type=_TableName(zk.ENGINE_STATES))
@format_option()
def states(which, fmt):
    """List the engine states of status ID 1 (engine_state, engine_state_name).

    CODE or NAME picks rows: a code, a name, or a part of a name (every state containing it).

    \b
    Examples:
      zk states
      zk states running -f csv
      zk states 11 -f json
      zk decode F1 E0 2E 0B 48 BC 47 | jq -r .engine_state_name    # running
    """
    _write_codes(zk.ENGINE_STATES, zk.ENGINE_STATE_TEXT, which, "state", fmt, "Engine states (status ID 1)")


@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("which", nargs=-1, metavar="[CODE|NAME...]", type=_TableName(zk.ERRORS))
@format_option()
def errors(which, fmt):
    """List the ECU error codes of status ID 1 (error_code, error_name).

    CODE or NAME picks rows: a code, a name, or a part of a name (every error containing it).

    \b
    Examples:
      zk errors
      zk errors 13
      zk errors egt -f jsonl
    """
    _write_codes(zk.ERRORS, zk.ERROR_TEXT, which, "error", fmt, "ECU error codes (status ID 1)")


# --- fields ------------------------------------------------------------------------------------

FIELD_COLUMNS = ["kind", "id", "frame", "key", "name_key", "raw_key", "bits", "width", "scale", "offset", "unit",
                 "raw_range", "range", "since", "option", "description", "note"]
FIELD_TABLE = [("kind", "kind"), ("id", "id"), ("frame", "frame"), ("key", "key"), ("bits", "bits"),
               ("scale", "scale"), ("unit", "unit"), ("_range", "range"), ("since", "since"),
               ("option", "option")]
#: Long enumerations point to their own table in the terminal view (JSON and CSV list every name).
_ENUM_TABLES = {id(zk.ENGINE_STATES): "zk states", id(zk.ERRORS): "zk errors",
                id(zk.ACTIONS): "zk send action --help"}


def _since_note(field) -> str:
    if not field.since_by_value:
        return ""
    by_version = {}
    for value, version in sorted(field.since_by_value.items()):
        name = field.names.get(value, str(value)) if field.names else str(value)
        by_version.setdefault(version, []).append(name)
    return "; ".join(f"{', '.join(names)} need{'s' if len(names) == 1 else ''} version {v}"
                     for v, names in sorted(by_version.items()))


def field_row(kind, frame_id, frame_name, field, since):
    notes = [n for n in (field.note, _since_note(field)) if n]
    if field.values is not None:
        rng = ", ".join(f"{raw} = {phys}" for raw, phys in field.values.items())
    else:
        rng = field.describe_range()
    return {
        "kind": kind, "id": frame_id, "frame": frame_name, "key": field.key, "name_key": field.name_key,
        "raw_key": field.raw_key, "bits": bits_text(field), "width": field.width, "scale": scale_text(field),
        "offset": field.offset or None, "unit": field.unit or None, "raw_range": f"{field.lo}..{field.hi}",
        "range": rng, "since": max(since, field.since), "option": field.cli, "description": field.help,
        "note": "; ".join(notes) or None,
    }


def field_rows(kind="both", frame_id=None):
    """Every control and status field, in table order."""
    if kind in ("both", "control"):
        for cmd in zk.CONTROL:
            if frame_id is None or frame_id == cmd.id:
                for f in cmd.fields:
                    yield field_row("control", cmd.id, cmd.name, f, cmd.since)
    if kind in ("both", "status"):
        for st in zk.STATUS:
            if frame_id is None or frame_id == st.id:
                for f in st.fields:
                    yield field_row("status", st.id, st.name, f, st.since)


def _fields_of(kind, frame_id):
    for k, frames in (("control", zk.CONTROL), ("status", zk.STATUS)):
        if kind in ("both", k):
            for fr in frames:
                if frame_id is None or frame_id == fr.id:
                    yield from fr.fields


def _short_range(field, full):
    if field.names is None or len(field.names) <= 4:
        return full
    codes = [v for v in field.names if field.lo <= v <= field.hi]
    where = _ENUM_TABLES.get(id(field.names), "-f json")
    return f"{min(codes)}..{max(codes)}, names: '{where}'"


@click.command(cls=Command, context_settings=CONTEXT)
@click.option("-k", "--kind", type=Choice(["both", "control", "status"]), default="both", show_default=True,
              help="Control (host -> ECU) or status (ECU -> host) fields.")
@click.option("-i", "--id", "frame_id", type=IntRange(0, 15), default=None, metavar="ID",
              help="Only the frame with this ID (control 0..8, status 1..10).")
@format_option()
def fields(kind, frame_id, fmt):
    """List every control and status field: frame, JSON key, bits, scale, unit, range and the
    protocol version it appeared in.

    Bits are 'bN[hi:lo]' of frame byte N, most significant part first (byte 0 is the head).
    The key is the field's key in 'zk decode' and 'zk monitor' records; option is how
    'zk send' takes it. Voltages of status IDs 2 and 6 have a version-dependent scale.

    \b
    Examples:
      zk fields
      zk fields --kind status --id 1
      zk fields -f csv > zk-fields.csv
      zk fields -f jsonl | jq -r 'select(.unit == "V") | .key'
    """
    rows = list(field_rows(kind, frame_id))
    if resolve_format(fmt) == "table":
        for row, f in zip(rows, _fields_of(kind, frame_id)):
            row["_range"] = _short_range(f, row["range"])
    if not rows:
        raise UsageError(f"id: no {'' if kind == 'both' else kind + ' '}frame has ID {frame_id}")
    write_rows(rows, FIELD_COLUMNS, fmt, title="ZK protocol fields", table_columns=FIELD_TABLE)
