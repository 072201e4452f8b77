"""Alarms and the start interlock of an engine stand: one :class:`Alarms` per stand (a browser
console, a shell, a batch), shared by every session it runs.

An alarm is raised by a trip — a violated limit, an ECU error, an abort or Ctrl-C, the dead-man
rule, a hung or a hot start — and stays **latched** until the controlling operator acknowledges
it (:meth:`Alarms.acknowledge`, which records who and when). A warning (a limit's warning band)
is listed too, but latches nothing.

A start is refused (:meth:`Alarms.refusal`) while any alarm is latched, and after a trip until
the engine has been seen back in a restartable state: the ECU reports stop or standby with the
rotor stopped (:func:`zkzap.api.session.at_rest`) and EGT below :attr:`Alarms.restart_egt_c`
(:data:`RESTART_EGT_C` unless told). After a trip the next start begins at setpoint 0: a start
never resumes the setpoint that was in force.

Every status record of every session goes through :meth:`Alarms.observe`: the limits'
entries become alarms, and the start is watched: a **hung start** (the ECU in a start-up state
for longer than :attr:`Alarms.hung_start_s` without reaching a running state) and a **hot
start** (EGT above :attr:`Alarms.hot_start_egt_c` during ignition, preheat or the fuel ramp)
raise a latched alarm; :attr:`Alarms.tripped` holds such an alarm for the session to end with
(a session that controls the engine sends its abort).

Nothing here imports click, rich or pyserial.
"""

from __future__ import annotations

import time

from ..errors import DeviceError

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Callable, Iterable, Mapping, Optional

#: EGT below which an engine that tripped may be started again (degC, ``--restart-egt``): well
#: below the usual 700-850 degC running limits, and above the 100 degC an ECU's cool-down ends at.
RESTART_EGT_C = 150.0
#: Longest an ECU may stay in its start-up states (ignition, preheat, fuel ramp, restart) before
#: the start counts as hung (seconds of the session's clock, ``--hung-start``; 0: not watched).
#: A small turbine reaches idle in 20-60 s.
HUNG_START_S = 90.0
#: EGT above which a start counts as hot (degC, ``--hot-start``; 0: not watched): during
#: ignition, preheat and the fuel ramp.
HOT_START_EGT_C = 850.0
#: Engine states of a start (zk.ENGINE_STATES): ignition-min-throttle, ignition, preheat,
#: fuel-ramp, restart.
START_STATES = frozenset({2, 3, 4, 5, 13})
#: The states of a hot start's EGT watch: ignition and preheat and the fuel ramp.
IGNITION_STATES = frozenset({2, 3, 4, 5})
#: Running states (learning ones included): a start that reaches one is done.
RUNNING_STATES = frozenset({6, 7, 8, 9, 10, 11})


_stand = []


class installed:
    """``with installed(alarms):`` the sessions of this process share ``alarms`` (a shell's or a
    batch's: a trip in one command latches for the next); :func:`current` gives it."""

    def __init__(self, alarms: Alarms) -> None:
        self.alarms = alarms

    def __enter__(self) -> Alarms:
        _stand.append(self.alarms)
        return self.alarms

    def __exit__(self, *exc: object) -> bool:
        _stand.remove(self.alarms)
        return False


def current() -> Optional[Alarms]:
    """The alarm list installed for this process's sessions (:class:`installed`), or None."""
    return _stand[-1] if _stand else None


class StartRefused(DeviceError):
    """A start refused by the interlock (exit status 5): an alarm latched, or an engine not yet
    back at rest and cool after a trip; nothing was sent."""


class StartAlarm(DeviceError):
    """A hung or hot start (exit status 5): the session ends with its abort."""


class Alarm:
    """One entry of the alarm list. ``level``: ``alarm`` (latched until acknowledged) or
    ``warning``; ``kind``: ``limit``, ``ecu-error``, ``abort``, ``interrupted``, ``dead-man``,
    ``hung-start``, ``hot-start``, ``silence``, ``port``, ``warning``; ``active``: the condition
    still holds (a limit still violated)."""

    __slots__ = ("id", "level", "kind", "text", "limit", "field", "value", "t", "wall", "active", "acked_by",
                 "acked_at")

    def __init__(self, id: int, level: str, kind: str, text: str, *, limit: Optional[str] = None,
                 field: Optional[str] = None, value: Any = None, t: Optional[float] = None,
                 wall: Optional[float] = None) -> None:
        self.id = id
        self.level = level
        self.kind = kind
        self.text = text
        self.limit = limit
        self.field = field
        self.value = value
        self.t = t
        self.wall = time.time() if wall is None else wall
        self.active = True
        self.acked_by = None
        self.acked_at = None

    @property
    def latched(self) -> bool:
        return self.level == "alarm" and self.acked_by is None

    def to_dict(self) -> dict:
        return {"id": self.id, "level": self.level, "kind": self.kind, "text": self.text, "limit": self.limit,
                "field": self.field, "value": self.value, "t": None if self.t is None else round(self.t, 3),
                "time": _iso(self.wall), "active": self.active, "latched": self.latched,
                "acked_by": self.acked_by, "acked_at": None if self.acked_at is None else _iso(self.acked_at)}


