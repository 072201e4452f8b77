"""Timed motion of several actuators: trajectories (``zap play``, :meth:`Bus.play`), teaching
waypoints (``zap teach``) and the safe stop of every actuator.

**A path** is rows of ``t`` (seconds from the start), ``id`` (one ID, or several: ``"1,2"`` in
CSV, a list in JSON), ``position`` (the goal) and optionally ``speed`` (goal-speed) and
``current`` (goal-current, mA): a CSV file with a header, a JSON array of objects or JSON
Lines (:func:`read_path`). Positions are counts, or millimetres with ``unit="mm"`` (and
speeds mm/s; see :mod:`zkzap.api.units`). Every row is checked before anything moves.

**The plan** (:func:`plan`): rows of one time are one *step*, and a step's goals of one register
go out as one Symmetric Store (one sync move, broadcast, never answered) — goal-current first,
then goal-speed, then goal-position; on Modbus RTU (``protocol``, a
:mod:`~zkzap.api.motion_wire` wire) one Write Multiple Registers per actuator of its
goal-speed and goal-current, then one per actuator of goal-position, each answered. With ``interpolate="linear"`` each actuator's goal moves
linearly between its rows and steps leave at ``rate`` Hz. The line must carry the plan: a step's
frames take their time on the wire (10 bits a byte at the baud rate); a plan whose steps come
closer than their frames take, or an interpolation rate above :data:`LINE_SHARE` of what the
line carries (:func:`max_rate`), is refused (:class:`~zkzap.errors.UsageError`), never played
late.

**Playing** (:class:`Player`): each step leaves at its due time on the session's clock
(:class:`zkzap.link.clock.SessionClock`: model time on a simulator that runs faster). Between
steps, the spare time reads the actuators one at a time, round robin (present-position ..
present-voltage in one Load Data; on Modbus RTU the map's runs of hardware-error ..
present-voltage), but only a read whose round trip (the wire, and the
actuator's learned latency, and for one whose last read went unanswered the time until the
bus would send it at once, :meth:`~zkzap.link.zap_bus.ZapBus.clear_at`) ends before the next
step is due, and it waits for its reply only until then (no reply by then: a ``no-reply``
row, never a late step): the log rows give goal vs
present position (the tracking error), current and voltage. The lateness of every step (when
its first byte left, after its due time) is kept (:attr:`Player.lateness`). A hardware error
bit in a reply, a current over ``limit`` (mA), or Ctrl-C/SIGTERM stops every actuator
(:func:`stop_all`: goal := present position, or force off) and says so (:attr:`Player.stopped`).

Nothing here imports click or rich.
"""

from __future__ import annotations

import csv
import io
import json
import math
import time
from array import array

from ..codec import zap
from ..errors import BadReply, DeviceError, NoReply, UsageError, ZkzapError
from .motion_wire import IrWire, wire_for, wire_of

POSITION = zap.REGISTER_BY_NAME["goal-position"]
SPEED = zap.REGISTER_BY_NAME["goal-speed"]
CURRENT = zap.REGISTER_BY_NAME["goal-current"]
FORCE = zap.REGISTER_BY_NAME["force-on-off"]
PRESENT = zap.REGISTER_BY_NAME["present-position"]
MARGIN = zap.REGISTER_BY_NAME["end-compliance-margin"]
#: The block a log read covers: present-position .. present-voltage.
LOG_FIRST = PRESENT
LOG_LENGTH = zap.REGISTER_BY_NAME["present-voltage"].address + 1 - PRESENT.address
from .motion_wire import LOAD_BYTES, REPLY_BYTES  # noqa: E402,F401  (bytes of a Load Data, of a bare reply)
#: The share of the line a plan may use for its goals (the rest: the log reads, the host).
LINE_SHARE = 0.8
#: Interpolation rate when none is asked: this, or what the line carries when less.
DEFAULT_RATE = 50.0
#: How long before a due time the player stops sleeping and watches the clock (seconds).
SPIN = 0.0015
#: A log read must be expected to end this long before the next step is due (seconds).
READ_GUARD = 0.002
#: The actuator's own turnaround before any is learned (a 12Lf's: the link's floor).
from ..link.zap_timing import FLOOR as TURNAROUND  # noqa: E402

#: Columns of the log rows.
LOG_COLUMNS = ["time", "t", "loop", "id", "goal", "present", "tracking_error", "current_ma", "voltage_v",
               "errors", "status"]
MM_COLUMNS = ["goal_mm", "present_mm", "tracking_error_mm"]
STOP_MODES = ("hold", "off")
PATH_FIELDS = ("t", "id", "position", "speed", "current", "bus")
_ALIASES = {"time": "t", "ids": "id", "goal": "position", "goal-position": "position", "goal_position": "position",
            "goal-speed": "speed", "goal_speed": "speed", "goal-current": "current", "goal_current": "current"}


