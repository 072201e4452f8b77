"""Engine schedules for ``zk profile``: throttle and RPM targets over time.

A schedule is CSV text, one row per step: ``time_s,throttle_pct[,state]``, or an RPM target
``time_s,rpm=95000[,state]``, or, with a header, any order of the columns ``time_s``,
``throttle_pct``, ``rpm`` and ``state`` (a row fills either ``throttle_pct`` or ``rpm``).
``#`` starts a comment, blank lines are skipped, times must increase (two rows at one time are
refused, naming both lines: only the second would ever be sent). The file may come
from a spreadsheet: a UTF-8 byte order mark, quoted cells, ``;`` or tab separators (with a
decimal comma when the separator is ``;``) are read as such. Every number must be finite and in
range (times 0..:data:`MAX_TIME_S`); a bad cell is refused naming ``FILE:LINE``.

Throttle rows send control ID 1 (state, throttle). RPM rows put the ECU in RPM mode: ID 6 with
the row's state and the RPM factor ``RPM_X`` (the smallest factor whose range, 40 950 x RPM_X
rpm, holds the schedule's highest target: the finest resolution, 10 x RPM_X rpm), alternating
with ID 7 targets. In a schedule with RPM rows the throttle rows alternate ID 1 with ID 6
``none`` (factor 0), which leaves RPM mode and hands the state back to ID 1. :meth:`Schedule.plan_check`
is the schedule's :class:`~zkzap.api.prestart.Plan`: a session running it listens for the ECU's
status ID 6 first and refuses the schedule before its first frame when a target is above the max
rpm the ECU reports or the ECU is older than protocol version 4 (:class:`ScheduleTargetError`,
exit status 2, nothing sent).

:meth:`Schedule.plan` lists the commands and when they change without stepping through every
control period, so its cost grows with the number of rows, not with the schedule's duration.
"""

from __future__ import annotations

import csv
import math

from ..codec import zk
from ..codec.fields import FieldValueError, beyond_float
from ..errors import UsageError, clip
from .prestart import EcuLimitError, Plan

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Iterable, Literal, Optional

    from typing_extensions import Self

_THROTTLE = zk.CONTROL_BY_NAME["control"].layout.by_key["throttle_pct"]
_SW = zk.CONTROL_BY_NAME["control"].layout.by_key["sw"]
_RPM_VALUE_MAX = zk.CONTROL_BY_NAME["rpm"].layout.by_key["target_rpm"].hi       # 4095
_FACTOR_MAX = zk.RPM_FACTOR.hi                                                  # 6
#: Highest target the protocol can express: 4095 x 10 x 6 rpm.
RPM_MAX = _RPM_VALUE_MAX * 10 * _FACTOR_MAX
#: The latest time a row may have (s, about 31.7 years): beyond it a control period (at most
#: 1 s) is no longer representable as a step of the row times' floating-point resolution.
MAX_TIME_S = 1e9
COLUMNS = ("time_s", "throttle_pct", "rpm", "state")
SHAPE = "time_s,throttle_pct[,state] or time_s,rpm=N[,state]"


class ScheduleError(UsageError):
    """A schedule that cannot be read; the message names ``FILE:LINE``."""


#: A schedule the connected ECU cannot follow (an RPM target above its max rpm, an ECU too old for
#: RPM mode): refused before the first frame (exit 2).
ScheduleTargetError = EcuLimitError


def rpm_factor_for(top) -> int:
    """The RPM_X that expresses targets up to ``top`` rpm with the finest steps (10 x RPM_X rpm)."""
    return max(1, math.ceil(top / (_RPM_VALUE_MAX * 10)))


class Row:
    """One schedule row: ``t`` (s), ``throttle`` (%) or ``rpm`` (target), ``state``, and the
    ``line`` it was read from."""

    __slots__ = ("t", "throttle", "rpm", "state", "line")

    def __init__(self, t, throttle, rpm, state, line):
        self.t, self.throttle, self.rpm, self.state, self.line = t, throttle, rpm, state, line

    @property
    def mode(self):
        """``rpm`` for an RPM target, else ``throttle``."""
        return "rpm" if self.rpm is not None else "throttle"

    def target_text(self):
        """The target in words: ``95000 rpm`` or ``40 %``."""
        return f"{self.rpm:g} rpm" if self.rpm is not None else f"{self.throttle:g} %"