def _iso(wall) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(wall)) + f".{int(wall * 1000) % 1000:03d}Z"


class Alarms:
    """The alarm list and the start interlock of one stand (see the module's text).

    ``conditions``: the limits (:class:`~zkzap.api.expr.Condition`), to name a violated one's
    field and value; ``notify(message)`` is told of every alarm raised and acknowledged;
    ``on_change()`` whenever the list changes (a view redraws it)."""

    def __init__(self, conditions: Iterable[Any] = (), *, restart_egt_c: float = RESTART_EGT_C,
                 hung_start_s: float = HUNG_START_S, hot_start_egt_c: float = HOT_START_EGT_C,
                 notify: Optional[Callable[[str], None]] = None, on_change: Optional[Callable[[], None]] = None,
                 keep: int = 200, tell_limits: bool = True) -> None:
        self.by_text = {c.text: c for c in conditions}
        self.tell_limits = tell_limits    # False: a limit's alarm is not told (its LimitSet tells it)
        self.restart_egt_c = restart_egt_c
        self.hung_start_s = hung_start_s
        self.hot_start_egt_c = hot_start_egt_c
        self.notify = notify or (lambda message: None)
        self.on_change = on_change or (lambda: None)
        self.keep = keep
        self.entries = []
        self._next = 1
        self._active = {}              # limit text -> its alarm or warning while it holds
        self.pending = None            # the trip the engine has not been seen at rest and cool after
        self.zero_setpoint = False     # a trip happened: the next start begins at setpoint 0
        self.tripped = None            # a start alarm for the running session to end with
        self.latest = {}               # the last engine state, rpm and EGT seen
        self._start_t = None           # when the ECU entered its start-up states

    # -- raising and acknowledging ---------------------------------------------------------------

    def raise_alarm(self, kind: str, text: str, *, level: str = "alarm", limit: Optional[str] = None,
                    field: Optional[str] = None, value: Any = None, t: Optional[float] = None) -> Alarm:
        """Add an entry; an alarm also marks a trip (see :meth:`refusal`)."""
        a = Alarm(self._next, level, kind, text, limit=limit, field=field, value=value, t=t)
        self._next += 1
        self.entries.append(a)
        if len(self.entries) > self.keep:           # the oldest acknowledged ones go first
            for i, old in enumerate(self.entries):
                if not old.latched and not old.active:
                    del self.entries[i]
                    break
        if level == "alarm":
            self.pending = a
            self.zero_setpoint = True
            if kind != "limit" or self.tell_limits:
                self.notify(f"ALARM: {text}")
        self.on_change()
        return a

    def trip(self, kind: str, text: str, *, t: Optional[float] = None, limit: Optional[str] = None,
             **kw: Any) -> Alarm:
        """A trip (an abort, an ECU error, the dead-man rule...): a latched alarm, unless the same
        trip is already listed and latched (a violated limit or a start alarm raised it as it
        happened)."""
        for a in reversed(self.entries):
            if a.latched and (a.text == text or (limit is not None and a.limit == limit)
                              or (kind == "alarm" and a.kind in ("hung-start", "hot-start"))):
                self.pending = a
                self.zero_setpoint = True
                return a
        if limit is not None:
            kw["limit"] = limit
        return self.raise_alarm(kind, text, t=t, **kw)

    def acknowledge(self, who: str, ids: Optional[Iterable[int]] = None) -> list[Alarm]:
        """Acknowledge the latched alarms (``ids``: only these), recording ``who`` and when; returns
        those acknowledged. The trip's restart rule still holds until the engine is at rest and
        cool."""
        now = time.time()
        done = []
        for a in self.entries:
            if a.latched and (ids is None or a.id in ids):
                a.acked_by, a.acked_at = who, now
                done.append(a)
        if done:
            self.notify(f"{who} acknowledged {len(done)} alarm{'s' if len(done) > 1 else ''}: "
                        + "; ".join(a.text for a in done))
            self.on_change()
        return done

    @property
    def latched(self) -> list:
        return [a for a in self.entries if a.latched]

    def to_list(self) -> list:
        """The list, newest first, as dicts (for a view or JSON)."""
        return [a.to_dict() for a in reversed(self.entries)]

    # -- the interlock --------------------------------------------------------------------------

    def settings(self, restart_egt_c: Optional[float] = None, hung_start_s: Optional[float] = None,
                 hot_start_egt_c: Optional[float] = None, conditions: Iterable[Any] = ()) -> None:
        """Take a session's options (those given) and its limits' conditions (to name them)."""
        if restart_egt_c is not None:
            self.restart_egt_c = restart_egt_c
        if hung_start_s is not None:
            self.hung_start_s = hung_start_s
        if hot_start_egt_c is not None:
            self.hot_start_egt_c = hot_start_egt_c
        for c in conditions:
            self.by_text.setdefault(c.text, c)

    def restartable(self, latest: Optional[Mapping[str, Any]] = None) -> bool:
        """The engine is at rest (stop or standby, rotor stopped) and EGT below the restart level."""
        from .session import at_rest

        latest = self.latest if latest is None else latest
        egt = latest.get("egt_c")
        return at_rest(latest) and egt is not None and egt < self.restart_egt_c

    def refusal(self, latest: Optional[Mapping[str, Any]] = None, setpoint: Optional[float] = None) -> Optional[str]:
        """Why a start is refused now (None: it may start). ``latest``: the ECU's latest values (the
        alarm list's own when not given); ``setpoint``: the throttle (%) or rpm target asked for."""
        latched = self.latched
        if latched:
            first = latched[0]
            more = f" (and {len(latched) - 1} more)" if len(latched) > 1 else ""
            return (f"start refused: alarm latched: {first.text}{more}; acknowledge "
                    f"{'it' if len(latched) == 1 else 'them'} first")
        latest = self.latest if latest is None else latest
        if self.pending is not None:
            if self.restartable(latest):
                self.pending = None
            else:
                state = latest.get("engine_state_name") or "unknown"
                egt = latest.get("egt_c")
                rpm = latest.get("rpm")
                return (f"start refused: the engine is not back at rest and cool after the trip ({state}, EGT "
                        f"{'?' if egt is None else f'{egt:g}'} °C, {'?' if rpm is None else f'{rpm:,}'} rpm); a start "
                        f"needs stop or standby with the rotor stopped and EGT below {self.restart_egt_c:g} °C")
        if self.zero_setpoint and setpoint:
            return (f"start refused: after a trip the engine starts at setpoint 0 (asked {setpoint:g}); "
                    f"set it to 0 and start, then raise it")
        return None

    def started(self) -> None:
        """A start went out: the setpoint rule of the last trip is spent."""
        if self.zero_setpoint:
            self.zero_setpoint = False
            self.on_change()

    def check_start(self, latest: Optional[Mapping[str, Any]] = None, setpoint: Optional[float] = None) -> None:
        """Raise :class:`StartRefused` with the reason when a start is refused now."""
        why = self.refusal(latest, setpoint)
        if why is not None:
            raise StartRefused(why)

    # -- the records ----------------------------------------------------------------------------

    def seen(self, latest: Mapping[str, Any]) -> None:
        """The engine's state, rpm and EGT as last seen (a telemetry's latest values: those of
        frames no record was written for, under --ids, too)."""
        for k in ("engine_state", "engine_state_name", "rpm", "egt_c"):
            v = latest.get(k)
            if v is not None:
                self.latest[k] = v

    def observe(self, t: float, rec: Mapping[str, Any]) -> None:
        """One status record: its limit entries, and the start's hung and hot watches."""
        self.seen(rec)
        violated = rec.get("limit") or ()
        warned = rec.get("warnings") or ()
        if violated or warned or self._active:
            self._limits(t, rec, violated, warned)
        state = rec.get("engine_state")
        if state is None:
            return
        if state in START_STATES:
            if self._start_t is None:
                self._start_t = t
            elif self.hung_start_s and t - self._start_t > self.hung_start_s:
                self._start_t = float("inf")            # once per start
                self._start_alarm("hung-start", f"hung start: the ECU has been starting for {self.hung_start_s:g} s "
                                                f"without reaching a running state ({rec.get('engine_state_name')})",
                                  t, None)
            egt = rec.get("egt_c")
            if (self.hot_start_egt_c and state in IGNITION_STATES and egt is not None
                    and egt > self.hot_start_egt_c and not self._hot):
                self._hot = True
                self._start_alarm("hot-start", f"hot start: EGT {egt:g} °C during {rec.get('engine_state_name')} "
                                               f"(above {self.hot_start_egt_c:g} °C)", t, egt)
        else:
            self._start_t = None
            self._hot = False

    _hot = False

    def _start_alarm(self, kind, text, t, value):
        a = self.raise_alarm(kind, text, t=t, field="egt_c" if value is not None else "engine_state", value=value)
        if self.tripped is None:
            self.tripped = StartAlarm(text)
        return a

    def _limits(self, t, rec, violated, warned):
        from .limits import KEYS_BY_ID

        now = set(violated) | set(warned)
        carried = KEYS_BY_ID.get(rec.get("id"), ())
        for text, a in list(self._active.items()):
            if a.field is not None and a.field not in carried:
                continue                    # this frame does not carry the field: nothing said
            if text not in now or (a.level == "warning" and text in violated):
                a.active = False
                del self._active[text]
                self.on_change()
        for level, texts in (("alarm", violated), ("warning", warned)):
            for text in texts:
                if text in self._active:
                    continue
                cond = self.by_text.get(text)
                field = cond.field if cond is not None else None
                value = rec.get(field) if field is not None else None
                if getattr(cond, "rate", False):
                    field, value = f"{field}/s", None       # the record holds the field, not its rate
                said = f"{field}={value:g}" if isinstance(value, (int, float)) else (field or text)
                what = "violated" if level == "alarm" else "in its warning band"
                self._active[text] = self.raise_alarm(
                    "limit" if level == "alarm" else "warning", f"limit {text} {what}: {said} at t={t:.2f} s",
                    level=level, limit=text, field=field, value=value, t=t)
