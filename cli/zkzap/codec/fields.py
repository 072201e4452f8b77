"""Declarative bit fields: one declaration per field drives encoding, decoding and the CLI.

A :class:`Field` names the bits it occupies in the notation of docs/protocol.md
(``"b4[1:0] b3[7:5]"``: the parts are concatenated most significant first), its scale/offset to
physical units, its range,
its unit, the protocol version it appeared in and, for enumerations, the names of its values.
A :class:`Layout` is an ordered set of fields over a fixed-size frame; it generates a decoder
function from the declarations (like ``collections.namedtuple`` does) so decoding is one call
with no per-field interpretation.
"""

from __future__ import annotations

import math

from ..errors import InvalidValue, clip, unknown_name


class FieldValueError(InvalidValue):
    """A value outside a field's range or grid, or an unknown name. The message names the field.
    A :class:`zkzap.errors.InvalidValue` (exit 2), so also a ``ValueError``."""


def parse_bits(spec: str) -> tuple:
    """``"b4[1:0] b3[7:5]"`` -> ``((4, 1, 0), (3, 7, 5))``; ``"b2"`` is ``b2[7:0]``."""
    parts = []
    for token in spec.split():
        try:
            if token[0] != "b":
                raise ValueError
            name, _, bits = token.partition("[")
            byte = int(name[1:])
            if bits:
                if not bits.endswith("]"):
                    raise ValueError
                hi_text, _, lo_text = bits[:-1].partition(":")
                hi = int(hi_text)
                lo = int(lo_text) if lo_text else hi
            else:
                hi, lo = 7, 0
        except (ValueError, IndexError):
            raise InvalidValue(f"bad bit spec {spec!r}") from None
        if not 0 <= lo <= hi <= 7:
            raise InvalidValue(f"bad bit range in {spec!r}")
        parts.append((byte, hi, lo))
    return tuple(parts)


def bits_text(field) -> str:
    """A field's bits in the notation :func:`parse_bits` reads: ``b4[1:0] b3[7:5]``, ``b2``, ``b4[5]``."""
    parts = []
    for byte, hi, lo in field.bits:
        if (hi, lo) == (7, 0):
            parts.append(f"b{byte}")
        elif hi == lo:
            parts.append(f"b{byte}[{hi}]")
        else:
            parts.append(f"b{byte}[{hi}:{lo}]")
    return " ".join(parts)


def scale_text(field):
    """A field's scale as a number, or its rule when it depends on the protocol version or a
    parameter; None for enumerations."""
    if field.names is not None or field.values is not None:
        return None
    s = field.scale
    return s.describe() if hasattr(s, "describe") else s


def _decimals(step: float) -> int:
    text = repr(float(step))
    if "e" in text:
        return 6
    frac = text.split(".")[1].rstrip("0")
    return len(frac)


class VersionScale:
    """A scale that depends on the protocol version: ``VersionScale(((3, 0.1),), 0.2)`` means
    0.1 for versions <= 3 and 0.2 above."""

    __slots__ = ("steps", "default", "decimals")

    def __init__(self, steps, default):
        self.steps = tuple(steps)
        self.default = default
        self.decimals = max(_decimals(s) for s in [default] + [s for _, s in self.steps])

    def __call__(self, ctx):
        v = ctx.get("version")
        for upto, s in self.steps:
            if v is not None and v <= upto:
                return s
        return self.default

    def describe(self) -> str:
        rules = [f"{s} for protocol version <= {upto}" for upto, s in self.steps]
        rules.append(f"{self.default} above")
        return ", ".join(rules)


class ContextScale:
    """A scale that is a factor times a context parameter (``target rpm = value x 10 x RPM_X``)."""

    __slots__ = ("param", "factor", "decimals")

    def __init__(self, param, factor):
        self.param = param
        self.factor = factor
        self.decimals = 0

    def __call__(self, ctx):
        p = ctx.get(self.param)
        return None if p is None or p == 0 else self.factor * p

    def describe(self) -> str:
        return f"{self.factor} x {self.param}"