class Row:
    """One checked row of a path: ``t``, ``ids`` (a tuple), ``position``, ``speed``, ``current``
    (raw register values; None where not given) and ``line`` (where it was read)."""

    __slots__ = ("t", "ids", "position", "speed", "current", "line", "bus")

    def __init__(self, t, ids, position, speed=None, current=None, line=0, bus=None):
        self.t, self.ids, self.position, self.speed, self.current, self.line = t, tuple(ids), position, speed, \
            current, line
        self.bus = bus

    def __repr__(self):
        return f"Row(t={self.t}, ids={self.ids}, position={self.position}, speed={self.speed}, current={self.current})"


class Step:
    """What leaves at one due time: ``t``, ``goals``/``speeds``/``currents`` ({ID: raw}) and
    their ``frames`` (in sending order: on IR Symmetric Store packets, on Modbus RTU one Write
    Multiple Registers per actuator; ``protocol``: the :mod:`~zkzap.api.motion_wire` wire)."""

    __slots__ = ("t", "goals", "speeds", "currents", "frames", "keyframe", "protocol")

    def __init__(self, t, goals, speeds=None, currents=None, keyframe=True, protocol=None):
        self.t = t
        self.goals = dict(goals)
        self.speeds = dict(speeds or {})
        self.currents = dict(currents or {})
        self.keyframe = keyframe
        self.protocol = protocol if protocol is not None else IrWire()
        self.frames = self.protocol.step_frames(self.goals, self.speeds, self.currents)

    def wire(self, baud: int, stop_bits: int = 1) -> float:
        """Seconds the step's frames hold the line (on Modbus RTU with their replies)."""
        return sum(self.protocol.frame_time(f, baud, stop_bits) for f in self.frames)

    def record(self) -> dict:
        return {"t": round(self.t, 6), "goals": {str(k): v for k, v in sorted(self.goals.items())},
                "speeds": {str(k): v for k, v in sorted(self.speeds.items())} or None,
                "currents": {str(k): v for k, v in sorted(self.currents.items())} or None,
                "frames": [f.hex(" ").upper() for f in self.frames]}


# -- reading a path ------------------------------------------------------------------------------

def _fail(name, line, text):
    raise UsageError(f"{name}:{line}: {text}" if line else f"{name}: {text}", line=line)


def _records(text: str, name: str):
    """(line, dict) of a CSV, JSON array or JSON Lines text."""
    head = text.lstrip()
    if head.startswith("["):
        from .documents import load_json

        doc = load_json(text, name)
        if not isinstance(doc, list):
            _fail(name, 0, "expected an array of rows")
        for n, rec in enumerate(doc, 1):
            if not isinstance(rec, dict):
                _fail(name, 0, f"row {n}: expected an object with t, id, position")
            yield n, rec
        return
    if head.startswith("{"):
        from .documents import load_json

        for n, line in enumerate(text.splitlines(), 1):
            if not line.strip():
                continue
            try:
                rec = load_json(line, f"{name}:{n}")
            except UsageError as e:
                _fail(name, n, str(e).split(": ", 2)[-1])
            if not isinstance(rec, dict):
                _fail(name, n, "expected an object with t, id, position")
            yield n, rec
        return
    reader = csv.reader(io.StringIO(text))
    header = None
    for row in reader:
        n = reader.line_num
        if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
            continue
        if header is None:
            header = [h.strip().lower() for h in row]
            continue
        if len(row) > len(header):
            _fail(name, n, f"{len(row)} fields, the header has {len(header)}")
        yield n, {k: v.strip() for k, v in zip(header, row) if v.strip() != ""}


def _number(name, line, key, v, *, integer=False):
    if isinstance(v, bool):
        _fail(name, line, f"{key}: {v!r} is not a number")
    if isinstance(v, str):
        try:
            v = float(v) if not integer or any(c in v for c in ".eE") else int(v, 0)
        except ValueError:
            _fail(name, line, f"{key}: {v!r} is not a number")
    if not isinstance(v, (int, float)) or not math.isfinite(v):
        _fail(name, line, f"{key}: {v!r} is not a finite number")
    return v


def _ids(name, line, v, protocol="ir"):
    if protocol == "modbus":
        from ..codec import modbus as checker

        what = "1..247"
    else:
        checker, what = zap, "0..253"
    items = v if isinstance(v, list) else [v] if isinstance(v, int) else str(v).replace(";", ",").split(",")
    out = []
    for item in items:
        try:
            ident = int(item) if not isinstance(item, str) else int(item.strip(), 0)
            if isinstance(item, (bool, float)):
                raise ValueError
            checker.check_id(ident, allow_broadcast=False)
        except (ValueError, TypeError, ZkzapError):
            _fail(name, line, f"id: {item!r} is not an actuator ID {what}")
        if ident in out:
            _fail(name, line, f"id: {ident} is given twice")
        out.append(ident)
    if not out:
        _fail(name, line, "id: none given")
    return out


