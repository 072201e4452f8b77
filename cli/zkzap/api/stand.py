"""The engine stand: its hooks (:class:`Stand`: limits, per-step averages, external sensors,
corrected values, the ESR answer, logbook statistics, fed every decoded status frame through
:attr:`zkzap.api.telemetry.Telemetry.on_frame`) and the one stand session every front end runs
(:class:`StandSession`: the hooks, the alarm list and start interlock, the records' sink and the
session loop with its ends).

A front end — ``zk monitor``, ``zk send --for``, ``zk profile``, a batch's or a shell's line,
the browser console — builds a :class:`Stand` from its options before any port opens, wraps it
in a :class:`StandSession` with where its records go (a writer object of :mod:`zkzap.io`, made
by the front end: the library does not import the writers), runs it, renders what it reports
and hands it the operator's input (a start, an acknowledgement).
"""

from __future__ import annotations

from . import logbook as _logbook

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Callable, Iterable, Optional

    from .alarms import Alarm, Alarms
    from .limits import LimitSet
    from .session import Outcome, Session
    from .telemetry import Telemetry

    Notify = Callable[[str], None]
    Sink = Callable[[dict], None]
    OnUpdate = Callable[[dict, dict], None]


class Stand:
    """The hooks of one session (see the module's text). ``aux``: an :class:`~zkzap.api.aux.AuxHub`
    (external sensors, merged into the records); ``corrections``: a
    :class:`~zkzap.api.ambient.RecordCorrections` (corrected fields in the records); ``answer``: a
    :class:`~zkzap.api.esr.PressureAnswer` (control ID 8 frames for the ECU's ESR request);
    ``engine``: the engine's name in the logbook and the summary."""

    def __init__(self, limits: Optional[LimitSet] = None, averager: Any = None, logbook: Optional[str] = None, *,
                 aux: Any = None, corrections: Any = None, answer: Any = None, engine: Optional[str] = None) -> None:
        self.limits = limits if limits else None          # api.limits.LimitSet (None: no limits)
        self.averager = averager                           # api.steady.StepAverager
        self.logbook = logbook                             # path of the logbook file
        self.aux = aux if aux else None
        self.corrections = corrections
        self.answer = answer
        self.engine = engine
        self.alarm_settings = {}                           # api.alarms.Alarms keywords the session's alarms take
        self.stats = _logbook.RunStats()
        self.clock = None                                  # the session's (link.clock)
        self.write = None                                  # how an ESR answer is sent (the session's source)
        self._started = False

    def start(self, timeout: float) -> None:
        """Before the port opens: the external sensors' readers, and their first lines (their
        field names; a silent sensor is exit 3 with nothing sent)."""
        if self.aux is not None and not self._started:
            from .. import checking

            checking.effect("sensors")     # opening a sensor's port is as far as a check goes
            self._started = True
            self.aux.start(timeout)
            self._check_fields()
            if self.averager is not None:
                self.averager.add_channels(self.aux.channels.values())

    def _check_fields(self):
        from ..errors import unknown_name

        quantities = []
        if self.averager is not None:
            quantities += [self.averager.thrust, self.averager.flow] + list(self.averager.ambient or ())
        if self.corrections is not None:
            c = self.corrections
            quantities += [c.temperature, c.pressure, c.thrust, c.flow]
        if self.answer is not None:
            quantities.append(getattr(self.answer, "quantity", None))
        if self.limits is not None:
            from .ambient import RecordCorrections
            from .limits import FIELDS

            for c in self.limits.conditions:
                if c.field not in FIELDS and c.field not in RecordCorrections.KEYS and c.field not in self.aux.fields:
                    self.close()
                    raise unknown_name("limit", c.field, list(FIELDS) + list(self.aux.fields), noun="field",
                                       otherwise=f"; the --aux sensors give {', '.join(self.aux.fields) or 'no field'}")
        for q in quantities:
            if q is not None and q.field is not None and q.field not in self.aux.fields:
                self.close()
                raise unknown_name(q.option, q.field, self.aux.fields, noun="sensor field",
                                   otherwise=f"; the --aux sensors give {', '.join(self.aux.fields) or 'no field'}")

    def close(self) -> None:
        """Stop the external sensors' readers (at the session's end, before any summary: their
        counts are frozen then). Closing twice is closing once."""
        if self.aux is not None:
            self.aux.close()

    def columns(self, record_columns):
        """Wrap the record column function: limit entries, sensor fields and corrected values
        become CSV columns."""
        extra = []
        if self.limits is not None:
            extra += ["warnings", "limit"]
        if self.aux is not None:
            extra += list(self.aux.fields)
        if self.corrections is not None:
            from .ambient import RecordCorrections

            extra += list(RecordCorrections.KEYS)
        if not extra:
            return record_columns

        def cols(snapshot, ids=None):
            return record_columns(snapshot, ids) + extra

        return cols

    def attach(self, telemetry, source, on_update):
        """Hook into ``telemetry``; returns the live-view callback (limit lines added)."""
        telemetry.on_frame = self.on_frame
        self.clock = source.clock
        self.write = source.write
        if self.aux is not None:
            self.aux.bind(source.now, source.clock.speed)
        if on_update is None or self.limits is None:
            return on_update
        limits = self.limits

        def update(snapshot, health):
            on_update(snapshot, dict(health, limits=limits.dashboard_lines()))

        return update

    def on_frame(self, t, rec):
        aux = self.aux
        if aux is not None:
            for ta, reading in aux.drain():
                if self.averager is not None:
                    self.averager.feed_aux(ta, reading)
        self.stats.feed(t, rec)
        if self.averager is not None:
            self.averager.feed(t, rec)
        more = {}
        if aux is not None:
            more.update(aux.merge(t))
        if self.corrections is not None:
            more.update(self.corrections.record(t, rec, aux.value if aux is not None else None))
        # the limits see the record's sensor and corrected values too (thrust<=20, ...)
        extra = self.limits.check(t, rec, more) if self.limits is not None else {}
        extra.update(more)
        if self.answer is not None:
            frame = self.answer.on_frame(t, rec)
            if frame is not None and self.write is not None:
                self.write(frame)
        return extra or None

    def summary(self) -> dict:
        """Entries for the run summary: ``limits`` (per condition), ``running_s``, ``starts``, the
        external sensors (``aux``), the ESR answers (``air_pressure_answers``), ``engine``."""
        out = {"running_s": round(self.stats.running_s, 3), "starts": self.stats.starts}
        if self.engine is not None:
            out["engine"] = self.engine
        if self.limits is not None:
            out["limits"] = self.limits.summary()
        if self.aux is not None:
            out["aux"] = self.aux.summary()
        if self.answer is not None:
            out["air_pressure_answers"] = self.answer.summary()
        return out

    def warned_violation(self, outcome):
        """With ``--on-limit warn``: after a run that otherwise ended well, the
        :class:`~zkzap.api.limits.LimitViolation` (exit 5) naming the limits violated (the run went
        on); None when none was, or the run ended otherwise."""
        limits = self.limits
        if limits is None or limits.on_limit != "warn" or not outcome.ok or not limits.violated():
            return None
        from .limits import LimitViolation

        return LimitViolation(f"limit violated (--on-limit warn: the run went on): {', '.join(limits.violated())}")

    def exit_status(self, outcome: Outcome) -> int:
        """The run's exit status: the outcome's, or 5 for a limit violated under ``--on-limit warn``."""
        err = self.warned_violation(outcome)
        return err.code if err is not None else outcome.exit_code

    def log_run(self, *, command: str, port: Optional[str], schedule: Optional[str], files: Iterable[Optional[str]],
                outcome: Outcome, tel: Telemetry, session: Any) -> Optional[int]:
        """Append this run to the logbook (when one was given); returns the run's ID."""
        if not self.logbook:
            return None
        s = tel.summary()
        duration = (session.ended_t or 0.0) if session is not None else 0.0
        clock = self.clock
        if clock is None or clock.wall(0.0) is None:      # never attached, or a replay of a raw log
            from ..link.clock import SessionClock

            clock = SessionClock()
            clock.wall0 -= clock.real(duration)
        # the real moments the session's start and end correspond to (its one clock)
        run = {
            "started": _logbook.iso(clock.wall(0.0)), "ended": _logbook.iso(clock.wall(duration)),
            "duration_s": round(duration, 3), "running_s": round(self.stats.running_s, 3),
            "starts": self.stats.starts, "max_rpm": s["max_rpm"], "max_egt_c": s["max_egt_c"],
            "fuel_used_l": s["fuel_used_l"], "errors": [f"{e['code']} {e['name']}" for e in s["errors"]],
            "limits_violated": self.limits.violated() if self.limits is not None else [],
            "command": command, "port": port, "schedule": schedule, "files": [f for f in files if f],
            "outcome": outcome.reason, "exit_status": self.exit_status(outcome), "engine": self.engine,
            "throttle_s": self.stats.throttle_s,
        }
        return _logbook.record(self.logbook, run)


