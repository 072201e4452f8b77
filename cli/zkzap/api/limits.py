"""Limit monitoring for ECU status streams: ``egt_c<=850,warn=800``, ``power_voltage_v>=7.2``, ...

A :class:`LimitSet` holds conditions from :mod:`zkzap.api.expr` over status keys. It is fed every
decoded status frame (:meth:`LimitSet.check`) and evaluates a condition only on frames that
carry its field (status ID 1 carries ``egt_c``, every ID carries ``rpm``): a snapshot's older
value is never tested twice. For each frame it returns the entries the record gets:
``warnings`` (the conditions in their warning band) and ``limit`` (the conditions violated).

``on_limit`` says what a violation does to the session: ``abort`` or ``exit`` end it with exit
status 5 — a session that controls the engine ends as every session does, with its abort
command (``--abort``; ``none`` sends nothing, and says so) — or ``warn`` (keep going; the
summary still names it). :attr:`LimitSet.tripped` is the first violation that ends the session.

:meth:`LimitSet.summary` gives, per condition, the frames that carried the field, the extreme
value reached (in the violating direction), the first warning and first violation times, and
the verdict (``ok``, ``warn``, ``violated``, or ``unchecked`` when no frame carried the field).
"""

from __future__ import annotations

from ..codec import zk
from ..errors import DeviceError, UsageError
import re

from .expr import Condition, ExpressionError, parse

_RATE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_\-]*)/s\s*(?=[<>=!])")

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Optional


#: What a violation does: abort or exit (end the session, exit 5; one that controls the engine
#: sends its abort either way), warn (go on).
ON_LIMIT = ("abort", "exit", "warn")
#: Status keys a limit may name: the numeric ones (an engine state or error code by its number;
#: the name keys, ``out_of_range`` and the frame's own keys hold no number to compare).
FIELDS = frozenset(f.key for s in zk.STATUS for f in s.fields)
#: Status keys each status frame ID carries.
KEYS_BY_ID = zk.STATUS_KEYS_BY_ID


class LimitViolation(DeviceError):
    """A limit violated (exit status 5); carries the condition, time and value."""

    def __init__(self, message: str, condition: Optional[Condition] = None, t: Optional[float] = None,
                 value: Optional[float] = None) -> None:
        super().__init__(message)
        self.condition = condition
        self.t = t
        self.value = value


#: Engine-state groups a limit's ``when=`` may name (besides any one engine state's name):
#: ``running`` (the running and learning states), ``start`` (ignition, preheat, fuel ramp,
#: restart), and ``stop``, ``standby``, ``cooling``.
WHEN = {"running": frozenset({6, 7, 8, 9, 10, 11}), "start": frozenset({2, 3, 4, 5, 13}),
        "stop": frozenset({0}), "standby": frozenset({1}), "cooling": frozenset({12})}
#: A rate-of-change limit (``egt_c/s<=50``: EGT rise per second) compares the change over the
#: last RATE_WINDOW_S seconds of frames that carry its field, once they span half of it.
RATE_WINDOW_S = 1.0


class Limit(Condition):
    """A :class:`~zkzap.api.expr.Condition` with what only a limit has: ``rate`` (it limits the
    field's change per second, ``FIELD/s``) and ``when`` (the engine states it applies in, None:
    always; ``when=running``, ``when=start``, ``when=cooling|standby``, or a state's name)."""

    __slots__ = ("rate", "when", "when_text")

    def __init__(self, cond, rate=False, when=None, when_text=None):
        super().__init__(cond.text, cond.field, cond.op, cond.threshold, cond.warn)
        self.rate = rate
        self.when = when
        self.when_text = when_text


def parse_limit(text, fields=FIELDS, *, where="limit") -> Limit:
    """One limit: ``FIELD OP NUMBER[,warn=NUMBER][,when=STATES]``, or ``FIELD/s OP NUMBER`` for
    its rate of change (per second). ``fields``: the allowed names (a collection or predicate)."""
    raw = str(text).strip()
    parts = raw.split(",")
    when = when_text = None
    keep = []
    for part in parts[1:]:
        key, sep, value = part.partition("=")
        if key.strip().lower() == "when" and sep:
            if when is not None:
                raise ExpressionError(f"{where}: {raw!r}: when= given twice")
            when, when_text = _when(value, raw, where), value.strip()
        else:
            keep.append(part)
    head = parts[0]
    rate = False
    m = _RATE.match(head)
    if m:
        rate, head = True, m.group(1) + head[m.end(1) + 2:]
    cond = parse(",".join([head] + keep), fields, where=where)
    cond.text = raw
    return Limit(cond, rate, when, when_text)