def _number(cell, what, where, decimal_comma=False):
    text = cell.strip()
    if decimal_comma:
        text = text.replace(",", ".")
    try:
        value = float(text)
    except ValueError:
        raise ScheduleError(f"{where}: {what}: {clip(repr(cell.strip()))} is not a number") from None
    if beyond_float(text, value):
        raise ScheduleError(f"{where}: {what}: {clip(repr(cell.strip()))} is out of range")
    if not math.isfinite(value):
        raise ScheduleError(f"{where}: {what}: {clip(repr(cell.strip()))} is not a finite number")
    return value


def _looks_numeric(cell, decimal_comma=False) -> bool:
    """Whether a first cell is meant as a number (``1e400``, ``nan`` too: data, refused as such
    later) rather than a column name."""
    text = cell.strip().lower()
    if decimal_comma:
        text = text.replace(",", ".")
    try:
        float(text)
    except ValueError:
        return False
    return True


def _separator(line):
    for sep in (";", "\t"):
        if sep in line:
            return sep
    return ","


def _cells(line, sep):
    row = next(csv.reader([line], delimiter=sep, skipinitialspace=True), [])
    return [c.strip() for c in row]


class Schedule:
    """Rows of throttle or RPM targets; see the module documentation."""

    def __init__(self, rows: Iterable[Row], interpolate: Literal["step", "linear"] = "step", name: str = "schedule",
                 notes: Iterable[str] = ()) -> None:
        if not rows:
            raise ScheduleError(f"{name}: no rows; expected {SHAPE}")
        self.rows = rows
        self.interpolate = interpolate
        self.name = name
        self.notes = list(notes)
        self.has_rpm = any(r.rpm is not None for r in rows)
        top = max((r.rpm for r in rows if r.rpm is not None), default=0)
        self.max_target = top
        self.rpm_factor = rpm_factor_for(top) if self.has_rpm else 0
        self._i = 0
        self._cache = {}
        self._toggle = 0

    # --- reading ---------------------------------------------------------------------------------
    @classmethod
    def parse(cls, text: str, name: str = "schedule", interpolate: Literal["step", "linear"] = "step",
              default_state: str = "run") -> Self:
        """Parse schedule text (``time_s,throttle_pct[,state]`` or ``time_s,rpm=N[,state]`` rows,
        optionally under a header; ``#`` comments); errors name ``NAME:LINE``."""
        rows, notes = [], []
        cols = None
        sep = None
        state = default_state
        from .textfile import lines_of

        for lineno, raw in enumerate(lines_of(text), 1):
            if lineno == 1:
                raw = raw.lstrip("\ufeff")
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            if sep is None:
                sep = _separator(line)
            comma = sep == ";"
            where = f"{name}:{lineno}"
            try:
                cells = _cells(line, sep)
            except csv.Error as e:            # a cell beyond the csv module's field limit, a stray quote
                raise ScheduleError(f"{where}: not a CSV row: {e}") from None
            while cells and not cells[-1]:            # spreadsheets pad rows with empty cells
                cells.pop()
            if not cells:
                continue
            if cols is None:
                if _looks_numeric(cells[0], comma):
                    cols = {}                         # data from the first row (a bad number says so)
                else:
                    names = [c.lower() for c in cells]
                    unknown = [c for c in names if c not in COLUMNS]
                    if unknown or "time_s" not in names or not ({"throttle_pct", "rpm"} & set(names)) \
                            or len(set(names)) != len(names):
                        raise ScheduleError(f"{where}: header {line!r}: columns are time_s, throttle_pct "
                                            f"and/or rpm, and optionally state") from None
                    cols = {c: i for i, c in enumerate(names)}
                    continue
            rows.append(cls._row(cells, cols, where, lineno, comma, state, notes))
            state = rows[-1].state
            if len(rows) > 1 and rows[-1].t < rows[-2].t:
                raise ScheduleError(f"{where}: time_s: {rows[-1].t:g} is before the previous row's "
                                    f"{rows[-2].t:g}; times must not decrease")
            if len(rows) > 1 and rows[-1].t == rows[-2].t:
                raise ScheduleError(f"{where}: time_s: {rows[-1].t:g} is also the time of {name}:{rows[-2].line}; "
                                    f"of two rows at one time only the second would be sent: give each row "
                                    f"its own time")
        sched = cls(rows, interpolate, name, notes)
        sched._round_rpm_notes()
        return sched

    @classmethod
    def load(cls, path: str, name: Optional[str] = None, interpolate: Literal["step", "linear"] = "step",
             default_state: str = "run") -> Self:
        """Read and parse the schedule file ``path`` (``-``: stdin, UTF-8); messages call it
        ``name`` (default: the path, or ``stdin``). A file that cannot be read is a
        :class:`~zkzap.errors.UsageError`."""
        from .textfile import read_text

        text, read_name = read_text(path, "schedule", f"CSV rows {SHAPE}")
        return cls.parse(text, name=name or read_name, interpolate=interpolate, default_state=default_state)

    @staticmethod
    def _row(cells, cols, where, lineno, comma, state, notes):
        if cols:
            if len(cells) > len(cols):
                raise ScheduleError(f"{where}: {len(cells)} cells; the header names {len(cols)}")
            get = {c: (cells[i] if i < len(cells) else "") for c, i in cols.items()}
            t_cell, thr_cell, rpm_cell, st_cell = (get.get(c, "") for c in COLUMNS)
            if not t_cell:
                raise ScheduleError(f"{where}: time_s: missing")
            if thr_cell and rpm_cell:
                raise ScheduleError(f"{where}: give throttle_pct or rpm, not both")
            if not thr_cell and not rpm_cell:
                raise ScheduleError(f"{where}: no target: give throttle_pct or rpm")
        else:
            if not 2 <= len(cells) <= 3:
                raise ScheduleError(f"{where}: {len(cells)} cells; expected {SHAPE}")
            t_cell, target = cells[0], cells[1]
            st_cell = cells[2] if len(cells) > 2 else ""
            key, eq, value = target.partition("=")
            if eq:
                key = key.strip().lower()
                if key not in ("rpm", "throttle_pct"):
                    raise ScheduleError(f"{where}: {target!r}: expected rpm=N or throttle_pct=N")
                thr_cell, rpm_cell = (value, "") if key == "throttle_pct" else ("", value)
            else:
                thr_cell, rpm_cell = target, ""
        t = _number(t_cell, "time_s", where, comma)
        if not 0 <= t <= MAX_TIME_S:
            raise ScheduleError(f"{where}: time_s: {t_cell} is out of range; allowed 0..{MAX_TIME_S:.0f} s "
                                "(about 31 years)")
        if st_cell:
            state = st_cell.lower()
        throttle = rpm = None
        try:
            if rpm_cell:
                rpm = _number(rpm_cell, "rpm", where, comma)
                if not 0 <= rpm <= RPM_MAX:
                    raise ScheduleError(f"{where}: rpm: {rpm_cell} is out of range; allowed 0..{RPM_MAX} "
                                        f"(4095 x 10 x RPM_X with RPM_X at most {_FACTOR_MAX})")
                if state not in zk.MODE_SW.values() or state == "none":
                    raise ScheduleError(f"{where}: state: {state!r} with an rpm target; allowed stop, "
                                        f"standby, run")
            else:
                throttle = _number(thr_cell, "throttle_pct", where, comma)
                _, note = _THROTTLE.to_raw(throttle)
                if note:
                    notes.append(f"{where}: {note}")
                state = zk.CONTROL_SW[_SW.to_raw(state)[0]]
        except FieldValueError as e:
            raise ScheduleError(f"{where}: {e}") from None
        return Row(t, throttle, rpm, state, lineno)

    def _round_rpm_notes(self):
        step = 10 * self.rpm_factor
        for r in self.rows:
            if r.rpm is not None and r.rpm % step:
                got = round(r.rpm / step) * step
                self.notes.append(f"{self.name}:{r.line}: rpm {r.rpm:g} rounded to {got:g} "
                                  f"(steps of {step} rpm at RPM_X {self.rpm_factor})")

    # --- in force at a time ------------------------------------------------------------------------
    @property
    def length(self) -> float:
        """The schedule's length: the last row's time (s)."""
        return self.rows[-1].t

    def check_length(self) -> None:
        """Refuse (UsageError) a schedule that would end as it starts (its last row at 0 s)."""
        if self.length <= 0:
            raise UsageError(f"schedule: {self.name}: the last row is at 0 s; the last row's time_s is the "
                             f"schedule's length")

    @property
    def final_state(self) -> str:
        """The last row's state (the engine's state when the schedule ends)."""
        return self.rows[-1].state

    @property
    def ends_in_rpm_mode(self) -> bool:
        """True when the last row is an RPM target (the end must leave RPM mode)."""
        return self.rows[-1].rpm is not None

    def row_index(self, t):
        """The index of the row in force at ``t`` (None before the first row)."""
        rows = self.rows
        if t < rows[0].t:
            return None
        i = self._i if self._i < len(rows) and rows[self._i].t <= t else 0
        while i + 1 < len(rows) and rows[i + 1].t <= t:
            i += 1
        self._i = i
        return i

    def command_at(self, t):
        """``(mode, state, value)`` in force at ``t`` (value: throttle % or target rpm), or None
        before the first row."""
        i = self.row_index(t)
        if i is None:
            return None
        r = self.rows[i]
        value = r.rpm if r.rpm is not None else r.throttle
        if self.interpolate == "linear" and i + 1 < len(self.rows):
            n = self.rows[i + 1]
            if n.mode == r.mode and n.t > r.t:
                nv = n.rpm if n.rpm is not None else n.throttle
                value = value + (nv - value) * (t - r.t) / (n.t - r.t)
        return r.mode, r.state, value

    def _frames(self, mode, state, value):
        """The frames for one command (one or two; a cycle)."""
        if mode == "rpm":
            step = 10 * self.rpm_factor
            key = ("rpm", state, round(value / step))
            got = self._cache.get(key)
            if got is None:
                got = self._cache[key] = (
                    zk.encode_control("mode", sw=state, rpm_factor=self.rpm_factor)[0],
                    zk.encode_control("rpm", target_rpm=key[2] * step, rpm_factor=self.rpm_factor)[0])
            return got
        key = ("thr", state, round(value / _THROTTLE.scale))
        got = self._cache.get(key)
        if got is None:
            id1 = zk.encode_control("control", sw=state, throttle_pct=key[2] * _THROTTLE.scale)[0]
            got = (id1, zk.encode_control("mode", sw="none", rpm_factor=0)[0]) if self.has_rpm else (id1,)
            self._cache[key] = got
        return got

    def plan_check(self) -> Plan:
        """The schedule as a :class:`~zkzap.api.prestart.Plan`: every frame it sends and each
        RPM target with its ``FILE:LINE``, checked against the ECU before the first frame."""
        targets = [(r.rpm, f"schedule {self.name}:{r.line}") for r in self.rows if r.rpm is not None]
        return Plan(self.frames(), targets=targets, what=f"schedule {self.name}")

    def frame_at(self, t):
        """The frame to send at ``t`` (the session calls this every control period)."""
        cmd = self.command_at(t)
        if cmd is None:
            return None
        frames = self._frames(*cmd)
        self._toggle = (self._toggle + 1) % len(frames)
        return frames[self._toggle]

    def frames(self):
        """Every distinct frame the schedule's rows send (for consent and validation)."""
        out = []
        for r in self.rows:
            out += self._frames(r.mode, r.state, r.rpm if r.rpm is not None else r.throttle)
        return out

    # --- the plan ------------------------------------------------------------------------------------
    def plan(self, rate: float) -> list[tuple[float, str, str, Optional[float], tuple[bytes, ...]]]:
        """``[(t, mode, state, value, frames)]``: each change of the command sent at ``rate`` Hz.

        Changes happen at row times and, with linear ramps, where the rounded value steps; only
        those control periods are evaluated, so a schedule of days costs what one of minutes does.
        """
        candidates = set()
        rows = self.rows
        for i, r in enumerate(rows):
            candidates.add(math.ceil(r.t * rate - 1e-9))
            if self.interpolate == "linear" and i + 1 < len(rows):
                n = rows[i + 1]
                if n.mode != r.mode or n.t <= r.t:
                    continue
                a = r.rpm if r.rpm is not None else r.throttle
                b = n.rpm if n.rpm is not None else n.throttle
                if a == b:
                    continue                          # a flat segment: nothing changes inside it
                step = 10 * self.rpm_factor if r.mode == "rpm" else _THROTTLE.scale
                lo, hi = sorted((a, b))
                k = math.floor(lo / step)
                while k * step <= hi + step:
                    edge = (k + 0.5) * step           # where rounding moves to the next level
                    if lo <= edge <= hi:                 # inclusive: a value on an edge rounds half to even
                        ts = r.t + (edge - a) / (b - a) * (n.t - r.t)
                        j = math.floor(ts * rate)
                        candidates.update((j - 1, j, j + 1, j + 2))     # either side of the edge
                    k += 1
        last_period = int(self.length * rate + 1e-9)
        out = []
        last = None
        for j in sorted(c for c in candidates if 0 <= c <= last_period):
            t = j / rate
            cmd = self.command_at(t)
            if cmd is None:
                continue
            frames = self._frames(*cmd)
            if frames != last:
                mode, state, _ = cmd
                shown = zk.decode_control(frames[0])
                value = (frames_target(frames[1], self.rpm_factor) if mode == "rpm"
                         else shown["throttle_pct"])
                out.append((round(t, 3), mode, state, value, frames))
                last = frames
        return out

    # --- steps for steady-state reduction ------------------------------------------------------------
    def steps(self) -> list[tuple[int, Row, float, float]]:
        """``[(number, row, t_start, t_end)]``: each steady target in state ``run`` that holds for
        some time (a standby, stop or pwm row is no steady state of the engine). Rows that repeat
        the target before them (same mode, state and target) are one step, from the first row's
        time; with ``--interpolate linear`` a row whose target ramps to the next row's is no step
        (:meth:`ramps`)."""
        out = []
        for i, r, end in self._segments():
            if r.state != "run" or self._ramps(i):
                continue
            if out and out[-1][3] == r.t and _same_target(out[-1][1], r):
                out[-1] = (out[-1][0], out[-1][1], out[-1][2], end)
                continue
            out.append((len(out) + 1, r, r.t, end))
        return out

    def ramps(self) -> list[tuple[Row, float, float, str]]:
        """``[(row, t_start, t_end, why)]``: the rows in state ``run`` whose target ramps to the next
        row's (``--interpolate linear``): no steady state, so no step."""
        return [(r, r.t, end, f"ramp {r.target_text()} to {self.rows[i + 1].target_text()}")
                for i, r, end in self._segments() if r.state == "run" and self._ramps(i)]

    def _segments(self):
        for i, r in enumerate(self.rows[:-1]):
            end = self.rows[i + 1].t
            if end > r.t:
                yield i, r, end

    def _ramps(self, i) -> bool:
        if self.interpolate != "linear":
            return False
        r, n = self.rows[i], self.rows[i + 1]
        return n.mode == r.mode and (r.rpm, r.throttle) != (n.rpm, n.throttle)


def _same_target(a, b) -> bool:
    return a.mode == b.mode and a.state == b.state and a.target_text() == b.target_text()


def frames_target(frame, factor):
    """The target rpm of the control ID 7 ``frame`` sent with RPM factor ``factor``."""
    return zk.decode_control(frame)["rpm_value"] * 10 * factor