def read_path(source, *, unit: str = "counts", scales=None, name=None, protocol=None) -> list:
    """The checked :class:`Row` list of a path file (``source``: a path, ``-`` for stdin, or a
    text stream), in time order (rows of one time keep their order). ``unit`` ``"mm"``:
    positions in mm and speeds in mm/s, converted with ``scales`` ({ID: Scale}). IDs and
    ranges are those of ``protocol`` (a :mod:`~zkzap.api.motion_wire` wire; None: the 12Lf's
    IR map). A bad row is a UsageError naming ``FILE:LINE``; nothing is returned from a file
    with one."""
    protocol = protocol if protocol is not None else IrWire()
    if hasattr(source, "read"):
        text, name = source.read(), name or getattr(source, "name", "path")
    elif source == "-":
        import sys

        text, name = sys.stdin.read(), name or "stdin"
    else:
        name = name or str(source)
        try:
            with open(source, encoding="utf-8") as f:
                text = f.read()
        except OSError as e:
            raise UsageError(f"{name}: cannot read: {e.strerror or e}") from None
        except UnicodeDecodeError:
            raise UsageError(f"{name}: not UTF-8 text") from None
    if unit not in ("counts", "mm"):
        raise UsageError(f"unit: {unit!r}; allowed counts, mm")
    rows = []
    for line, rec in _records(text, name):
        rec = {_ALIASES.get(str(k).lower(), str(k).lower()): v for k, v in rec.items()}
        for k in rec:
            if k not in PATH_FIELDS:
                _fail(name, line, f"unknown field {k!r}; allowed t, id, position, speed, current, bus")
        for k in ("t", "id", "position"):
            if rec.get(k) in (None, ""):
                _fail(name, line, f"{k}: missing")
        t = _number(name, line, "t", rec["t"])
        if t < 0:
            _fail(name, line, f"t: {t:g} is before the start (t >= 0)")
        ids = _ids(name, line, rec["id"], protocol.protocol)
        values = {}
        for key, reg in (("position", protocol.position), ("speed", protocol.speed), ("current", protocol.current)):
            v = rec.get(key)
            if v in (None, ""):
                values[key] = None
                continue
            v = _number(name, line, key, v, integer=unit == "counts" or key == "current")
            if unit == "mm" and key != "current":
                per = {}
                for ident in ids:
                    scale = (scales or {}).get(ident)
                    if scale is None:
                        _fail(name, line, f"ID {ident}: no stroke known to convert mm (a fleet file's motion entry)")
                    try:
                        per[ident] = scale.counts(v, what=key) if key == "position" else scale.speed_raw(v)
                    except UsageError as e:
                        _fail(name, line, str(e))
                if len(set(per.values())) > 1:        # the IDs' scales differ: a value per ID
                    values[key] = per
                    continue
                v = next(iter(per.values()))
            elif v != int(v):
                _fail(name, line, f"{key}: {v!r} is not a whole number of {'counts' if key == 'position' else 'mA'}")
            v = int(v)
            if not reg.lo <= v <= reg.hi:
                _fail(name, line, f"{key}: {v} is out of range; allowed {reg.lo}..{reg.hi}")
            values[key] = v
        bus = rec.get("bus")
        if bus is not None and (not isinstance(bus, str) or not bus.strip()):
            _fail(name, line, f"bus: {bus!r} is not a bus name")
        bus = bus.strip() if bus else None
        if any(isinstance(v, dict) for v in values.values()):
            for ident in ids:
                rows.append(Row(t, (ident,), *[v[ident] if isinstance(v, dict) else v
                                               for v in (values["position"], values["speed"], values["current"])],
                                line=line, bus=bus))
        else:
            rows.append(Row(t, ids, values["position"], values["speed"], values["current"], line=line, bus=bus))
    if not rows:
        _fail(name, 0, "no rows (expected t, id, position)")
    rows.sort(key=lambda r: r.t)
    seen = {}
    for r in rows:
        for ident in r.ids:
            key = (r.t, r.bus, ident)
            if key in seen:
                _fail(name, r.line, f"ID {ident} is given twice at t={r.t:g} (line {seen[key]} too)")
            seen[key] = r.line
    return rows


