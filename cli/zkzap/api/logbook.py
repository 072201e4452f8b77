"""An engine logbook: every run in one SQLite file (stdlib :mod:`sqlite3`).

:class:`RunStats` collects a run's figures from the decoded status frames as they arrive:
engine-running time (the time spent in the ``running*`` engine states), starts (entries into a
running state from any other state), max rpm and EGT, and the fuel used (the ECU's fuel-used
counter at the end minus at the start). :func:`record` appends the run; :func:`runs` and
:func:`totals` read them back (running hours, starts, fuel).

The database is opened in WAL mode with a busy timeout, and every run is one short ``INSERT``
transaction, so two stands (or two processes) writing the same file are safe; a reader never
blocks a writer. sqlite3 itself is imported only when a logbook is opened.
"""

from __future__ import annotations

import json
import os
import time

from ..errors import OutputError, UsageError

BUSY_TIMEOUT_S = 30.0
RUNNING_STATES = frozenset({"running", "running-min-throttle", "running-pump-limit"})
#: Engine states of a start (and the cooling that precedes a restart): a schedule row during
#: which the engine passes through one is its start-up, not a steady-state step.
STARTING_STATES = frozenset({"ignition-min-throttle", "ignition", "preheat", "fuel-ramp", "learn-max-throttle",
                             "learn-min-throttle", "learn-idle", "restart"})

SCHEMA = """
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    started TEXT NOT NULL,
    ended TEXT NOT NULL,
    duration_s REAL NOT NULL,
    running_s REAL NOT NULL,
    starts INTEGER NOT NULL,
    max_rpm NUMERIC,
    max_egt_c NUMERIC,
    fuel_used_l REAL,
    errors TEXT NOT NULL,
    limits_violated TEXT NOT NULL,
    command TEXT NOT NULL,
    port TEXT,
    schedule TEXT,
    files TEXT NOT NULL,
    outcome TEXT NOT NULL,
    exit_status INTEGER NOT NULL
)
"""
#: Columns of a listed run, in order (JSON keys, CSV header).
COLUMNS = ("id", "started", "ended", "duration_s", "running_s", "starts", "max_rpm", "max_egt_c", "fuel_used_l",
           "errors", "limits_violated", "command", "port", "schedule", "files", "outcome", "exit_status")
_LISTS = ("errors", "limits_violated", "files")


class RunStats:
    """Running time and starts from status frames (``feed(t, record)``)."""

    def __init__(self):
        self.running_s = 0.0
        self.starts = 0
        self._state = None
        self._t = None

    def feed(self, t, rec):
        if rec.get("id") != 1:
            return
        name = rec.get("engine_state_name")
        running = name in RUNNING_STATES
        if self._state is not None and self._t is not None and self._state:
            self.running_s += max(0.0, t - self._t)
        if running and self._state is False:
            self.starts += 1
        self._state, self._t = running, t


def connect(path, *, create=True):
    """Open the logbook at ``path`` (created with its table when ``create``)."""
    import sqlite3

    if not create and not os.path.exists(path):
        raise UsageError(f"logbook: {path}: no such file")
    try:
        db = sqlite3.connect(path, timeout=BUSY_TIMEOUT_S, isolation_level=None)
        db.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")
        if create:
            db.execute("PRAGMA journal_mode = WAL")
            db.execute(SCHEMA)
        else:
            db.execute("SELECT 1 FROM runs LIMIT 1")
    except sqlite3.DatabaseError as e:
        what = "not a zkzap logbook" if "no such table" in str(e) or "not a database" in str(e) else str(e)
        raise (OutputError if create else UsageError)(f"logbook: {path}: {what}") from None
    return db


def check_writable(path):
    """Open (and create) the logbook before a run, so an unusable path is found first: a missing
    directory, a directory or a file that cannot be written is a UsageError (exit 2) naming it."""
    parent = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise UsageError(f"logbook: {path} is a directory; give a file")
    if not os.path.isdir(parent):
        raise UsageError(f"logbook: cannot create {path}: no such directory {parent}")
    if os.path.exists(path) and not os.access(path, os.R_OK | os.W_OK):
        raise UsageError(f"logbook: cannot write {path}: permission denied")
    if not os.path.exists(path) and not os.access(parent, os.W_OK | os.X_OK):
        raise UsageError(f"logbook: cannot create {path}: permission denied in {parent}")
    connect(path).close()


def record(path, run: dict) -> int:
    """Append one run (keys of :data:`COLUMNS` except ``id``); returns its ID."""
    row = dict(run)
    for k in _LISTS:
        row[k] = json.dumps(row.get(k) or [], ensure_ascii=False)
    keys = [c for c in COLUMNS if c != "id"]
    import sqlite3

    try:
        db = connect(path)
        try:
            cur = db.execute(f"INSERT INTO runs ({', '.join(keys)}) VALUES ({', '.join('?' * len(keys))})",
                             [row.get(k) for k in keys])
            return cur.lastrowid
        finally:
            db.close()
    except sqlite3.Error as e:
        raise OutputError(f"logbook: cannot write {path}: {e}") from None


def runs(path) -> list:
    db = connect(path, create=False)
    try:
        cur = db.execute(f"SELECT {', '.join(COLUMNS)} FROM runs ORDER BY id")
        out = []
        for values in cur:
            rec = dict(zip(COLUMNS, values))
            for k in _LISTS:
                rec[k] = json.loads(rec[k] or "[]")
            out.append(rec)
        return out
    finally:
        db.close()


def totals(recs) -> dict:
    fuel = [r["fuel_used_l"] for r in recs if r["fuel_used_l"] is not None]
    return {
        "runs": len(recs),
        "running_hours": round(sum(r["running_s"] for r in recs) / 3600.0, 4),
        "running_s": round(sum(r["running_s"] for r in recs), 1),
        "starts": sum(r["starts"] for r in recs),
        "fuel_used_l": round(sum(fuel), 3),
        "max_rpm": max((r["max_rpm"] for r in recs if r["max_rpm"] is not None), default=None),
        "max_egt_c": max((r["max_egt_c"] for r in recs if r["max_egt_c"] is not None), default=None),
        "runs_with_errors": sum(1 for r in recs if r["errors"]),
        "runs_with_limits": sum(1 for r in recs if r["limits_violated"]),
    }


def iso(ts):
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(ts))
