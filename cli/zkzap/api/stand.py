"""Test-stand hooks for a ZK logging session: limits, per-step averages and logbook statistics,
fed every decoded status frame through :attr:`zkzap.api.telemetry.Telemetry.on_frame`.

One :class:`Stand` is built from the command's options before any port opens, handed to the
session (``run_telemetry(stand=...)``) and asked afterwards for the summary entries and the
logbook row. ``zk batch`` plugs in the same way: build a Stand per step (or one for the batch)
and pass it to the session that step runs.
"""

from __future__ import annotations

from . import logbook as _logbook


class Stand:
    """The hooks of one session (see the module's text). ``aux``: an :class:`~zkzap.api.aux.AuxHub`
    (external sensors, merged into the records); ``corrections``: a
    :class:`~zkzap.api.ambient.RecordCorrections` (corrected fields in the records); ``answer``: a
    :class:`~zkzap.api.esr.PressureAnswer` (control ID 8 frames for the ECU's ESR request);
    ``engine``: the engine's name in the logbook and the summary."""

    def __init__(self, limits=None, averager=None, logbook=None, *, aux=None, corrections=None, answer=None,
                 engine=None):
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

    def start(self, timeout) -> None:
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

    def exit_status(self, outcome) -> int:
        """The run's exit status: the outcome's, or 5 for a limit violated under ``--on-limit warn``."""
        err = self.warned_violation(outcome)
        return err.code if err is not None else outcome.exit_code

    def log_run(self, *, command, port, schedule, files, outcome, tel, session):
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