def _when(value, raw, where):
    by_name = {v: k for k, v in zk.ENGINE_STATES.items()}
    states = set()
    for name in value.strip().lower().split("|"):
        name = name.strip()
        if name in WHEN:
            states |= WHEN[name]
        elif name in by_name:
            states.add(by_name[name])
        else:
            from ..errors import did_you_mean

            names = sorted(WHEN) + sorted(by_name)
            raise ExpressionError(f"{where}: {raw!r}: when={name!r} is no engine state"
                                  f"{did_you_mean(name, names, otherwise='; allowed ' + ', '.join(sorted(WHEN)) + ' or a state name')}")
    return frozenset(states)


def read_limits(exprs=(), files=(), fields=FIELDS) -> list:
    """Limits (:class:`Limit`) from ``--limit EXPR`` options and ``--limits FILE`` files (``-`` is
    stdin). ``fields``: the names a limit may name (the status keys; a stand with sensors or
    corrected values allows theirs too)."""
    from .textfile import lines_of, read_text

    out = []
    for path in files:
        text, name = read_text(path, "limits", "FIELD OP NUMBER lines")
        got = []
        for lineno, line in enumerate(lines_of(text), 1):
            line = line.split("#", 1)[0].strip().lstrip("\ufeff")
            if line:
                got.append(parse_limit(line, fields, where=f"{name}:{lineno}"))
        if not got:
            raise UsageError(f"limits: {name} has no limit (only comments or blank lines); expected FIELD OP "
                             f"NUMBER lines such as egt_c<=850,warn=800")
        out += got
    for e in exprs:
        out.append(parse_limit(e, fields, where="limit"))
    return out


class _State:
    __slots__ = ("checked", "extreme", "extreme_t", "first_warn", "first_violation", "warnings", "violations",
                 "band", "seen")

    def __init__(self):
        self.seen = None                 # a rate limit's recent (t, value) of its field
        self.checked = 0
        self.extreme = None
        self.extreme_t = None
        self.first_warn = None
        self.first_violation = None
        self.warnings = 0
        self.violations = 0
        self.band = "ok"