def rows_for_bus(rows, spec, specs, name="path", *, shared=False) -> list:
    """The rows of ``rows`` that bus ``spec`` plays (:class:`zkzap.api.buses.BusSpec`): those
    naming it, and those naming no bus whose IDs are on it (an ID on several of ``specs`` needs
    the row's bus: UsageError; with ``shared``, such a row is played on each of them: buses of
    alike machines)."""
    names = {s.name for s in specs}
    out = []
    for r in rows:
        if r.bus is not None:
            if r.bus not in names:
                _fail(name, r.line, f"bus: no bus {r.bus!r} (the buses: {', '.join(sorted(names))})")
            if r.bus == spec.name:
                out.append(r)
            continue
        for ident in r.ids:
            on = [s.name for s in specs if ident in s.ids]
            if not on:
                _fail(name, r.line, f"ID {ident} is on none of the buses ({', '.join(sorted(names))})")
            if len(on) > 1 and not shared:
                _fail(name, r.line, f"ID {ident} is on buses {', '.join(on)}: give the row's bus")
        mine = tuple(i for i in r.ids if i in spec.ids)
        if mine:
            out.append(Row(r.t, mine, r.position, r.speed, r.current, r.line, spec.name))
    return out


def write_path(stream, rows, *, fmt: str = "csv") -> None:
    """Write waypoint rows (dicts with t, id, position) as a path file ``zap play`` reads."""
    if fmt == "csv":
        stream.write("t,id,position\n")
        for r in rows:
            stream.write(f"{r['t']:g},{r['id']},{r['position']:g}\n")
    elif fmt == "jsonl":
        for r in rows:
            stream.write(json.dumps({"t": r["t"], "id": r["id"], "position": r["position"]}) + "\n")
    else:
        stream.write(json.dumps([{"t": r["t"], "id": r["id"], "position": r["position"]} for r in rows],
                                indent=1) + "\n")


# -- the plan ------------------------------------------------------------------------------------

def _keyframes(rows):
    """[(t, {id: position}, {id: speed}, {id: current})], one per distinct time."""
    out = []
    for r in rows:
        if not out or out[-1][0] != r.t:
            out.append((r.t, {}, {}, {}))
        _, goals, speeds, currents = out[-1]
        for ident in r.ids:
            if r.position is not None:
                goals[ident] = r.position
            if r.speed is not None:
                speeds[ident] = r.speed
            if r.current is not None:
                currents[ident] = r.current
    return out


def max_rate(ids, baud: int, stop_bits: int = 1, protocol=None) -> float:
    """The fastest interpolation rate (Hz) the line carries for a sync move of ``ids``: a
    step's goal-position frames (one Symmetric Store on IR; one answered write per actuator on
    Modbus RTU) within :data:`LINE_SHARE` of each period."""
    step = Step(0.0, {i: 0 for i in ids}, protocol=protocol)
    return LINE_SHARE / step.wire(baud, stop_bits)


class Plan:
    """The steps of a path, checked against the line: ``steps``, ``ids``, ``duration``, ``rate``
    (the interpolation rate, None without), ``baud``, ``note`` (what the check says),
    ``protocol`` (the :mod:`~zkzap.api.motion_wire` wire its frames are for)."""

    def __init__(self, steps, ids, duration, rate, baud, note, protocol=None):
        self.steps, self.ids, self.duration, self.rate, self.baud, self.note = steps, ids, duration, rate, baud, note
        self.protocol = protocol if protocol is not None else IrWire()

    @property
    def frames(self) -> int:
        return sum(len(s.frames) for s in self.steps)


def plan(rows, *, baud: int = 57600, stop_bits: int = 1, interpolate=None, rate=None, protocol=None) -> Plan:
    """The :class:`Plan` of checked path rows at ``baud`` on ``protocol`` (a
    :mod:`~zkzap.api.motion_wire` wire, or ``"ir"``/``"modbus"``; None: IR): refused
    (UsageError) when the line cannot carry it (see the module's description)."""
    if protocol is None or isinstance(protocol, str):
        protocol = wire_for(protocol or "ir")
    keys = _keyframes(rows)
    ids = sorted({i for _, g, s, c in keys for i in (*g, *s, *c)})
    duration = keys[-1][0]
    if interpolate not in (None, "none", "linear"):
        raise UsageError(f"interpolate: {interpolate!r}; allowed linear")
    if interpolate == "linear":
        limit = max_rate(ids, baud, stop_bits, protocol)
        frame = Step(0.0, {i: 0 for i in ids}, protocol=protocol)
        size = (f"{len(frame.frames[0])} bytes" if len(frame.frames) == 1 else
                f"{len(frame.frames)} answered frames of {len(frame.frames[0])} bytes")
        why = (f"a sync move of {len(ids)} actuator{'s' if len(ids) != 1 else ''} is {size}, "
               f"{frame.wire(baud, stop_bits) * 1000:.2f} ms at {baud} baud; {LINE_SHARE:.0%} of the line carries "
               f"{math.floor(limit)} Hz")
        if rate is None:
            rate = min(DEFAULT_RATE, math.floor(limit))
        elif rate > limit:
            raise UsageError(f"--rate {rate:g} Hz: more than the line carries ({why})", rate=rate,
                             max_rate=math.floor(limit))
        steps = _interpolated(keys, ids, rate, protocol)
        note = f"interpolating at {rate:g} Hz ({why})"
    else:
        steps = [Step(t, g, s, c, protocol=protocol) for t, g, s, c in keys]
        note = f"{len(steps)} steps at their own times"
        rate = None
    check_line(steps, baud, stop_bits)
    return Plan(steps, ids, duration, rate, baud, note, protocol)