def shared_stand(notify: Optional[Notify] = None) -> Any:
    """``with shared_stand(notify):`` the stand sessions this process runs one after the other (a
    shell's or a batch's lines) share one alarm list: a trip in one latches for the next, until
    an ``ack`` acknowledges it (:func:`zkzap.api.alarms.installed`); the limits' own messages
    say their violations, the list says the rest through ``notify``."""
    from .alarms import Alarms, installed

    return installed(Alarms(tell_limits=False, notify=notify))


class StandSession:
    """One engine stand's session: the same object under every front end.

    It carries the stand's hooks (``stand``, a :class:`Stand` or None: limits, external sensors,
    corrected values, the ESR answer, the logbook and the engine's name), the alarm list and
    start interlock (``alarms``, an :class:`~zkzap.api.alarms.Alarms`; by default the one
    installed for the process by a shell or a batch, :func:`zkzap.api.alarms.current`, else its
    own), the records' sink (given to :meth:`attach`: the front end's writer, every output
    format of :mod:`zkzap.io`), and runs the :class:`~zkzap.api.session.Session` loop with the
    ends every engine session keeps: the abort on every abnormal end, the signal-safe end (every
    terminating signal reaches the abort), the trip latched as an alarm and the rundown
    recorded after it.

    Its life::

        ss = StandSession(stand, notify=print)        # before any port opens (options checked)
        ss.start(timeout)                             # the sensors' first lines: a silent one is exit 3
        ss.record(output, "--output run.csv")         # the one sink of the records (or attach's sink)
        on_update = ss.attach(source, telemetry, on_update=on_update)
        outcome = ss.run(control=..., duration=...)   # again for each session of a console
        ss.close()                                    # the sensors stop: one count for every summary
        ss.close_output()                             # the records queued are written, the file closed
        ss.summary(), ss.log_run(...)                 # the run's entries, its logbook row

    ``notify(message)``: how the session's, the limits' and the alarms' messages are said (a
    front end puts them above its live view). A console's sessions follow one another on one
    clock (``restart=False`` to :meth:`run`).
    """

    def __init__(self, stand: Optional[Stand] = None, *, alarms: Optional[Alarms] = None,
                 notify: Optional[Notify] = None) -> None:
        from .alarms import Alarms, current

        self.stand = stand
        self.notify = notify or (lambda message: None)
        #: the alarm list and start interlock (shared with the process's shell or batch when one
        #: is installed: a trip in one command latches for the next)
        self.alarms = alarms if alarms is not None else (current() or Alarms(tell_limits=False, notify=self.notify))
        if stand is not None:
            self.alarms.settings(conditions=self.limits.conditions if self.limits is not None else (),
                                 **stand.alarm_settings)
        self.source = None
        self.telemetry = None
        self.sink = None
        #: where the records are written (:meth:`record`: a writer of :mod:`zkzap.io`; None: the
        #: front end's sink given to :meth:`attach`, or nowhere)
        self.output = None
        self._write = None             # the output's write, made in its lane
        self.session = None            # the last Session run
        self._closed = False

    @property
    def limits(self) -> Optional[LimitSet]:
        """The stand's :class:`~zkzap.api.limits.LimitSet` (None: no limits)."""
        return self.stand.limits if self.stand is not None else None

    @property
    def answers_esr(self) -> bool:
        """Something answers the ECU's request for the air pressure (``--air-pressure``)."""
        return self.stand is not None and self.stand.answer is not None

    def start(self, timeout: float) -> None:
        """Before the port opens: the external sensors' readers and their first lines (a silent
        sensor is exit 3 with nothing sent)."""
        if self.stand is not None:
            try:
                self.stand.start(timeout)
            except BaseException:
                self.close()
                raise

    def record(self, output: Any, what: str, *, wait: Optional[bool] = None) -> Sink:
        """The session's records go to ``output`` (a writer of :mod:`zkzap.io`, made by the front
        end: ``output.offload(lane)`` returns its write made in that lane, ``output.close()``
        writes what is queued and closes), each record once, written off the session's thread
        in one :class:`~zkzap.offload.Lane` (``what``: the output's name in messages; ``wait``:
        what a full queue does, see :mod:`zkzap.offload`). Every session this object runs, and
        every trip it marks, writes through this one sink; :meth:`close_output` closes it.
        Returns the sink (``sink(record)``)."""
        if self.output is not None:
            from ..errors import UsageError

            raise UsageError(f"the records go to {self.output!r} already: one output per stand session")
        from ..offload import Lane

        self.output = output
        self._write = output.offload(Lane(what, wait=wait))
        return self._write

    @property
    def lane(self) -> Any:
        """The :class:`~zkzap.offload.Lane` the records are written in (None: no :meth:`record`)."""
        return getattr(self.output, "lane", None) if self.output is not None else None

    def close_output(self) -> None:
        """Write the records still queued and close the output of :meth:`record` (a stalled one
        is abandoned, see :mod:`zkzap.offload`). Twice is once."""
        if self.output is not None:
            self.output.close()

    def attach(self, source: Any, telemetry: Telemetry, sink: Optional[Sink] = None,
               on_update: Optional[OnUpdate] = None, *, watch: Optional[Sink] = None) -> Optional[OnUpdate]:
        """Run on ``source`` (a live or replayed ZK source) through ``telemetry`` into ``sink``
        (``sink(record)``: the front end's own writer; None: the output of :meth:`record`, else
        records are not kept); ``watch(record)`` is also handed every record once it is queued
        for writing (a console's pages). Returns the live view's callback with the stand's limit
        lines and the alarm list added (None stays None)."""
        if sink is not None and self._write is not None:
            from ..errors import UsageError

            raise UsageError("the records have their output already (record): no second sink")
        sink = sink or self._write or (lambda rec: None)
        if watch is not None:
            write = sink

            def sink(rec):
                write(rec)
                watch(rec)

        self.source, self.telemetry, self.sink = source, telemetry, sink
        if self.stand is not None:
            on_update = self.stand.attach(telemetry, source, on_update)
        if on_update is not None and getattr(source, "live", True):
            alarms, inner = self.alarms, on_update

            def on_update(snapshot, health):
                inner(snapshot, dict(health, alarms=alarms.to_list()[:4]) if alarms.entries else health)

        return on_update

    def rebind(self, source: Any) -> None:
        """The source is wrapped (a tap that copies every frame to a capture or a bridge): ESR
        answers go out through it, recorded like every control frame."""
        self.source = source
        if self.stand is not None:
            self.stand.write = source.write

    def run(self, **options: Any) -> Outcome:
        """One :class:`~zkzap.api.session.Session` over the attached source, with the stand's
        alarms (a live source only: a replay starts nothing), limits and ESR answer; ``options``
        are the Session's (control, rate, abort, count, duration, silence, end, rundown, ...).
        Returns its :class:`~zkzap.api.session.Outcome`; :attr:`session` is the Session."""
        self.session = self.make_session(**options)
        return self.session.run()

    def make_session(self, **options: Any) -> Session:
        """The :class:`~zkzap.api.session.Session` :meth:`run` runs (for a front end that needs
        it before it runs: a console cuts it short from its requests)."""
        from .session import Session

        source = options.pop("source", None) or self.source
        options.setdefault("notify", self.notify)
        options.setdefault("limits", self.limits)
        options.setdefault("answers_esr", self.answers_esr)
        if getattr(source, "live", True):
            options.setdefault("alarms", self.alarms)
        return Session(source, self.telemetry, self.sink, **options)

    def acknowledge(self, who: str, ids: Optional[Iterable[int]] = None) -> list[Alarm]:
        """The operator ``who`` acknowledges the latched alarms (``ids``: only these); returns the
        :class:`~zkzap.api.alarms.Alarm` entries acknowledged (each says who and when). A trip's
        restart rule holds on until the engine is at rest and cool."""
        return self.alarms.acknowledge(who, ids)

    def refusal(self, setpoint: Optional[float] = None) -> Optional[str]:
        """Why a start is refused now (None: it may start), by the ECU's latest values: an alarm
        latched, an engine not yet at rest and cool after a trip, a setpoint but 0 for the first
        start after one (:meth:`~zkzap.api.alarms.Alarms.refusal`), or a limit violated now (a
        rate, or a limit of other engine states than the ECU's, is not judged here)."""
        latest = self.telemetry.latest if self.telemetry is not None else None
        why = self.alarms.refusal(latest, setpoint)
        if why is not None or self.limits is None or latest is None:
            return why
        for c in self.limits.conditions:
            when = getattr(c, "when", None)
            if getattr(c, "rate", False) or (when is not None and latest.get("engine_state") not in when):
                continue
            value = latest.get(c.field)
            if value is not None and c.check(value) == "violated":
                return f"start refused: limit {c.text} is violated now ({c.field}={value:g})"
        return None

    def check_start(self, setpoint: Optional[float] = None) -> None:
        """Raise :class:`~zkzap.api.alarms.StartRefused` with the reason when a start is refused
        now (:meth:`refusal`)."""
        why = self.refusal(setpoint)
        if why is not None:
            from .alarms import StartRefused

            raise StartRefused(why)

    def mark_trip(self, kind: str, why: str, sent: Optional[str], t: Optional[float] = None) -> Alarm:
        """A trip the front end made (an operator's abort, the dead-man rule: a session that
        ended as asked, but as a trip): the alarm latched, and, when ``sent`` (the abort's
        ``standby`` or ``stop``) went out, a trip record in the records, as a limit's or a
        signal's trip is marked by the session itself. Returns the alarm."""
        from .session import Outcome, describe_abort, trip_record

        aborted = sent in ("standby", "stop")
        said = f"{why}; sent {describe_abort(sent)}" if aborted else why
        alarm = self.alarms.trip(kind, said, t=t)
        if aborted and self.source is not None and self.sink is not None:
            src = self.source
            self.sink(trip_record(Outcome(kind, aborted=sent), src.now(), src.clock, why=why))
        return alarm

    def close(self) -> None:
        """Stop the external sensors (at the session's end, before any summary). Twice is once."""
        if self.stand is not None and not self._closed:
            self._closed = True
            self.stand.close()

    def summary(self) -> dict:
        """The stand's entries of a run summary (:meth:`Stand.summary`) and the alarm list."""
        out = self.stand.summary() if self.stand is not None else {}
        if self.alarms.entries:
            out["alarms"] = self.alarms.to_list()
        return out

    def exit_status(self, outcome: Outcome) -> int:
        """The run's exit status (5 for a run that went on through a violated limit)."""
        return self.stand.exit_status(outcome) if self.stand is not None else outcome.exit_code

    def log_run(self, *, command: str, port: Optional[str], schedule: Optional[str] = None,
                files: Iterable[Optional[str]] = (), outcome: Outcome, ended_t: Optional[float] = None) -> Optional[int]:
        """Append the run to the logbook (when one was given); returns the run's ID."""
        if self.stand is None:
            return None
        session = self.session
        if ended_t is not None:
            class _Ended:                   # a console's whole time: one run of the logbook
                pass

            session = _Ended()
            session.ended_t = ended_t
        return self.stand.log_run(command=command, port=port, schedule=schedule, files=files, outcome=outcome,
                                  tel=self.telemetry, session=session)