class Field:
    """One field of a frame. ``key`` is its JSON key / CSV column; ``cli`` how the CLI takes it
    (``"--state"`` for an option, ``"VOLTS"`` for an argument, None when not offered)."""

    __slots__ = (
        "key", "bits", "width", "scale", "offset", "unit", "lo", "hi", "since", "names",
        "name_key", "values", "raw_key", "cli", "help", "note", "since_by_value", "decimals",
        "_label",
    )

    def __init__(self, key, bits, *, scale=1, offset=0, unit="", lo=0, hi=None, since=1,
                 names=None, name_key=None, values=None, raw_key=None, cli=None, help="",
                 note="", since_by_value=None, label=None):
        self.key = key
        self._label = label
        self.bits = parse_bits(bits)
        self.width = sum(hi_ - lo_ + 1 for _, hi_, lo_ in self.bits)
        self.scale = scale
        self.offset = offset
        self.unit = unit
        self.lo = lo
        self.hi = (1 << self.width) - 1 if hi is None else hi
        if self.hi >= 1 << self.width:
            raise InvalidValue(f"{key}: range exceeds {self.width} bits")
        self.since = since
        self.names = names
        self.name_key = name_key
        self.values = values
        self.raw_key = raw_key
        self.cli = cli
        self.help = help
        self.note = note
        self.since_by_value = since_by_value or {}
        if isinstance(scale, (VersionScale, ContextScale)):
            self.decimals = scale.decimals
        else:
            self.decimals = _decimals(scale) if isinstance(scale, float) else 0

    # --- description -------------------------------------------------------------------
    @property
    def label(self) -> str:
        """Name used in messages: the CLI spelling where there is one."""
        if self._label:
            return self._label
        if self.cli and self.cli.startswith("--"):
            return self.cli[2:]
        if self.cli:
            return self.cli.lower()
        return self.key

    @property
    def is_enum(self) -> bool:
        return self.names is not None

    def scale_for(self, ctx):
        s = self.scale
        return s(ctx) if callable(s) else s

    def physical_range(self, ctx=None):
        """(low, high) in physical units, or None when the scale depends on missing context."""
        if self.names is not None or self.values is not None:
            return self.lo, self.hi
        s = self.scale_for(ctx or {})
        if s is None:
            return None
        return self._phys(self.lo, s), self._phys(self.hi, s)

    def describe_range(self, ctx=None) -> str:
        if self.names is not None:
            return ", ".join(f"{n} ({v})" for v, n in self.names.items() if self.lo <= v <= self.hi)
        if self.values is not None:
            return ", ".join(f"{p}" for p in self.values.values())
        r = self.physical_range(ctx)
        unit = f" {self.unit}" if self.unit else ""
        if r is None:
            return f"{self.lo}..{self.hi} (raw)"
        return f"{_fmt(r[0])}..{_fmt(r[1])}{unit}"

    def step(self, ctx=None):
        s = self.scale_for(ctx or {})
        return s

    def _phys(self, raw, s):
        v = raw * s + self.offset
        if isinstance(v, float):
            v = round(v, self.decimals)
            if self.decimals == 0:
                v = int(v)
        return v

    # --- conversion ---------------------------------------------------------------------
    def to_physical(self, raw, ctx=None):
        if self.values is not None:
            return self.values.get(raw)
        if self.names is not None:
            return raw
        s = self.scale_for(ctx or {})
        if s is None:
            return None
        return self._phys(raw, s)

    def _range_error(self, value, ctx, extra=""):
        note = f" ({self.note})" if self.note else ""
        return FieldValueError(
            f"{self.label}: {value} is out of range; allowed {self.describe_range(ctx)}{note}{extra}")

    def check_raw(self, raw, label=None) -> int:
        label = label or self.label
        if not isinstance(raw, int) or isinstance(raw, bool):
            raise FieldValueError(f"{label}: {raw!r} is not an integer")
        if not self.lo <= raw <= self.hi:
            raise FieldValueError(f"{label}: raw value {quote_value(raw)} is out of range {self.lo}..{self.hi}"
                                  f" ({self.width}-bit field)")
        return raw

    def to_raw(self, value, ctx=None):
        """Physical value (or, for enumerations, a name or number) -> (raw, note or None).

        Off-grid values are rounded to the nearest step; the note says so. Out-of-range values
        raise :class:`FieldValueError` naming the field and its allowed range.
        """
        ctx = ctx or {}
        if self.names is not None:
            if isinstance(value, str):
                lowered = value.strip().lower()
                for raw, name in self.names.items():
                    if name == lowered and self.lo <= raw <= self.hi:
                        return raw, None
                try:
                    value = int(lowered, 0)
                except ValueError:
                    raise unknown_name(self.label, value, [n for r, n in self.names.items() if self.lo <= r <= self.hi],
                                       otherwise=f"; allowed {self.describe_range(ctx)}",
                                       cls=FieldValueError) from None
            if not isinstance(value, int) or not self.lo <= value <= self.hi:
                raise self._range_error(quote_value(value), ctx)
            return value, None
        if self.values is not None:
            for raw, phys in self.values.items():
                if phys == value or (isinstance(value, str) and str(phys) == value.strip()):
                    return raw, None
            raise self._range_error(quote_value(value), ctx)
        if isinstance(value, str):
            try:
                value = float(value) if any(c in value for c in ".eE") else int(value, 0)
            except ValueError:
                raise FieldValueError(f"{self.label}: {clip(repr(value))} is not a number") from None
        if not isinstance(value, (int, float)):
            raise FieldValueError(f"{self.label}: {clip(repr(value))} is not a number")
        if isinstance(value, float) and (value != value or value in (float("inf"), float("-inf"))):
            raise FieldValueError(f"{self.label}: {value} is not a finite number; allowed "
                                  f"{self.describe_range(ctx)}")
        s = self.scale_for(ctx)
        if s is None:
            raise FieldValueError(f"{self.label}: needs {self.scale.param.replace('_', '-')} to convert")
        # The range first, compared exactly (an int of 400 digits, 1e308): only a value in range
        # is converted, so no arithmetic on it can overflow.
        lo_p, hi_p = self._phys(self.lo, s), self._phys(self.hi, s)
        eps = abs(s) * 1e-6
        if value < min(lo_p, hi_p) - eps or value > max(lo_p, hi_p) + eps:
            raise self._range_error(quote_value(value), ctx)
        exact = (value - self.offset) / s
        raw = min(max(int(round(exact)), self.lo), self.hi)
        note = None
        if abs(exact - raw) > 1e-6:
            unit = f" {self.unit}" if self.unit else ""
            note = (f"{self.label}: {_fmt(value)}{unit} is not a multiple of {_fmt(s)}{unit}; "
                    f"rounded to {_fmt(self._phys(raw, s))}{unit}")
        return raw, note

    # --- code generation ----------------------------------------------------------------
    def raw_expr(self, buf="b") -> str:
        expr = None
        for byte, hi, lo in self.bits:
            w = hi - lo + 1
            piece = f"{buf}[{byte}]"
            if lo:
                piece = f"({piece} >> {lo})"
            if w < 8:
                piece = f"({piece} & {(1 << w) - 1:#x})"
            expr = piece if expr is None else f"(({expr}) << {w} | {piece})"
        return expr

    def insert(self, frame: bytearray, raw: int) -> None:
        shift = self.width
        for byte, hi, lo in self.bits:
            w = hi - lo + 1
            shift -= w
            part = (raw >> shift) & ((1 << w) - 1)
            mask = ((1 << w) - 1) << lo
            frame[byte] = (frame[byte] & ~mask & 0xFF) | (part << lo)

    def mask_of(self, byte: int) -> int:
        m = 0
        for b, hi, lo in self.bits:
            if b == byte:
                m |= ((1 << (hi - lo + 1)) - 1) << lo
        return m