def check_line(steps, baud: int, stop_bits: int = 1, speed: float = 1.0) -> None:
    """Refuse (UsageError) steps that come closer than their frames take on the line; ``speed``:
    the session clock's model seconds per real second (a simulator run faster: the line is not)."""
    for a, b in zip(steps, steps[1:]):
        need = a.wire(baud, stop_bits) * speed
        if need > b.t - a.t:
            at = f" (a simulator at speed {speed:g}: the line keeps its real time)" if speed != 1 else ""
            raise UsageError(f"the steps at t={a.t:g} s and t={b.t:g} s are {(b.t - a.t) * 1000:.1f} ms apart, but the "
                             f"first one's {len(a.frames)} frame{'s' if len(a.frames) != 1 else ''} take "
                             f"{need * 1000:.2f} ms on the line at {baud} baud{at}: the line cannot carry this path",
                             t=a.t)


def _interpolated(keys, ids, rate, protocol):
    """Steps every 1/rate s: each actuator's goal linear between its keyframes (held before its
    first and after its last); speeds and currents leave with the first step at or after their
    keyframe. Only goals that change are sent."""
    tracks = {i: [(t, g[i]) for t, g, _, _ in keys if i in g] for i in ids}
    extras = [(t, s, c) for t, _, s, c in keys if s or c]
    duration = keys[-1][0]
    n = max(1, math.ceil(duration * rate - 1e-9))
    last = {}
    steps = []
    ei = 0
    for k in range(n + 1):
        t = min(duration, k / rate)
        goals = {}
        for i, track in tracks.items():
            g = _at(track, t)
            if g is not None and last.get(i) != g:
                goals[i] = last[i] = g
        speeds, currents = {}, {}
        while ei < len(extras) and extras[ei][0] <= t + 1e-9:
            speeds.update(extras[ei][1])
            currents.update(extras[ei][2])
            ei += 1
        if goals or speeds or currents:
            steps.append(Step(t, goals, speeds, currents, keyframe=any(abs(t - kt) < 1e-9 for kt, *_ in keys),
                              protocol=protocol))
    return steps


def _at(track, t):
    """The linear goal of ``track`` ([(t, goal)], sorted) at ``t`` (None before its first)."""
    if not track or t < track[0][0] - 1e-9:
        return None
    import bisect

    j = bisect.bisect_right([p[0] for p in track], t + 1e-9) - 1
    if j >= len(track) - 1:
        return track[-1][1]
    (t0, g0), (t1, g1) = track[j], track[j + 1]
    if t1 <= t0:
        return g1
    return round(g0 + (g1 - g0) * (t - t0) / (t1 - t0))


# -- stopping ------------------------------------------------------------------------------------

def stop_all(bus, ids, mode: str = "hold") -> dict:
    """Stop every actuator of ``ids`` now: ``hold`` reads each present position and makes it
    the goal in one sync move (on Modbus RTU one write each, every one tried); ``off`` turns
    the force off. Returns ``{ID: position held, or None}``; an actuator whose position cannot
    be read, or whose hold was not confirmed, is turned off instead (None)."""
    link = getattr(bus, "link", bus)
    wire = wire_of(link)
    ids = list(ids)
    if mode == "off":
        wire.write_all(link, "force-on-off", {i: 0 for i in ids})
        return {i: None for i in ids}
    held, lost = {}, []
    for i in ids:
        # asked twice: a stop often follows a read it interrupted, whose reply the bus still
        # owes (the first ask then gives no value, never a wrong one)
        for attempt in (1, 2):
            try:
                held[i] = wire.read_present(link, i)
                break
            except ZkzapError:
                if attempt == 2:
                    lost.append(i)
    for i in wire.write_all(link, "goal-position", held):
        held.pop(i)
        lost.append(i)
    if lost:
        wire.write_all(link, "force-on-off", {i: 0 for i in lost})
    return {i: held.get(i) for i in ids}


def describe_stop(positions: dict, mode: str) -> str:
    if mode == "off":
        return "force off: " + ", ".join(f"ID {i}" for i in positions)
    return "; ".join(f"ID {i} held at {p}" if p is not None else f"ID {i} force off (its position could not be read)"
                     for i, p in positions.items())


# -- playing -------------------------------------------------------------------------------------