class LimitSet:
    """Conditions evaluated on every frame that carries their field; see the module text.

    ``notify(message)`` is told when a condition enters its warning band or is violated (once
    per entry, not on every frame).
    """

    def __init__(self, conditions, on_limit="warn", notify=None):
        if on_limit not in ON_LIMIT:
            raise UsageError(f"on-limit: {on_limit!r}; allowed {', '.join(ON_LIMIT)}")
        self.conditions = list(conditions)
        self.on_limit = on_limit
        self.notify = notify or (lambda message: None)
        self.state = [_State() for _ in self.conditions]
        self.tripped = None
        self._by_id = {sid: [i for i, c in enumerate(self.conditions) if c.field in keys]
                       for sid, keys in KEYS_BY_ID.items()}
        #: limits of fields no status frame carries (external sensors, corrected values): tested
        #: on the values each record gets
        self._other = [i for i, c in enumerate(self.conditions) if c.field not in FIELDS]
        self._engine_state = None

    def __bool__(self):
        return bool(self.conditions)

    def check(self, t, rec, more=None) -> dict:
        """Evaluate the conditions whose field ``rec`` (one decoded status frame) carries, and
        those of fields in ``more`` (the record's sensor and corrected values). A limit with
        ``when=`` is tested only while the engine is in one of its states; a rate limit on the
        field's change per second. Returns the record's extra entries: ``{"warnings": [...],
        "limit": [...]}`` (only the non-empty ones)."""
        extra = {}
        state = rec.get("engine_state")
        if state is not None:
            self._engine_state = state
        todo = self._by_id.get(rec.get("id"), ())
        if more and self._other:
            todo = list(todo) + [i for i in self._other if more.get(self.conditions[i].field) is not None]
        for i in todo:
            cond = self.conditions[i]
            value = rec.get(cond.field) if cond.field in FIELDS else (more or {}).get(cond.field)
            when = getattr(cond, "when", None)
            if getattr(cond, "rate", False):
                value = self._rate(i, t, value)
            if when is not None and self._engine_state not in when:
                if self.state[i].band != "ok" and self.state[i].checked:
                    self.state[i].band = "ok"     # out of its states: a new entry is told again
                continue
            verdict = cond.check(value)
            if verdict is None:
                continue
            st = self.state[i]
            st.checked += 1
            worse = cond.worse(st.extreme, value)
            if worse != st.extreme or st.extreme is None:
                st.extreme, st.extreme_t = worse, t
            if verdict == "warn":
                st.warnings += 1
                if st.first_warn is None:
                    st.first_warn = t
                extra.setdefault("warnings", []).append(cond.text)
                if st.band != "warn":
                    self.notify(f"limit warning: {_name(cond)}={_v(value)} at t={t:.2f} s ({cond.text})")
            elif verdict == "violated":
                st.violations += 1
                if st.first_violation is None:
                    st.first_violation = t
                extra.setdefault("limit", []).append(cond.text)
                if st.band != "violated":
                    if self.on_limit == "warn":
                        self.notify(f"limit violated: {_name(cond)}={_v(value)} at t={t:.2f} s ({cond.text})")
                if self.tripped is None and self.on_limit != "warn":
                    self.tripped = LimitViolation(
                        f"limit violated: {_name(cond)}={_v(value)} at t={t:.2f} s ({cond.text})", cond, t, value)
            st.band = verdict
        return extra

    def _rate(self, i, t, value):
        """The field's change per second over the last :data:`RATE_WINDOW_S` (None until the
        frames span half of it)."""
        if value is None or isinstance(value, (str, list, dict)):
            return None
        from collections import deque

        st = self.state[i]
        seen = st.seen
        if seen is None:
            seen = st.seen = deque()
        seen.append((t, value))
        while len(seen) > 2 and seen[1][0] <= t - RATE_WINDOW_S:
            seen.popleft()
        t0, v0 = seen[0]
        if t - t0 < RATE_WINDOW_S / 2:
            return None
        return round((value - v0) / (t - t0), 3)

    def verdict(self, i) -> str:
        st = self.state[i]
        if st.checked == 0:
            return "unchecked"
        if st.violations:
            return "violated"
        return "warn" if st.warnings else "ok"

    def summary(self) -> list:
        out = []
        for i, c in enumerate(self.conditions):
            st = self.state[i]
            out.append({
                "limit": c.text, "field": _name(c), "op": c.op, "threshold": c.threshold, "warn": c.warn,
                "verdict": self.verdict(i), "checked": st.checked, "extreme": st.extreme,
                "extreme_t": None if st.extreme_t is None else round(st.extreme_t, 3),
                "warnings": st.warnings,
                "first_warning_t": None if st.first_warn is None else round(st.first_warn, 3),
                "violations": st.violations,
                "first_violation_t": None if st.first_violation is None else round(st.first_violation, 3),
            })
        return out

    def dashboard_lines(self) -> list:
        """``[(level, text)]`` for a live view: every condition violated so far (red) and those in
        their warning band now (yellow)."""
        out = []
        for i, c in enumerate(self.conditions):
            st = self.state[i]
            if st.violations:
                out.append(("violated", f"{c.text} violated at {st.first_violation:.1f} s, "
                                        f"extreme {_v(st.extreme)}"))
            elif st.band == "warn":
                out.append(("warn", f"{c.text}: in the warning band, extreme {_v(st.extreme)}"))
        return out

    def violated(self) -> list:
        return [c.text for i, c in enumerate(self.conditions) if self.state[i].violations]


def _name(cond):
    """The quantity a limit tests, as a message names it (``egt_c``, ``egt_c/s``)."""
    return f"{cond.field}/s" if getattr(cond, "rate", False) else cond.field


def _v(value):
    return f"{value:g}" if isinstance(value, float) else str(value)


def summary_lines(summary) -> list:
    """Human lines for a limits summary (stderr)."""
    lines = []
    for s in summary:
        ext = "-" if s["extreme"] is None else _v(s["extreme"])
        if s["verdict"] == "unchecked":
            tail = "never checked: no frame carried the field"
        elif s["violations"]:
            tail = f"VIOLATED first at {s['first_violation_t']:g} s ({_n(s['violations'])})"
        elif s["warnings"]:
            tail = f"warning band first at {s['first_warning_t']:g} s ({_n(s['warnings'])})"
        else:
            tail = "ok"
        lines.append(f"  limit {s['limit']}: {tail}; extreme {ext} over {_n(s['checked'])}")
    return lines


def _n(count):
    return f"{count} frame{'' if count == 1 else 's'}"
