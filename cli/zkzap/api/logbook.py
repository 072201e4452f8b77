"""An engine logbook: every run in one SQLite file (stdlib :mod:`sqlite3`), per engine.

:class:`RunStats` collects a run's figures from the decoded status frames as they arrive:
engine-running time (the time spent in the ``running*`` engine states), starts (entries into a
running state from any other state), max rpm and EGT, and the fuel used (the ECU's fuel-used
counter at the end minus at the start), and the running time per whole percent of throttle.
:func:`record` appends the run (with the engine's name, ``--engine``); :func:`runs` and
:func:`totals` read them back (running hours, starts, fuel, hours at or above a throttle);
:func:`record_service` notes a service of an engine, and :func:`engine_report` gives one
engine's totals, overall and since its last service (the runs recorded after it).

The database is opened in WAL mode with a busy timeout, and every run is one short ``INSERT``
transaction, so two stands (or two processes) writing the same file are safe; a reader never
blocks a writer. sqlite3 itself is imported only when a logbook is opened.
"""

from __future__ import annotations

import json
import os
import time

from ..errors import OutputError, UsageError, clip

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
    exit_status INTEGER NOT NULL,
    engine TEXT,
    throttle_s TEXT
)
"""
SERVICES = """
CREATE TABLE IF NOT EXISTS services (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    engine TEXT NOT NULL,
    at TEXT NOT NULL,
    note TEXT,
    after_run INTEGER NOT NULL
)
"""
#: Columns added after the first release: a logbook written before gets them on first use.
_ADDED = (("engine", "TEXT"), ("throttle_s", "TEXT"))
#: Columns of a listed run, in order (JSON keys, CSV header).
COLUMNS = ("id", "started", "ended", "duration_s", "running_s", "starts", "max_rpm", "max_egt_c", "fuel_used_l",
           "errors", "limits_violated", "command", "port", "schedule", "files", "outcome", "exit_status", "engine",
           "throttle_s")
_LISTS = ("errors", "limits_violated", "files")


class RunStats:
    """Running time, starts and the running time at each throttle from status frames
    (``feed(t, record)``). :attr:`throttle_s` holds the seconds spent running per whole percent
    of the ECU's throttle (status ID 3; ``"101"`` for anything above 100 %)."""

    def __init__(self):
        self.running_s = 0.0
        self.starts = 0
        self.throttle_s = {}
        self._state = None
        self._t = None
        self._throttle = None

    def feed(self, t, rec):
        sid = rec.get("id")
        if sid == 3 and isinstance(rec.get("throttle_pct"), (int, float)):
            self._throttle = rec["throttle_pct"]
        if sid != 1:
            return
        name = rec.get("engine_state_name")
        running = name in RUNNING_STATES
        if self._state is not None and self._t is not None and self._state:
            dt = max(0.0, t - self._t)
            self.running_s += dt
            if self._throttle is not None:
                key = str(min(int(self._throttle), 101))
                self.throttle_s[key] = self.throttle_s.get(key, 0.0) + dt
        if running and self._state is False:
            self.starts += 1
        self._state, self._t = running, t


def connect(path, *, create=True):
    """Open the logbook at ``path`` (created with its table when ``create``)."""
    import sqlite3

    if not create and not os.path.exists(path):
        raise UsageError(f"logbook: {path}: no such file")
    if create:
        from .. import checking

        checking.effect("file", path=path)
    try:
        db = sqlite3.connect(path, timeout=BUSY_TIMEOUT_S, isolation_level=None)
        # text a damaged file holds reads with replacement characters instead of failing the listing
        db.text_factory = lambda b: b.decode("utf-8", "replace")
        db.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")
        if create:
            db.execute("PRAGMA journal_mode = WAL")
            db.execute(SCHEMA)
            db.execute(SERVICES)
        else:
            db.execute("SELECT 1 FROM runs LIMIT 1")
        have = {row[1] for row in db.execute("PRAGMA table_info(runs)")}
        for name, kind in _ADDED:
            if name not in have:
                db.execute(f"ALTER TABLE runs ADD COLUMN {name} {kind}")
        if not create:
            db.execute(SERVICES)
    except (sqlite3.DatabaseError, UnicodeDecodeError) as e:
        if isinstance(e, UnicodeDecodeError):       # sqlite's own message quotes a damaged schema
            what = "a damaged database (its schema is not text)"
        else:
            what = "not a zkzap logbook" if "no such table" in str(e) or "not a database" in str(e) else str(e)
        raise (OutputError if create else UsageError)(f"logbook: {path}: {what}") from None
    return db