def beyond_float(text: str, value: float) -> bool:
    """Whether ``value``, read from ``text``, is infinite only because the finite number written
    (``1e400``, 400 digits) is beyond a float's range: out of range, not "not finite"."""
    return math.isinf(value) and not any(w in str(text).lower() for w in ("inf", "nan"))


def quote_value(x) -> str:
    """A value as a message quotes it: :func:`_fmt`, a huge float in ``g`` form, an integer of
    many digits by its count."""
    if isinstance(x, float) and abs(x) >= 1e15:
        return f"{x:.6g}"
    if isinstance(x, int) and abs(x) >= 10 ** 18:
        digits = len(str(abs(x))) if abs(x) < 10 ** 4000 else "over 4000"
        return f"{'a negative' if x < 0 else 'an'} integer of {digits} digits"
    return _fmt(x) if isinstance(x, (int, float)) else clip(repr(x) if isinstance(x, str) else str(x))


def _fmt(x) -> str:
    if isinstance(x, float):
        text = f"{x:.6f}".rstrip("0").rstrip(".")
        return text if text not in ("-0", "") else "0"
    return str(x)


class Layout:
    """Fields over a fixed-size frame, with a generated decoder.

    ``decode(frame, ctx, known)`` returns a dict of keys in declaration order. ``ctx`` carries
    context parameters (``version`` for version-dependent scales, ``rpm_factor``...). A field
    whose ``since`` is newer than the *known* version (``known``; None when unknown) decodes
    to None. ``raw=True`` adds ``<key>_raw`` entries with the undecoded integers.
    """

    def __init__(self, fields, size, covered=None):
        self.fields = tuple(fields)
        self.size = size
        self.by_key = {f.key: f for f in self.fields}
        self._decoders = {}
        self._covered = covered or {}
        self._reserved = None

    @property
    def reserved(self):
        if self._reserved is None:
            self._reserved = self._reserved_masks(self._covered)
        return self._reserved

    def decoder(self, ctx=None, known=None, raw=False):
        """The generated decoder ``frame -> dict`` for one context (compiled on first use, from
        the same :meth:`items` as the text encoders)."""
        ctx = ctx or {}
        key = (tuple(sorted(ctx.items())), known, raw)
        fn = self._decoders.get(key)
        if fn is None:
            fn = self._decoders[key] = compile_dict(*self.items(ctx, known, raw),
                                                    checks=self.range_checks(known))
        return fn

    def range_checks(self, known=None):
        """``(key, rvar, bad)`` for every field whose raw values are not all documented: ``bad``
        is a tuple of booleans by raw value (True: outside the field's range or name table).
        A decoded record lists such fields under :data:`OUT_OF_RANGE`, values unchanged."""
        cache = self.__dict__.setdefault("_checks", {})
        if known in cache:
            return cache[known]
        checks = []
        for i, f in enumerate(self.fields):
            if f.since > 1 and known is not None and known < f.since:
                continue
            every = range(1 << f.width)
            if f.names is None and f.values is None and f.lo == 0 and f.hi == (1 << f.width) - 1:
                continue                          # every raw value is in range
            if f.names is not None:
                bad = tuple(v not in f.names or not f.lo <= v <= f.hi for v in every)
            elif f.values is not None:
                bad = tuple(f.values.get(v) is None for v in every)
            else:
                bad = tuple(not f.lo <= v <= f.hi for v in every)
            if any(bad):
                checks.append((f.key, f"r{i}", bad))
        cache[known] = checks
        return checks

    def _reserved_masks(self, covered):
        masks = {}
        for byte in range(self.size):
            used = covered.get(byte, 0)
            for f in self.fields:
                used |= f.mask_of(byte)
            masks[byte] = ~used & 0xFF
        return masks

    def decode(self, frame, ctx=None, known=None, raw=False):
        return self.decoder(ctx, known, raw)(frame)

    # --- text encoders ------------------------------------------------------------------
    def items(self, ctx, known, raw=False, tables=0):
        """The record this layout decodes to, as ``(code, items)`` for one fixed context.

        ``code`` is the lines that extract the raw values ``r0, r1...`` from a frame ``b``;
        ``items`` lists ``(key, kind, what)`` in the decoder's key order, where kind is
        ``"const"`` (what: the value), ``"int"``/``"float"`` (what: an expression) or
        ``"table"`` (what: ``(expression, values)``, the value for every raw value). With the
        context fixed, version gates and version-dependent scales are constants, so the
        values are exactly those :meth:`decoder` gives for that context. ``tables`` (a bit
        width) turns the ``"float"`` items of one field up to that width (and ``"int"`` items
        followed by the table of their names) into ``"table"`` items, evaluated from the same
        expression for every raw value, and the ``"float"`` items of wider fields into
        ``"lazy"`` items (what: ``(variable, number of raw values, expression)``) for a table
        filled as values occur.
        """
        code, items = self._items(ctx, known, raw)
        if tables:
            widths = {f"r{i}": f.width for i, f in enumerate(self.fields)}
            for n, (key, kind, what) in enumerate(items):
                if kind not in ("float", "int"):
                    continue
                var = [v for v in widths if v in _names(what)]
                if len(var) != 1:
                    continue
                width = widths[var[0]]
                if kind == "int":
                    # an int is formatted about as fast as it is looked up: a table only where
                    # the value's name follows it (one look-up then gives both)
                    after = items[n + 1] if n + 1 < len(items) else None
                    if not (after and after[1] == "table" and after[2][0] == var[0] and width <= tables):
                        continue
                if width <= tables:
                    items[n] = (key, "table", (var[0], _values(var[0], what, width)))
                else:
                    items[n] = (key, "lazy", (var[0], 1 << width, what))
        return code, items

    def _items(self, ctx, known, raw=False):
        code = []
        items = []
        for i, f in enumerate(self.fields):
            r = f"r{i}"
            code.append(f"{r} = {f.raw_expr()}")
            if f.since > 1 and known is not None and known < f.since:
                items.append((f.key, "const", None))
                if f.name_key:
                    items.append((f.name_key, "const", None))
            else:
                if f.raw_key:
                    items.append((f.raw_key, "int", r))
                every = range(1 << f.width)
                if f.values is not None:
                    items.append((f.key, "table", (r, [f.values.get(v) for v in every])))
                elif f.names is not None:
                    items.append((f.key, "int", r))
                    items.append((f.name_key, "table", (r, [f.names.get(v) or "undocumented-%d" % v for v in every])))
                elif callable(f.scale):
                    sc = f.scale(ctx)
                    if sc is None:
                        items.append((f.key, "const", None))
                    else:
                        items.append((f.key,) + _phys_item(r, sc, f.offset, f.decimals))
                elif f.scale == 1 and f.offset == 0:
                    items.append((f.key, "int", r))
                elif isinstance(f.scale, float):
                    items.append((f.key, "float", f"round({r} * {f.scale!r} + {f.offset!r}, {f.decimals})"))
                else:
                    if isinstance(f.offset, float):
                        items.append((f.key, "float", f"{r} * {f.scale!r} + {f.offset!r}"))
                    else:
                        items.append((f.key, "int", _int_linear(r, f.scale, f.offset)))
            if raw:
                items.append((f.key + "_raw", "int", r))
        return code, items

    def text_encoder(self, dialect, ctx, known, raw=False, head=(), tail=(), guard=None):
        """A generated function ``frame -> text`` rendering the record of one frame straight to
        ``dialect``'s text (JSON object, CSV row) for one fixed context.

        ``head`` and ``tail`` are items around the layout's own (``("kind", "const",
        "status")``, ``("frame", "str", "b.hex(' ').upper()")``). Built from the same
        declarations as :meth:`decoder`, value for value. ``guard`` is ``(expression,
        function)``: a frame for which the expression over ``b`` is true is handed to the
        function instead (a frame this context does not cover). The function takes only
        frames of the layout's size.
        """
        code, items = self.items(ctx, known, raw, tables=TABLE_WIDTH)
        checks = self.range_checks(known)
        head, tail = list(head), list(tail)
        if not checks:
            return compile_text(code, head + items + tail, dialect, size=self.size, guard=guard)
        # a frame with a value out of range (rare) gets the out_of_range cell before the tail,
        # looked up by the bit mask of the failed checks: one table look-up per checked field
        tables = {f"K{j}": bad for j, (_key, _r, bad) in enumerate(checks)}
        mask = " | ".join(f"(K{j}[{r}] << {j})" for j, (_key, r, _bad) in enumerate(checks))
        lists = [[key for j, (key, _r, _bad) in enumerate(checks) if m >> j & 1] for m in range(1 << len(checks))]
        return compile_text(code, head + items + tail, dialect, size=self.size, guard=guard,
                            flagged=(len(head) + len(items), mask, lists, tables))


    def keys(self):
        out = []
        for f in self.fields:
            if f.raw_key:
                out.append(f.raw_key)
            out.append(f.key)
            if f.name_key:
                out.append(f.name_key)
        if self.range_checks():
            out.append(OUT_OF_RANGE)
        return out

    def reserved_bits(self, frame):
        """Non-zero reserved bits as ``"b1=0x0c b2=0x80"`` (None when all are zero)."""
        found = [f"b{byte}={frame[byte] & mask:#04x}" for byte, mask in self.reserved.items()
                 if frame[byte] & mask]
        return " ".join(found) or None


