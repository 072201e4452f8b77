"""Conditions on record fields, parsed strictly (no ``eval``): ``FIELD OP NUMBER[,warn=NUMBER]``.

One syntax serves every place that tests values as they stream by: ECU limits
(``egt_c<=850,warn=800``, ``power_voltage_v>=7.2``, ``error_code==0``) and ending conditions
(``moving==0``). ``OP`` is one of ``< <= > >= == !=``; ``NUMBER`` is a finite decimal, a
``0x`` hex integer, or ``true``/``false`` (1/0). The optional warning band is a second
threshold on the same side of the limit: with ``<= 850,warn=800`` a value above 800 warns and
one above 850 violates.

:func:`parse` takes the set of allowed field names (or a predicate), so an unknown field is
refused with the names that are allowed, before any port opens. Errors are
:class:`ExpressionError` (a :class:`zkzap.errors.UsageError`, exit status 2), naming the
expression and, when read from a file, ``FILE:LINE``.
"""

from __future__ import annotations

import math
import operator
import re

from ..errors import UsageError, clip, close_names, did_you_mean

#: Operators, longest first (the parser tries them in this order).
OPERATORS = {
    "<=": operator.le, ">=": operator.ge, "==": operator.eq, "!=": operator.ne,
    "<": operator.lt, ">": operator.gt,
}
_SPLIT = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_\-]*)\s*(<=|>=|==|!=|<|>)\s*(\S.*?)\s*$")


class ExpressionError(UsageError):
    """A condition that cannot be parsed; the message names it and what is allowed."""


def parse_number(text: str, what: str) -> float:
    """A finite number from ``text`` (decimal, ``0x..``, true/false); ExpressionError otherwise."""
    t = text.strip().lower()
    if t in ("true", "false"):
        return 1.0 if t == "true" else 0.0
    try:
        value = float(int(t, 16)) if t.startswith(("0x", "-0x")) else float(t)
    except ValueError:
        raise ExpressionError(f"{what}: {clip(repr(text.strip()))} is not a number") from None
    except OverflowError:             # a hexadecimal integer beyond a float's range
        raise ExpressionError(f"{what}: {clip(repr(text.strip()))} is out of range (at most 1.8e308)") from None
    if not math.isfinite(value):
        raise ExpressionError(f"{what}: {clip(repr(text.strip()))} is not a finite number")
    return value


class Condition:
    """``field op threshold``, with an optional warning threshold ``warn``.

    :meth:`check` returns ``"ok"``, ``"warn"`` or ``"violated"`` for a value (None: the record
    does not carry the field, nothing to say). A warning band only makes sense for the ordering
    operators; for ``<``/``<=`` it must be below the limit, for ``>``/``>=`` above it.
    """

    __slots__ = ("text", "field", "op", "threshold", "warn", "_test", "_warn_test")

    def __init__(self, text, field, op, threshold, warn=None):
        self.text = text
        self.field = field
        self.op = op
        self.threshold = threshold
        self.warn = warn
        self._test = OPERATORS[op]
        self._warn_test = OPERATORS[op] if warn is not None else None

    def holds(self, value) -> bool:
        """Whether ``value`` satisfies the condition (False for None)."""
        if value is None or isinstance(value, (str, list, dict)):
            return False
        return bool(self._test(value, self.threshold))

    def check(self, value):
        if value is None or isinstance(value, (str, list, dict)):
            return None
        if not self._test(value, self.threshold):
            return "violated"
        if self._warn_test is not None and not self._warn_test(value, self.warn):
            return "warn"
        return "ok"

    def worse(self, a, b):
        """The more extreme of two values in the direction that violates the condition."""
        if a is None:
            return b
        if b is None:
            return a
        if self.op in ("<", "<="):
            return max(a, b)
        if self.op in (">", ">="):
            return min(a, b)
        return b if not self.holds(b) else a

    def __repr__(self):
        return f"Condition({self.text!r})"

    def __str__(self):
        return self.text


def parse(text: str, fields=None, *, where: str = "", allow_warn: bool = True,
          example: str = "egt_c<=850") -> Condition:
    """Parse one condition. ``fields``: the allowed field names (a collection or a predicate;
    None allows any); ``where``: ``FILE:LINE`` or an option name for messages; ``example``: a
    valid condition where these fields are used, for the message of a malformed one."""
    label = f"{where}: " if where else ""
    raw = str(text)
    main, *extras = raw.split(",")
    m = _SPLIT.match(main)
    if not m:
        raise ExpressionError(f"{label}{raw.strip()!r}: expected FIELD OP NUMBER with OP one of "
                              f"{' '.join(sorted(OPERATORS, key=len))} (for example {example})")
    field, op, number = m.group(1), m.group(2), m.group(3)
    if fields is not None and not _allowed(field, fields) and _allowed(field.replace("-", "_"), fields):
        field = field.replace("-", "_")
    if fields is not None and not _allowed(field, fields):
        names = sorted(fields) if not callable(fields) else []
        hint = did_you_mean(field, names, otherwise=f"; allowed {', '.join(names)}" if names and len(names) <= 60
                            else "")
        raise ExpressionError(f"{label}{raw.strip()!r}: unknown field {field!r}{hint}", field=field,
                              suggestions=close_names(field, names))
    threshold = parse_number(number, f"{label}{raw.strip()!r}")
    warn = None
    for extra in extras:
        key, sep, value = extra.partition("=")
        if key.strip().lower() != "warn" or not sep:
            raise ExpressionError(f"{label}{raw.strip()!r}: {extra.strip()!r} is not warn=NUMBER")
        if not allow_warn:
            raise ExpressionError(f"{label}{raw.strip()!r}: a warning band is not allowed here")
        if warn is not None:
            raise ExpressionError(f"{label}{raw.strip()!r}: warn= given twice")
        warn = parse_number(value, f"{label}{raw.strip()!r}: warn")
        if op in ("==", "!="):
            raise ExpressionError(f"{label}{raw.strip()!r}: warn= needs one of < <= > >=")
        if not OPERATORS[op](warn, threshold) and warn != threshold:
            side = "below" if op in ("<", "<=") else "above"
            raise ExpressionError(f"{label}{raw.strip()!r}: warn={value.strip()} must be {side} the limit "
                                  f"{number}")
    return Condition(raw.strip(), field, op, threshold, warn)


def _allowed(field, fields) -> bool:
    return fields(field) if callable(fields) else field in fields


def parse_lines(text: str, fields=None, *, name: str = "limits") -> list:
    """Conditions from a file's text: one per line, ``#`` comments, blank lines skipped; errors
    name ``NAME:LINE``."""
    out = []
    from .textfile import lines_of

    for lineno, line in enumerate(lines_of(text), 1):
        line = line.split("#", 1)[0].strip().lstrip("\ufeff")
        if line:
            out.append(parse(line, fields, where=f"{name}:{lineno}"))
    return out