class Stopped:
    """Why a play stopped early: ``reason`` (``interrupted``, ``device-error``, ``current-limit``,
    ``no-reply`` (a goal's write unanswered, on Modbus RTU), ``cancelled``), ``message``, ``positions`` (what :func:`stop_all` held) and ``mode``."""

    __slots__ = ("reason", "message", "positions", "mode", "error")

    def __init__(self, reason, message, positions, mode, error=None):
        self.reason, self.message, self.positions, self.mode, self.error = reason, message, positions, mode, error

    def __repr__(self):
        return f"Stopped({self.reason!r}, {self.message!r})"


def percentile(values, q: float) -> float:
    """The ``q`` quantile (0..1) of ``values`` (nearest rank); nan for none."""
    vals = sorted(values)
    if not vals:
        return math.nan
    return vals[min(len(vals) - 1, max(0, math.ceil(q * len(vals)) - 1))]


class Player:
    """Play ``plan`` on ``bus`` (a :class:`zkzap.api.zap.Bus` or its link) ``loops`` times.

    :meth:`rows` sends the steps on time and yields the log rows (:data:`LOG_COLUMNS`; with
    ``scales`` the mm columns too); ``log=False`` reads nothing between steps. ``limit``: the
    current (mA) that stops everything; ``stop_mode``: ``hold`` or ``off``; ``on_progress(done,
    total)`` after every step; ``settle``: how long after the last step the log goes on until
    every rod is at its goal; ``cancel``: a threading.Event that stops it (and every actuator)
    when set — another bus's failure, a console's Cancel (``cancel_why``: the words of
    :attr:`stopped`); ``start``: the wall-clock moment (time.time()) step 0 is due, shared by
    several buses. After it: :attr:`lateness` (seconds, one per step), :attr:`sent`
    (steps), :attr:`stopped` (a :class:`Stopped`, or None when the plan ran to its end)."""

    def __init__(self, bus, plan, *, loops: int = 1, log: bool = True, limit=None, stop_mode: str = "hold",
                 scales=None, on_progress=None, clock=None, settle: float = 5.0, cancel=None, start=None,
                 cancel_why: str = "another bus stopped"):
        self.link = getattr(bus, "link", bus)
        self.wire = wire_of(self.link)
        if self.wire.protocol != plan.protocol.protocol:
            raise UsageError(f"play: the plan's frames are of the {plan.protocol.protocol} protocol, the bus speaks "
                             f"{self.wire.protocol}")
        self.cancel = cancel
        self.cancel_why = cancel_why
        self._start = start
        self.plan = plan
        self.loops = loops
        self.log = log
        self.limit = limit
        if stop_mode not in STOP_MODES:
            raise UsageError(f"stop: {stop_mode!r}; allowed {', '.join(STOP_MODES)}")
        self.stop_mode = stop_mode
        self.scales = scales or {}
        self.on_progress = on_progress
        if clock is None:
            from ..link.clock import SessionClock

            clock = SessionClock.of_port(self.link.port)
        self.clock = clock
        if clock.speed != 1:
            check_line(plan.steps, self.link.baud, self.link.stop_bits, clock.speed)
        self.lateness = array("d")
        self.sent = 0
        self.reads = 0
        self.read_failures = 0
        self.stopped = None
        self.goal = {}
        self.settle = settle
        self.unsettled = []
        """IDs still away from their last goal (beyond end-compliance-margin) ``settle`` s after
        the last step."""
        self._margins = {}
        self._next = 0

    @property
    def total(self) -> int:
        return len(self.plan.steps) * self.loops

    def _read_cost(self, ident) -> float:
        """Session seconds a log read of ``ident`` is expected to take."""
        learned = self.link.latencies().get(ident) if hasattr(self.link, "latencies") else None
        lat = TURNAROUND
        if learned and learned.get("latency_ms") is not None:
            lat = max(lat, learned["latency_ms"] / 1000.0)      # smoothed: one late reply does not starve it
        # after an unanswered read of it (a silent actuator's) the bus waits, or asks an Echo, first
        held = self._clear_at(ident) - self.link.now() if hasattr(self.link, "clear_at") else 0.0
        return (max(0.0, held) + self.wire.read_cost(self.link, ident, lat) + READ_GUARD) * self.clock.speed

    def _clear_at(self, ident) -> float:
        return self.link.clear_at(ident, self.wire.reads()[0][0])

    def _fits(self, due) -> bool:
        """Whether a log read can end before ``due``: the next actuator in turn whose read fits
        becomes the next one read (one that does not is passed over this time)."""
        ids = self.plan.ids
        now = self.clock.now()
        for k in range(len(ids)):
            if now + self._read_cost(ids[(self._next + k) % len(ids)]) < due:
                self._next += k
                return True
        return False

    def _wait(self, due) -> None:
        clock = self.clock
        if self.cancel is not None:          # wake for a cancel while waiting long
            while due - clock.now() > 0.1 * clock.speed and not self.cancel.is_set():
                clock.sleep(0.05 * clock.speed)
        left = due - clock.now()
        virtual = getattr(clock, "virtual", False)        # a simulator's virtual clock: no time passes in a spin
        spin = 0.0 if virtual else SPIN * clock.speed
        if left > spin:
            clock.sleep(left - spin)
        while clock.now() < due:
            if virtual:
                clock.sleep(max(due - clock.now(), 1e-9))

    def _send(self, step) -> None:
        for frame in step.frames:
            self.wire.send(self.link, frame)
        self.goal.update(step.goals)

    def _read_one(self, loop, due=None):
        """Read the next actuator in turn; ``due``: the next step's time, which its reply's wait
        must end before (an actuator that does not answer by then is no-reply, never a late step)."""
        ids = self.plan.ids
        ident = ids[self._next % len(ids)]
        self._next += 1
        kw = {}
        if due is not None and hasattr(self.link, "clear_at"):
            start = max(self.link.now(), self._clear_at(ident))
            kw["window"] = max(TURNAROUND, (due - self.clock.now()) / self.clock.speed
                               - (start - self.link.now()) - self.wire.read_cost(self.link, ident, 0.0)
                               - READ_GUARD / 2)
            kw["optional"] = True          # silence by then is its answer: no listening on past the step
        row = {"time": None, "t": None, "loop": loop, "id": ident, "goal": self.goal.get(ident), "present": None,
               "tracking_error": None, "current_ma": None, "voltage_v": None, "errors": [], "status": "ok"}
        for col in self.wire.log_columns:
            row[col] = None
        reply = None
        try:
            reply = self.wire.read_sample(self.link, ident, retries=0, **kw)
            if reply is None:
                row["status"] = "no-reply"
        except NoReply:
            row["status"] = "no-reply"
        except BadReply:
            row["status"] = "bad-reply"
        t = self.clock.now()
        row["t"] = round(t, 4)
        row["time"] = self.clock.iso(t) if hasattr(self.clock, "iso") else None
        self.reads += 1
        if reply is None:
            self.read_failures += 1
        else:
            row["present"] = reply.position
            row["current_ma"] = reply.current
            row["voltage_v"] = reply.voltage_v
            if self.wire.log_columns:
                row["voltage_raw"] = reply.voltage_raw
            row["errors"] = reply.errors
            if row["goal"] is not None and row["present"] is not None:
                row["tracking_error"] = row["present"] - row["goal"]
        scale = self.scales.get(ident)
        if scale is not None:
            row["goal_mm"] = None if row["goal"] is None else scale.mm(row["goal"])
            row["present_mm"] = None if row["present"] is None else scale.mm(row["present"])
            row["tracking_error_mm"] = None if row["tracking_error"] is None else \
                round(row["tracking_error"] * scale.mm_per_count, 3)
        return row, reply

    def _check(self, row, reply):
        """A Stopped reason for a row, or None."""
        if reply is not None and reply.error:
            return "device-error", f"ID {row['id']} reports {', '.join(reply.errors)}"
        if self.limit is not None and row["current_ma"] is not None and row["current_ma"] > self.limit:
            return "current-limit", f"ID {row['id']} draws {row['current_ma']} mA, over the limit of {self.limit:g} mA"
        return None

    def stop(self, reason="interrupted", message="interrupted", error=None) -> None:
        """Stop every actuator now (as a Ctrl-C does; for a caller interrupted outside
        :meth:`rows`, while handling a row). Once: a second call does nothing."""
        if self.stopped is not None:
            return
        self._stop(reason, message, error)

    def _stop(self, reason, message, error=None):
        try:
            positions = stop_all(self.link, self.plan.ids, self.stop_mode)
        except ZkzapError as e:
            positions = {}
            message += f"; stopping failed: {e}"
        self.stopped = Stopped(reason, message, positions, self.stop_mode, error)

    def rows(self):
        """Send the plan, yielding log rows; returns when it ends or is stopped (a
        KeyboardInterrupt goes on after every actuator was stopped)."""
        steps = self.plan.steps
        period = self.plan.duration
        if self.plan.rate:
            period += 1.0 / self.plan.rate
        if self.log:
            for i in self.plan.ids:
                try:
                    self._margins[i] = max(1, self.wire.read_margin(self.link, i))
                except ZkzapError:
                    pass            # its reads fail in the log too, and say so there
        start = self.clock.now()
        if self._start is not None:         # a time shared with other buses' players
            start += (self._start - time.time()) * self.clock.speed
        done = 0
        try:
            for loop in range(1, self.loops + 1):
                base = start + (loop - 1) * period
                for k, step in enumerate(steps):
                    due = base + step.t
                    self._wait(due)
                    if self.cancel is not None and self.cancel.is_set():
                        self._stop("cancelled", self.cancel_why)
                        return
                    self.lateness.append((self.clock.now() - due) / self.clock.speed)
                    self._send(step)
                    self.sent += 1
                    done += 1
                    if self.on_progress is not None:
                        self.on_progress(done, self.total)
                    if not self.log:
                        continue
                    last = loop == self.loops and k + 1 == len(steps)
                    nxt = base + steps[k + 1].t if k + 1 < len(steps) else base + period
                    if last:                # the end: read until every rod has reached its goal
                        nxt = self.clock.now() + self.settle
                    settled = set()
                    while self._fits(nxt):
                        if self.cancel is not None and self.cancel.is_set():
                            self._stop("cancelled", self.cancel_why)       # now, not at the next step
                            return
                        row, reply = self._read_one(loop, None if last else nxt)
                        yield row
                        bad = self._check(row, reply)
                        if bad is not None:
                            self._stop(*bad)
                            return
                        if last and row["tracking_error"] is not None:
                            if abs(row["tracking_error"]) <= self._margins.get(row["id"], 1):
                                settled.add(row["id"])
                            else:
                                settled.discard(row["id"])
                            if len(settled) == len(self.plan.ids):
                                break
                    if last and len(settled) < len(self.plan.ids):
                        self.unsettled = sorted(set(self.plan.ids) - settled)
        except KeyboardInterrupt:
            self._stop("interrupted", "interrupted")
            raise
        except DeviceError as e:
            self._stop("device-error", str(e), e)
        except NoReply as e:                 # a goal's write unanswered (Modbus RTU answers each)
            self._stop("no-reply", str(e), e)

    def run(self, on_row=None):
        """Play to the end; ``on_row(row)`` for every log row. Returns self."""
        for row in self.rows():
            if on_row is not None:
                on_row(row)
        return self

    def summary(self) -> dict:
        """Counts and lateness figures (ms): ``steps``, ``frames``, ``reads``, ``read_failures``,
        ``lateness_p50_ms``, ``lateness_p99_ms``, ``lateness_max_ms``, ``stopped``."""
        late = list(self.lateness)
        ms = (lambda v: None if v != v else round(v * 1000, 3))
        return {"steps": self.sent, "frames": sum(len(s.frames) for s in self.plan.steps) * self.loops
                if self.stopped is None else None, "reads": self.reads, "read_failures": self.read_failures,
                "lateness_p50_ms": ms(percentile(late, 0.5)), "lateness_p99_ms": ms(percentile(late, 0.99)),
                "lateness_max_ms": ms(max(late)) if late else None,
                "stopped": None if self.stopped is None else self.stopped.reason}