#: The record key listing the fields whose decoded value is outside its documented range.
OUT_OF_RANGE = "out_of_range"
#: Text encoders render the values of fields up to this many bits from a table built when the
#: encoder is (256 entries at most: building an encoder stays cheap, as it must for a decode of
#: a few frames), instead of scaling and formatting them per frame; wider float fields use a
#: shared table filled as values occur.
TABLE_WIDTH = 8
#: A wider field's table is filled as its values occur, and whole once 1/LAZY_FILL of it was
#: filled that way (values that keep changing: a whole table costs less than the misses).
LAZY_FILL = 16


#: Lazily filled value tables, shared by every encoder: (text function, expression, size) ->
#: (table, miss function).
_LAZY = {}


def _lazy_table(value, var, count, expr):
    """``(table, miss)``: a list of the text of ``expr`` for each raw value ``var`` in
    ``range(count)``, None until :func:`miss` (``miss(raw) -> text``) fills it for a value;
    once values keep changing (1/LAZY_FILL of the table missed), it fills the table whole.
    Encoders of the same field and context share one table."""
    import re

    norm = re.sub(rf"\b{var}\b", "x", expr)
    key = (value, norm, count)
    got = _LAZY.get(key)
    if got is None:
        if len(_LAZY) >= 64:
            _LAZY.clear()
        ns = {"VALUE": value, "t": [None] * count, "left": [max(count // LAZY_FILL, 1)]}
        exec("def miss(x, t=t, left=left):\n"  # noqa: S102 - generated from the static tables
             f"    v = t[x] = VALUE({norm})\n"
             "    left[0] -= 1\n"
             "    if not left[0]:\n"
             f"        t[:] = [VALUE({norm}) for x in range({count})]\n"
             "    return v", ns)
        got = _LAZY[key] = (ns["t"], ns["miss"])
    return got


#: Value tables of field expressions: (expression in x, width) -> the value of every raw value.
_VALUES = {}


def _values(var, expr, width):
    """The value of ``expr`` (in the variable ``var``) for every raw value of ``width`` bits,
    computed once per expression and width."""
    import re

    norm = re.sub(rf"\b{var}\b", "x", expr)
    got = _VALUES.get((norm, width))
    if got is None:
        if len(_VALUES) >= 256:
            _VALUES.clear()
        fn = eval(f"lambda x: {norm}")  # noqa: S307 - generated from the static tables
        got = _VALUES[norm, width] = tuple(fn(v) for v in range(1 << width))
    return got


def _names(expr):
    """The identifiers of an expression."""
    import re

    return set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", expr))


def _phys_item(r, sc, offset, decimals):
    """Field._phys with a constant scale, as an (kind, expression) item."""
    if isinstance(sc, float) or isinstance(offset, float):
        if decimals == 0:
            return "int", f"int(round({r} * {sc!r} + {offset!r}, 0))"
        return "float", f"round({r} * {sc!r} + {offset!r}, {decimals})"
    return "int", _int_linear(r, sc, offset)


def _int_linear(r, scale, offset):
    """``r * scale + offset`` for integer scale and offset, without the no-op parts."""
    expr = r if scale == 1 else f"{r} * {scale!r}"
    if offset:
        expr += f" - {-offset!r}" if offset < 0 else f" + {offset!r}"
    return expr


def compile_dict(code, items, checks=()):
    """Compile ``code`` + ``items`` (see :meth:`Layout.items`) into ``frame -> dict``; with
    ``checks`` (see :meth:`Layout.range_checks`) a record with values out of range gets the
    :data:`OUT_OF_RANGE` list of their keys."""
    ns = {}
    entries = []
    for n, (key, kind, what) in enumerate(items):
        if kind == "const":
            ns[f"c{n}"] = what
            entries.append(f"{key!r}: c{n}")
        elif kind == "table":
            expr, values = what
            ns[f"t{n}"] = tuple(values)
            entries.append(f"{key!r}: t{n}[{expr}]")
        else:
            entries.append(f"{key!r}: {what}")
    src = ["def decode(b):"] + [f"    {line}" for line in code]
    if not checks:
        src.append("    return {" + ", ".join(entries) + "}")
    else:
        src.append("    d = {" + ", ".join(entries) + "}")
        tests = []
        for j, (key, rvar, bad) in enumerate(checks):
            ns[f"k{j}"] = bad
            tests.append((key, f"k{j}[{rvar}]"))
        src.append(f"    if {' or '.join(t for _, t in tests)}:")
        pairs = ", ".join(f"({key!r}, {t})" for key, t in tests)
        src.append(f"        d[{OUT_OF_RANGE!r}] = [k for k, bad in ({pairs},) if bad]")
        src.append("    return d")
    exec("\n".join(src), ns)  # noqa: S102 - generated from the static tables
    return ns["decode"]


def _check_vars(mask):
    """The raw variables of a mask expression ``(K0[r1] << 0) | (K1[r4] << 1)``, in order."""
    import re

    return re.findall(r"K\d+\[(r\d+)\]", mask)


#: Text tables: (dialect key, values) -> the dialect's text of each value.
_TEXTS = {}


def _texts(dialect, values):
    """The dialect's text of each value (numbers by ``number_value`` where the dialect has it:
    the same text, without the general encoder's dispatch), made once per dialect and table."""
    values = tuple(values)
    # the types too: 1, 1.0 and True are equal keys but different texts
    key = (getattr(dialect, "key", None) or id(dialect), values, tuple(map(type, values)))
    got = _TEXTS.get(key)
    if got is None:
        value = dialect.value
        number = getattr(dialect, "number_value", None)
        if number is None:
            got = tuple(value(v) for v in values)
        else:
            got = tuple(number(v) if type(v) in (int, float) else value(v) for v in values)
        if len(_TEXTS) >= 512:
            _TEXTS.clear()
        _TEXTS[key] = got
    return got


def _fstring(template, args, ns=None):
    """The %-template ``template`` (pieces ``%d`` for ints, ``%s`` for text, ``%r``, ``%%``)
    filled with the expressions ``args``, as the source of one f-string expression.

    With ``ns`` (the namespace the tables ``tN`` live in), two ``%s`` pieces that look up
    tables of text with the same index and only literal text between them (a value and its
    name: ``5,fuel-ramp``) become one look-up in a table of both, added to ``ns``."""
    import re

    seq = []                                  # ["text", ["expression", "!r" or ""], "text"...]
    lit, n = "", 0
    for k, part in enumerate(re.split(r"(%[dsr%])", template)):
        if k % 2 == 0:
            lit += part
        elif part == "%%":
            lit += "%"
        else:
            seq += [lit, [args[n], "!r" if part == "%r" else "", part]]
            lit = ""
            n += 1
    seq.append(lit)
    assert n == len(args), "one expression per piece"
    if ns is not None:
        k = 1
        while k + 2 < len(seq):
            a, b = seq[k], seq[k + 2]
            ma, mb = re.fullmatch(r"(t\d+)\[(\w+)\]", a[0]), re.fullmatch(r"(t\d+)\[(\w+)\]", b[0])
            if (a[2] == b[2] == "%s" and ma and mb and ma.group(2) == mb.group(2)
                    and isinstance(ns.get(ma.group(1)), tuple) and isinstance(ns.get(mb.group(1)), tuple)):
                sep = seq[k + 1]
                merged = ns.setdefault("_merged", {})
                name = merged.get((ma.group(1), sep, mb.group(1)))
                if name is None:
                    name = merged[ma.group(1), sep, mb.group(1)] = f"t{len(merged)}m"
                    ns[name] = tuple(x + sep + y for x, y in zip(ns[ma.group(1)], ns[mb.group(1)]))
                seq[k:k + 3] = [[f"{name}[{ma.group(2)}]", "", "%s"]]
                continue
            k += 2
    out = []
    for k, item in enumerate(seq):
        if k % 2 == 0:
            if item:
                out.append(repr(item))
        else:
            out.append(f'f"{{{item[0]}{item[1]}}}"')
    return "(" + " ".join(out or ["''"]) + ")"


def compile_text(code, items, dialect, flagged=None, size=None, guard=None):
    """Compile ``code`` + ``items`` (see :meth:`Layout.items`; kind ``"str"`` is an expression
    giving text that needs no escaping) into ``frame -> text`` for ``dialect``.

    The dialect renders values (``dialect.value(v)``), gives the template piece of a dynamic
    string (``dialect.str_piece``) and arranges the ``(key, piece, arg)`` cells into one
    %-template (``dialect.template(cells) -> (template, args)``). ``flagged`` is
    ``(position, mask expression, lists by mask, tables)``: when the mask is non-zero a second
    template renders the :data:`OUT_OF_RANGE` list at ``position``. With ``size`` (the frame
    length: the function then takes only frames of that length) the frame's bytes are
    unpacked into locals once. ``guard``: see :meth:`Layout.text_encoder`.
    """
    import re

    ns = {}
    cells = []
    for n, (key, kind, what) in enumerate(items):
        if kind == "const":
            cells.append((key, dialect.value(what).replace("%", "%%"), None))
        elif kind == "int":
            cells.append((key, "%d", what))
        elif kind == "float":
            # rendered once per raw value (round() and float repr are the slow part)
            var = re.findall(r"\br\d+\b", what)
            if len(var) == 1:
                ns[f"t{n}"] = {}
                ns["VALUE"] = dialect.value
                exec(f"def f{n}({var[0]}):\n    v = t{n}[{var[0]}] = VALUE({what})\n    return v", ns)  # noqa: S102
                cells.append((key, "%s", f"(t{n}.get({var[0]}) or f{n}({var[0]}))"))
            else:
                cells.append((key, "%r", what))
        elif kind == "str":
            cells.append((key, dialect.str_piece, what))
        elif kind == "table":
            expr, values = what
            ns[f"t{n}"] = _texts(dialect, values)
            cells.append((key, "%s", f"t{n}[{expr}]"))
        elif kind == "lazy":
            # a table filled as raw values occur (see _lazy_table), shared by every encoder
            var, count, expr = what
            ns[f"t{n}"], ns[f"f{n}"] = _lazy_table(getattr(dialect, "number_value", dialect.value),
                                                   var, count, expr)
            cells.append((key, "%s", f"(t{n}[{var}] or f{n}({var}))"))
        else:  # pragma: no cover - the kinds above are all Layout.items produces
            raise InvalidValue(f"item kind {kind!r}")
    template, args = dialect.template(cells)
    mask = ""
    if flagged is not None:
        position, mask, lists, tables = flagged
        ns.update(tables)
        ns["OOR"] = tuple(dialect.value(v) for v in lists)
        template2, args2 = dialect.template(cells[:position] + [(OUT_OF_RANGE, "%s", "OOR[m]")] + cells[position:])
        ns["TEMPLATE2"] = template2
    used = set(re.findall(r"\br\d+\b", " ".join(args) + " " + mask))
    body = [line for line in code if line.split(" = ")[0] in used]
    # the template as an f-string (faster than %): an argument that cannot sit inside the
    # f-string's quotes is computed into a local first
    hoisted = {}
    for a in args + (args2 if flagged is not None else []):
        if a not in hoisted and re.search(r"['\"\\{}]", a):
            hoisted[a] = f"a{len(hoisted)}"
            body.append(f"{hoisted[a]} = {a}")
    lines = []
    if flagged is not None:
        lines.append(f"if {' or '.join(f'K{j}[{r}]' for j, r in enumerate(_check_vars(mask)))}:")
        lines.append(f"    m = {mask}")
        lines.append(f"    return {_fstring(template2, [hoisted.get(a, a) for a in args2], ns)}")
    lines.append(f"return {_fstring(template, [hoisted.get(a, a) for a in args], ns)}")
    body += lines
    if guard is not None:
        ns["GUARDED"] = guard[1]
        body[:0] = [f"if {guard[0]}:", "    return GUARDED(b)"]
    if size:
        # b[3] -> b3, one unpacking of the frame instead of an index per use
        text = "\n".join(body)
        idx = {int(k) for k in re.findall(r"\bb\[(\d+)\]", text)}
        body = [re.sub(r"\bb\[(\d+)\]", r"b\1", line) for line in body]
        # a raw value that is a whole byte is that byte's local
        alias = dict(m.groups() for m in (re.fullmatch(r"(r\d+) = (b\d+)", line) for line in body) if m)
        if alias:
            body = [re.sub(r"\br\d+\b", lambda m: alias.get(m.group(0), m.group(0)), line)
                    for line in body if not re.fullmatch(r"r\d+ = b\d+", line)]
        if idx:
            body.insert(0, ", ".join(f"b{k}" if k in idx else "_" for k in range(size)) + " = b")
    # the tables and templates as default arguments: local look-ups on the fast path
    names = sorted(k for k in ns if k not in ("VALUE", "__builtins__", "_merged")
                   and re.search(rf"\b{k}\b", "\n".join(body)))
    src = [f"def encode(b{''.join(f', {k}={k}' for k in names)}):"] + [f"    {line}" for line in body]
    exec("\n".join(src), ns)  # noqa: S102 - generated from the static tables
    return ns["encode"]