def check_writable(path):
    """Refuse, before a run, a logbook path that cannot take the run (exit 2): a device, a
    FIFO or a directory (a logbook is an SQLite database file), a missing directory, no
    permission, or a file that is not a zkzap logbook. Nothing is created: the first run it
    records creates the database."""
    from ..outfile import check_path

    kind = check_path(path, "logbook")
    if kind == "stream":
        raise UsageError(f"logbook: {path} is not a regular file; a logbook is an SQLite database file")
    if kind == "regular" and os.path.getsize(path) > 0:
        import sqlite3

        try:
            uri = "file:" + os.path.abspath(path).replace("?", "%3f").replace("#", "%23") + "?mode=ro"
            db = sqlite3.connect(uri, uri=True, timeout=BUSY_TIMEOUT_S)
            try:
                db.execute("SELECT 1 FROM runs LIMIT 1")
            finally:
                db.close()
        except sqlite3.DatabaseError as e:
            what = "not a zkzap logbook" if "no such table" in str(e) or "not a database" in str(e) else str(e)
            raise UsageError(f"logbook: {path}: {what}") from None


def record(path, run: dict) -> int:
    """Append one run (keys of :data:`COLUMNS` except ``id``); returns its ID."""
    row = dict(run)
    for k in _LISTS:
        row[k] = json.dumps(row.get(k) or [], ensure_ascii=False)
    row["throttle_s"] = json.dumps({k: round(v, 3) for k, v in (row.get("throttle_s") or {}).items()})
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
    except (sqlite3.DatabaseError, ValueError) as e:      # a damaged file: its pages, its encoding
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
    text = rec["throttle_s"]
    try:
        value = json.loads(text or "{}") if isinstance(text, (str, bytes)) or text is None else None
    except (ValueError, RecursionError):
        value = None
    if not isinstance(value, dict) or not all(_number(v) and _integer_text(k) for k, v in value.items()):
        bad("throttle_s", "not a JSON object of seconds by throttle percentage")
    rec["throttle_s"] = value
    for k, nullable in _NUMBERS.items():
        v = rec[k]
        if v is None and nullable:
            continue
        if not _number(v):
            bad(k, f"{clip(repr(v))} is not a number")
    for k, nullable in _TEXTS.items():
        what = _not_text(rec[k], nullable)
        if what:
            bad(k, what)
    return rec


#: Columns that must hold text (None where the column allows NULL).
_TEXTS = {"started": False, "ended": False, "command": False, "port": True, "schedule": True,
          "outcome": False, "engine": True}


def _not_text(v, nullable) -> str:
    """What is wrong with ``v`` as a text column's value ('' when nothing is)."""
    if isinstance(v, str) or (v is None and nullable):
        return ""
    if isinstance(v, bytes):
        return f"a BLOB of {len(v)} byte{'' if len(v) == 1 else 's'} is not text"
    return f"{clip(repr(v))} is not text"


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _integer_text(k) -> bool:
    try:
        int(k)
    except (TypeError, ValueError):
        return False
    return True


def simulated(run) -> bool:
    """A run on a simulator (its port ``sim://...``): no real engine ran."""
    return str(run.get("port") or "").startswith("sim://")


