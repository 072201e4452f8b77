"""ZK status frames -> records: :class:`Telemetry` decodes each frame (in the ECU's own unit,
once status ID 6 gave the protocol version) into one record per frame or a snapshot row of every
field's latest value, with time stamps, the stale-data rule, health figures, ECU errors and a
summary; and the helpers every ZK command shares: :func:`parse_ids`, :func:`record_columns`,
:func:`iso_utc`, :func:`describe_error`.

Everything about frames comes from :mod:`zkzap.codec.zk`. Nothing here imports click, rich or
pyserial.
"""

from __future__ import annotations

from collections import deque

from ..codec import zk
from ..errors import UsageError
from ..link.clock import iso_utc  # noqa: F401 - the one rendering of a date, re-exported

#: A status ID is stale when it has not been seen for more than this many of its periods.
STALE_PERIODS = 3
#: Frames held back while waiting for the first status ID 6 (the protocol version); more than a
#: full cycle of IDs 1..10.
HOLD_FRAMES = 12


def describe_error(code, name=None, t=None) -> str:
    """The one wording of an ECU error code, in every command: ``ECU error 3 (egt-high: ...) at
    t=4.20 s``."""
    name = name or zk.ERRORS.get(code, f"undocumented-{code}")
    text = zk.ERROR_TEXT.get(code, "undocumented")
    return f"ECU error {code} ({name}: {text})" + (f" at t={t:.2f} s" if t is not None else "")




def parse_ids(text):
    """``"1,2,6"`` or ``"1-3,9"`` -> frozenset of status IDs (1..14)."""
    ids = set()
    import re

    # "1 2" is two IDs (never 12); spaces around a range's dash are allowed ("1 - 3")
    for part in re.split(r"[,\s]+", re.sub(r"\s*-\s*", "-", str(text).strip())):
        if not part:
            continue
        lo, sep, hi = part.partition("-")
        try:
            a = int(lo)
            b = int(hi) if sep else a
        except ValueError:
            raise UsageError(f"ids: {part!r} is not an ID or a range such as 1-3") from None
        for v in (a, b):
            if not 1 <= v <= 14:
                raise UsageError(f"ids: {v} is out of range; allowed status IDs 1..14")
        if b < a:
            raise UsageError(f"ids: {part!r} is an empty range")
        ids.update(range(a, b + 1))
    if not ids:
        raise UsageError("ids: no ID given; allowed status IDs 1..14, e.g. 1,2,6 or 1-3")
    return frozenset(ids)


def status_keys(ids=None):
    """Status keys in table order, restricted to the keys of ``ids`` (None: all)."""
    if ids is None:
        return list(zk.STATUS_KEYS)
    keep = set()
    for s in zk.STATUS:
        if s.id in ids:
            keep.update(s.layout.keys())
    return [k for k in zk.STATUS_KEYS if k in keep]


def record_columns(snapshot: bool, ids=None):
    """The fixed column set of monitor records (CSV header)."""
    keys = status_keys(ids)
    if snapshot:
        return ["time", "t", "id"] + keys + ["stale", "stale_ids"]
    return ["time", "t", "kind", "id"] + keys + ["payload", "frame", "stale", "stale_ids"]


