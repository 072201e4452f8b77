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
    """Open (and create) the logbook before a run, so an unusable path is found first."""
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


#: Columns that must hold a number (None where the column allows NULL), as :func:`totals` adds them.
_NUMBERS = {"duration_s": False, "running_s": False, "starts": False, "max_rpm": True, "max_egt_c": True,
            "fuel_used_l": True, "exit_status": False}


def runs(path) -> list:
    """Every run of the logbook at ``path``, in order. A damaged file (or one edited by hand:
    a list column that is not a JSON list, text where a number belongs) is a UsageError
    naming the file, the run and the column."""
    import sqlite3

    db = connect(path, create=False)
    try:
        cur = db.execute(f"SELECT {', '.join(COLUMNS)} FROM runs ORDER BY id")
        out = []
        for values in cur:
            out.append(_run(path, dict(zip(COLUMNS, values))))
        return out
    except sqlite3.DatabaseError as e:
        raise UsageError(f"logbook: {path}: {e}") from None
    finally:
        db.close()


def _run(path, rec) -> dict:
    def bad(column, what):
        raise UsageError(f"logbook: {path}: run {rec.get('id')}: {column}: {what}")

    for k in _LISTS:
        text = rec[k]
        try:
            value = json.loads(text or "[]") if isinstance(text, (str, bytes)) or text is None else None
        except (ValueError, RecursionError):
            value = None
        if not isinstance(value, list):
            bad(k, "not a JSON list")
        rec[k] = value
    for k, nullable in _NUMBERS.items():
        v = rec[k]
        if v is None and nullable:
            continue
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            bad(k, f"{v!r} is not a number")
    return rec


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