def totals(recs, above=()) -> dict:
    """Totals of ``recs``: runs, run and running time, starts, fuel, maxima, runs with errors or
    limits; with ``above`` (throttle percentages) the running hours at or above each
    (``hours_above``: {"80": h}; from runs recorded with their throttle times). Runs on a
    simulator (:func:`simulated`) count toward none of them: an engine's hours are its own;
    ``simulated_runs`` says how many were left out."""
    sims = sum(1 for r in recs if simulated(r))
    recs = [r for r in recs if not simulated(r)]
    fuel = [r["fuel_used_l"] for r in recs if r["fuel_used_l"] is not None]
    out = {
        "runs": len(recs),
        "run_hours": round(sum(r["duration_s"] for r in recs) / 3600.0, 4),
        "running_hours": round(sum(r["running_s"] for r in recs) / 3600.0, 4),
        "running_s": round(sum(r["running_s"] for r in recs), 1),
        "starts": sum(r["starts"] for r in recs),
        "fuel_used_l": round(sum(fuel), 3),
        "max_rpm": max((r["max_rpm"] for r in recs if r["max_rpm"] is not None), default=None),
        "max_egt_c": max((r["max_egt_c"] for r in recs if r["max_egt_c"] is not None), default=None),
        "runs_with_errors": sum(1 for r in recs if r["errors"]),
        "runs_with_limits": sum(1 for r in recs if r["limits_violated"]),
        "simulated_runs": sims,
    }
    if above:
        out["hours_above"] = {f"{pct:g}": round(sum(s for r in recs for k, s in (r.get("throttle_s") or {}).items()
                                                     if int(k) >= pct) / 3600.0, 4) for pct in above}
    return out


def record_service(path, engine, note=None, at=None) -> dict:
    """Record a service of ``engine`` (now, or at ``at`` POSIX time); returns it."""
    import sqlite3

    svc = {"engine": engine, "at": iso(time.time() if at is None else at), "note": note}
    try:
        db = connect(path)
        try:
            # the runs recorded so far are before the service, whatever their clocks say
            cur = db.execute("INSERT INTO services (engine, at, note, after_run) "
                             "VALUES (?, ?, ?, (SELECT COALESCE(MAX(id), 0) FROM runs))",
                             (svc["engine"], svc["at"], svc["note"]))
            svc["id"] = cur.lastrowid
        finally:
            db.close()
    except sqlite3.Error as e:
        raise OutputError(f"logbook: cannot write {path}: {e}") from None
    return svc


def services(path, engine=None) -> list:
    import sqlite3

    db = connect(path, create=False)
    try:
        q = "SELECT id, engine, at, note, after_run FROM services" + (" WHERE engine = ?" if engine is not None
                                                                       else "")
        out = [dict(zip(("id", "engine", "at", "note", "after_run"), row))
               for row in db.execute(q + " ORDER BY id", (engine,) if engine is not None else ())]
    except sqlite3.DatabaseError as e:
        raise UsageError(f"logbook: {path}: {e}") from None
    finally:
        db.close()
    for svc in out:
        if not isinstance(svc["after_run"], int) or isinstance(svc["after_run"], bool):
            raise UsageError(f"logbook: {path}: service {svc['id']}: after_run: {clip(repr(svc['after_run']))} "
                             "is not a run ID")
        for k, nullable in (("engine", False), ("at", False), ("note", True)):
            what = _not_text(svc[k], nullable)
            if what:
                raise UsageError(f"logbook: {path}: service {svc['id']}: {k}: {what}")
    return out


def engine_report(path, engine, above=(80,)) -> dict:
    """One engine's book: its runs, the totals, and the totals since its last service."""
    recs = [r for r in runs(path) if r.get("engine") == engine]
    svc = services(path, engine)
    last = svc[-1] if svc else None
    since = [r for r in recs if last is None or r["id"] > last["after_run"]]
    return {"engine": engine, "runs": recs, "totals": totals(recs, above), "services": svc,
            "last_service": last, "since_service": totals(since, above)}


def iso(ts):
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(ts))