class Telemetry:
    """Status frames -> records, with the state a live view and a summary need.

    - Until the first status ID 6 reveals the protocol version, frames are held back (at most
      :data:`HOLD_FRAMES`) so that every voltage decodes in the ECU's own unit; with a given
      ``protocol_version`` nothing is held. Without an ID 6 the default version is used and
      :attr:`version_note` says so.
    - ``snapshot=True``: one row per frame with every field's latest value; otherwise one record
      per frame, as ``zk decode`` gives it. Both carry ``time`` (ISO 8601 UTC), ``t`` (seconds
      since the start), and ``stale``/``stale_ids``.
    - ``clock``: the session's clock (:class:`~zkzap.link.clock.SessionClock`; a source's
      ``clock``), which turns ``t`` into ``time``; None: real time from now (``wall0``, a POSIX
      time, moves its origin). A replay's clock without dates gives ``time: null``.
    - Stale rule: an ID is stale when it has not been seen for more than ``stale_periods`` of its
      period; the period of one ID is (IDs in the ECU's cycle) / (status rate from ID 6; 20 Hz
      until seen), as the ECU sends one frame per period, the IDs in turn.
    - ECU errors: the error code of the first ID 1 frame is where the session starts; a non-zero
      code different from it (or one that comes back after a 0) is a *new error*
      (:attr:`new_error`).
    """

    def __init__(self, protocol_version=None, ids=None, snapshot=False, stale_periods=STALE_PERIODS,
                 clock=None, wall0=None):
        self.decoder = zk.ZkDecoder(protocol_version)
        if clock is None:
            from ..link.clock import SessionClock

            clock = SessionClock()
            if wall0 is not None:
                clock.wall0 = wall0
        #: the session's clock: ``time`` of the record at ``t`` is ``clock.iso(t)``
        self.clock = clock
        self.holding = protocol_version is None
        self.held = []
        self.ids = ids
        self.snapshot_rows = snapshot
        self.stale_periods = stale_periods
        self.keys = status_keys(ids)
        self.latest = dict.fromkeys(zk.STATUS_KEYS)
        self.last_seen = {}
        self.rate = 20
        self.frames = 0
        self.frames_by_id = {}        # status ID -> frames decoded
        self.records = 0
        self.version_note = None
        # ECU errors
        self._baseline = None
        self.initial_error = None     # (code, name) of an error the ECU reported from the start
        self.new_error = None
        self.errors = {}
        # summary
        self.first_t = None
        self.last_t = None
        self.max_rpm = None
        self.max_egt = None
        self.fuel_first = None
        self.fuel_last = None
        self.states = []
        self._rate_window = deque()
        #: ``on_frame(t, record)`` sees every decoded frame (before --ids); a dict it returns is
        #: added to the frame's row (limit entries)
        self.on_frame = None

    # frames in, records out
    def feed(self, t, frame) -> list:
        """The records of a status ``frame`` received at ``t`` (none while frames are held)."""
        if self.holding:
            self.held.append((t, frame))
            if frame[0] == zk.VERSION_HEAD or len(self.held) >= HOLD_FRAMES:
                return self._release()
            return []
        return self._emit(t, frame)

    def seed(self, six) -> None:
        """Learn from a status ID 6 frame heard before the session began (its protocol version,
        status rate and limits), so that no frame is held back for one; it is no record."""
        rec = self.decoder.decode(six)
        for k, v in rec.items():
            if k in self.latest:
                self.latest[k] = v
        if rec.get("status_rate_hz"):
            self.rate = rec["status_rate_hz"]
        if self.holding and not self.held:
            self.holding = False

    def flush(self) -> list:
        """Records of frames still held (end of the stream)."""
        return self._release() if self.held else []

    def _release(self):
        self.holding = False
        six = next((f for _, f in self.held if f[0] == zk.VERSION_HEAD), None)
        if six is not None:
            self.decoder.decode(six)
        else:
            self.version_note = (f"no status ID 6 frame among the first {len(self.held)}: voltages assume "
                                 f"protocol version {zk.DEFAULT_PROTOCOL_VERSION}; set --protocol-version "
                                 f"if the ECU is older")
        out = []
        for t, f in self.held:
            out += self._emit(t, f)
        self.held = []
        return out

    def _emit(self, t, frame):
        rec = self.decoder.decode(frame)
        sid = rec["id"]
        extra = self.on_frame(t, rec) if self.on_frame is not None else None
        self.frames += 1
        self.frames_by_id[sid] = self.frames_by_id.get(sid, 0) + 1
        self.last_seen[sid] = t
        if self.first_t is None:
            self.first_t = t
        self.last_t = t
        win = self._rate_window
        win.append(t)
        while win and win[0] < t - 1.0:
            win.popleft()
        latest = self.latest
        for k, v in rec.items():
            if k in latest:
                latest[k] = v
        latest[zk.OUT_OF_RANGE] = rec.get(zk.OUT_OF_RANGE)   # this frame's, never a stale one
        rpm = rec.get("rpm")
        if rpm is not None and (self.max_rpm is None or rpm > self.max_rpm):
            self.max_rpm = rpm
        if sid == 1:
            self._engine(t, rec)
        elif sid == 6 and rec.get("status_rate_hz"):
            self.rate = rec["status_rate_hz"]
        elif sid == 7 and rec.get("fuel_used_l") is not None:
            if self.fuel_first is None:
                self.fuel_first = rec["fuel_used_l"]
            self.fuel_last = rec["fuel_used_l"]
        if self.ids is not None and sid not in self.ids:
            return []
        stale = self.stale_ids(t)
        self.records += 1
        when = self.clock.iso(t)
        if self.snapshot_rows:
            row = {"time": when, "t": round(t, 3), "id": sid}
            for k in self.keys:
                row[k] = latest[k]
        else:
            row = {"time": when, "t": round(t, 3)}
            row.update(rec)
            row["frame"] = frame.hex(" ").upper()
        row["stale"] = bool(stale)
        row["stale_ids"] = stale
        if extra:
            row.update(extra)
        return [row]

    def _engine(self, t, rec):
        egt = rec.get("egt_c")
        if egt is not None and (self.max_egt is None or egt > self.max_egt):
            self.max_egt = egt
        name = rec.get("engine_state_name")
        if name and (not self.states or self.states[-1] != name):
            self.states.append(name)
        code = rec.get("error_code") or 0
        if self._baseline is None:
            self._baseline = code
            self.initial_error = (code, rec.get("error_name")) if code else None
        if code and code not in self.errors:
            self.errors[code] = t
        if code == 0:
            self._baseline = 0
        elif code != self._baseline:
            self._baseline = code
            self.new_error = (code, rec.get("error_name"), t)

    # views
    def frames_with(self, key) -> int:
        """How many decoded frames carried the status field ``key`` (``error_code``: ID 1's)."""
        return sum(n for sid, n in self.frames_by_id.items() if key in zk.STATUS_KEYS_BY_ID.get(sid, ()))

    def period(self, sid=None) -> float:
        """Expected seconds between two frames of one ID."""
        return max(len(self.last_seen), 1) / self.rate

    def stale_ids(self, t) -> list:
        """Status IDs (of ``ids``) not seen for more than ``stale_periods`` of their periods at ``t``."""
        limit = self.stale_periods * self.period()
        return sorted(i for i, seen in self.last_seen.items()
                      if t - seen > limit and (self.ids is None or i in self.ids))

    def snapshot(self, t) -> dict:
        """Every status field's latest value, and ``time_s``."""
        snap = dict(self.latest)
        snap["time_s"] = round(t, 3)
        return snap

    def health(self, t, framer=None) -> dict:
        """Link health at ``t``: frames, frames per second (last second), CRC errors and skipped
        bytes (of ``framer``), stale, protocol version and where it came from."""
        win = self._rate_window
        while win and win[0] < t - 1.0:
            win.popleft()
        if self.last_seen:
            stale = bool(self.stale_ids(t))
        else:
            stale = t > self.stale_periods / self.rate
        return {
            "frames": self.frames,
            "frames_per_s": float(len(win)) if t >= 1.0 else (len(win) / t if t > 0 else 0.0),
            "crc_errors": framer.bad if framer is not None else 0,
            "skipped": framer.skipped if framer is not None else 0,
            "stale": stale,
            "protocol_version": self.decoder.version,
            "version_source": self.decoder.version_source,
        }

    def summary(self) -> dict:
        """Frames, records, max rpm, max EGT, fuel used, the engine states passed through, the
        ECU errors seen, the protocol version."""
        fuel = None
        if self.fuel_first is not None:
            fuel = round(self.fuel_last - self.fuel_first, 1)
        return {
            "frames": self.frames,
            "records": self.records,
            "max_rpm": self.max_rpm,
            "max_egt_c": self.max_egt,
            "fuel_used_l": fuel,
            "fuel_total_l": self.fuel_last,
            "states": list(self.states),
            "errors": [{"code": c, "name": zk.ERRORS.get(c, f"undocumented-{c}"), "t": round(t, 3)}
                       for c, t in self.errors.items()],
            "protocol_version": self.decoder.version,
            "version_source": self.decoder.version_source,
        }