def play(bus, path, *, unit="counts", scales=None, interpolate=None, rate=None, loops=1, log=True, limit=None,
         stop_mode="hold", on_row=None, on_progress=None) -> Player:
    """Read, plan and play the path file ``path`` on ``bus`` (see :class:`Player`); returns the
    Player (its :meth:`Player.summary` and :attr:`Player.stopped`)."""
    link = getattr(bus, "link", bus)
    wire = wire_of(link)
    rows = read_path(path, unit=unit, scales=scales, protocol=wire)
    p = plan(rows, baud=link.baud, stop_bits=link.stop_bits, interpolate=interpolate, rate=rate, protocol=wire)
    return Player(bus, p, loops=loops, log=log, limit=limit, stop_mode=stop_mode, scales=scales,
                  on_progress=on_progress).run(on_row)


# -- teaching ------------------------------------------------------------------------------------

def read_positions(bus, ids) -> dict:
    """``{ID: present position}`` of every actuator of ``ids`` (a failed read raises)."""
    link = getattr(bus, "link", bus)
    return {i: link.read(i, PRESENT) for i in ids}


class Teacher:
    """Waypoints from the actuators' present positions: :meth:`take` reads every ID and returns
    its rows (``t``, ``id``, ``position``; with ``scale``s, in mm); ``t`` is ``interval`` x the
    waypoint's number, or with ``timed`` the session time since the first waypoint."""

    def __init__(self, bus, ids, *, interval: float = 1.0, timed: bool = False, scales=None, clock=None):
        self.bus = bus
        self.ids = list(ids)
        self.interval = interval
        self.timed = timed
        self.scales = scales or {}
        self.count = 0
        self._t0 = None
        self.clock = clock or time.monotonic

    def take(self) -> list:
        positions = read_positions(self.bus, self.ids)
        now = self.clock()
        if self._t0 is None:
            self._t0 = now
        t = round(now - self._t0, 3) if self.timed else round(self.count * self.interval, 6)
        self.count += 1
        rows = []
        for i, pos in positions.items():
            scale = self.scales.get(i)
            rows.append({"t": t, "id": i, "position": scale.mm(pos) if scale is not None else pos, "counts": pos})
        return rows
