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
    def __init__(self, limits=None, averager=None, logbook=None):
        self.limits = limits if limits else None          # api.limits.LimitSet (None: no limits)
        self.averager = averager                           # api.steady.StepAverager
        self.logbook = logbook                             # path of the logbook file
        self.stats = _logbook.RunStats()
        self.clock = None                                  # the session's (link.clock)

    def columns(self, record_columns):
        """Wrap the record column function: limit entries become CSV columns."""
        if self.limits is None:
            return record_columns

        def cols(snapshot, ids=None):
            return record_columns(snapshot, ids) + ["warnings", "limit"]

        return cols

    def attach(self, telemetry, source, on_update):
        """Hook into ``telemetry``; returns the live-view callback (limit lines added)."""
        telemetry.on_frame = self.on_frame
        self.clock = source.clock
        if on_update is None or self.limits is None:
            return on_update
        limits = self.limits

        def update(snapshot, health):
            on_update(snapshot, dict(health, limits=limits.dashboard_lines()))

        return update

    def on_frame(self, t, rec):
        self.stats.feed(t, rec)
        if self.averager is not None:
            self.averager.feed(t, rec)
        if self.limits is not None:
            return self.limits.check(t, rec)
        return None

    def summary(self) -> dict:
        """Entries for the run summary: ``limits`` (per condition), ``running_s``, ``starts``."""
        out = {"running_s": round(self.stats.running_s, 3), "starts": self.stats.starts}
        if self.limits is not None:
            out["limits"] = self.limits.summary()
        return out

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
            "outcome": outcome.reason, "exit_status": outcome.exit_code,
        }
        return _logbook.record(self.logbook, run)
