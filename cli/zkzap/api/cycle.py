"""Endurance cycles of one actuator: ``zap cycle`` (:class:`Cycler`).

A cycle moves the rod from end A to end B and back (or plays a path once, see
:mod:`zkzap.api.motion`). Each leg writes the goal and then polls the log read of
:mod:`zkzap.api.motion_wire` (present-position .. present-voltage in one Load Data on IR; the
map's runs of hardware-error, present-position, present-current and present-voltage on Modbus
RTU) back to back (the poll rate the line allows, as ``zap watch`` does), and measures:

- ``reach_s``: the time from the goal's write to the first reading within the actuator's
  end-compliance-margin of the goal;
- ``overshoot``: how far the rod went past the goal, in the direction it travelled (counts),
  from the write to the end of the dwell;
- the current (peak and mean over the move), the lowest supply voltage (on Modbus RTU the raw
  value, ``min_voltage_raw``: the 17Lf's map gives no unit) and the error bits of every read
  (the IR reply's error byte; the hardware-error register on Modbus RTU).

After the goal is reached the rod dwells ``dwell`` seconds (still polled). A cycle is one
record (:data:`COLUMNS`). The run stops, stopping the rod where it is (goal := present
position, :func:`zkzap.api.motion.stop_all`), on an error bit, a stall (no progress of
:data:`STALL_COUNTS` toward the goal within ``stall`` seconds), a current over ``limit`` mA, a
leg longer than ``timeout`` seconds, or Ctrl-C. :class:`CycleState` keeps how far a run got (a
JSON file rewritten after every cycle), so an interrupted run resumes at its next cycle.

Nothing here imports click or rich.
"""

from __future__ import annotations

import json
import os
import time

from ..errors import BadReply, NoReply, UsageError, ZkzapError
from .motion import stop_all
from .motion_wire import wire_of

#: Progress toward the goal that counts as moving (counts), within ``stall`` seconds.
STALL_COUNTS = 3
STATE_FORMAT = "zkzap-cycle/1"
#: One record per cycle.
COLUMNS = ["cycle", "time", "t", "reach_b_s", "reach_a_s", "overshoot_b", "overshoot_a", "peak_current_ma",
           "mean_current_ma", "min_voltage_v", "errors", "polls", "status"]
MM_COLUMNS = ["overshoot_b_mm", "overshoot_a_mm"]
#: The column a record gains on Modbus RTU, whose present-voltage has no documented unit: the raw value.
RAW_VOLTAGE_COLUMNS = ["min_voltage_raw"]
REASONS = ("done", "duration", "device-error", "stall", "current-limit", "timeout", "no-reply", "interrupted",
           "cancelled")


class Leg:
    """What one move measured: ``reach_s`` (None when not reached), ``overshoot``, ``peak``,
    ``mean`` (mA), ``min_voltage`` (V), ``errors`` (names), ``polls``, ``stop`` (a reason of
    :data:`REASONS` or None) and ``why`` (its words)."""

    __slots__ = ("reach_s", "overshoot", "peak", "mean", "min_voltage", "errors", "polls", "stop", "why")

    def __init__(self):
        self.reach_s = None
        self.overshoot = 0
        self.peak = 0
        self.mean = None
        self.min_voltage = None
        self.errors = set()
        self.polls = 0
        self.stop = None
        self.why = ""


class Cycler:
    """Cycle actuator ``ident`` between positions ``a`` and ``b`` on ``bus`` (a Bus or its
    link). :meth:`run` yields one record per cycle, from cycle ``first`` to ``cycles``;
    afterwards :attr:`reason`/:attr:`why` say why it ended and :attr:`held` where the rod was
    stopped. ``speed``: goal-speed written first; ``scale`` (a :class:`zkzap.api.units.Scale`)
    adds the overshoot in mm; ``cancel``: a threading.Event (anything with ``is_set()``) that,
    once set, stops the rod and ends the run at the next poll (reason ``cancelled``,
    ``cancel_why`` its words: another bus stopped, a console's Cancel)."""

    def __init__(self, bus, ident, a, b, *, dwell=0.5, cycles=10, first=1, speed=None, stall=1.0, limit=None,
                 timeout=10.0, scale=None, clock=None, duration=None, cancel=None, cancel_why="cancelled"):
        self.link = getattr(bus, "link", bus)
        self.wire = wire_of(self.link)
        self.cancel = cancel
        self.cancel_why = cancel_why
        from .fleet import check_ident

        self.ident = check_ident(self.wire.map, ident)
        for v in (a, b):
            self.wire.position.check(v)
        if a == b:
            raise UsageError("between: the two ends are the same position")
        if speed is not None:
            self.wire.speed.check(speed)
        self.a, self.b = a, b
        self.dwell, self.cycles, self.first = dwell, cycles, first
        self.speed, self.stall, self.limit, self.timeout = speed, stall, limit, timeout
        self.scale = scale
        self.duration = duration
        self._end = None
        if clock is None:
            from ..link.clock import SessionClock

            clock = SessionClock.of_port(self.link.port)
        self.clock = clock
        self.margin = 1
        self.reason = None
        self.why = ""
        self.held = None
        self.polls = 0
        self.poll_time = 0.0
        self.done = first - 1

    def wire_limit(self) -> float:
        """Polls per second the line allows for this read (the wire and the actuator's turnaround;
        on Modbus RTU the silence before each request too)."""
        from .watch import TURNAROUND

        return 1.0 / self.wire.read_cost(self.link, self.ident, TURNAROUND)

    @property
    def achieved(self) -> float:
        """Polls per second achieved while polling."""
        return self.polls / self.poll_time if self.poll_time > 0 else 0.0

    def _poll(self):
        return self.wire.read_sample(self.link, self.ident)

    def leg(self, goal) -> Leg:
        """Move to ``goal``, measure until it is reached and the dwell is over."""
        leg = Leg()
        link, clock = self.link, self.clock
        link.store(self.ident, self.wire.position, goal)
        t0 = clock.now()
        start = None
        direction = 0
        best = None                         # the closest to the goal so far
        progress_t = t0
        currents = []
        reached_at = None
        poll_start = time.monotonic()
        try:
            while True:
                try:
                    reply = self._poll()
                except NoReply as e:
                    leg.stop, leg.why = "no-reply", str(e)
                    return leg
                now = clock.now()
                leg.polls += 1
                pos, cur = reply.position, reply.current
                volts = reply.voltage_v if reply.voltage_v is not None else reply.voltage_raw
                if start is None:
                    start = pos
                    direction = 1 if goal > start else -1
                leg.errors.update(reply.errors)
                if volts is not None:
                    leg.min_voltage = volts if leg.min_voltage is None else min(leg.min_voltage, volts)
                leg.overshoot = max(leg.overshoot, (pos - goal) * direction)
                if reached_at is None:
                    currents.append(cur)
                    leg.peak = max(leg.peak, cur)
                if reply.error:
                    leg.stop, leg.why = "device-error", f"ID {self.ident} reports {', '.join(reply.errors)}"
                    return leg
                if self.limit is not None and cur > self.limit:
                    leg.stop, leg.why = "current-limit", (f"ID {self.ident} draws {cur} mA, over the limit of "
                                                          f"{self.limit:g} mA")
                    return leg
                if reached_at is None:
                    distance = abs(goal - pos)
                    if distance <= self.margin:
                        reached_at = now
                        leg.reach_s = round(now - t0, 4)
                    else:
                        if best is None or distance <= best - STALL_COUNTS:
                            best, progress_t = distance, now
                        elif now - progress_t > self.stall:
                            leg.stop, leg.why = "stall", (f"ID {self.ident} stalled at {pos}: no progress toward "
                                                          f"{goal} in {self.stall:g} s (current {cur} mA)")
                            return leg
                        if now - t0 > self.timeout:
                            leg.stop, leg.why = "timeout", (f"ID {self.ident} did not reach {goal} in "
                                                            f"{self.timeout:g} s (at {pos})")
                            return leg
                if reached_at is not None and now - reached_at >= self.dwell:
                    return leg
                if self.cancel is not None and self.cancel.is_set():
                    leg.stop, leg.why = "cancelled", self.cancel_why
                    return leg
                if self._end is not None and now >= self._end:
                    leg.stop, leg.why = "duration", f"stopped after {self.duration:g} s (--duration)"
                    return leg
        finally:
            self.polls += leg.polls
            self.poll_time += time.monotonic() - poll_start
            if currents:
                leg.mean = round(sum(currents) / len(currents), 1)

    def run(self):
        """Cycle until ``cycles`` or a stop; yields one record per cycle (a stopped cycle's
        record too, status naming the reason). A KeyboardInterrupt stops the rod and goes on."""
        link = self.link
        try:
            # error bits are the first poll's to report (as a stop), not this read's
            self.margin = max(1, self.wire.read_margin(link, self.ident))
            if self.speed is not None:
                link.store(self.ident, self.wire.speed, self.speed)
            start = self.clock.now()
            if self.duration is not None:
                self._end = start + self.duration
            for n in range(self.first, self.cycles + 1):
                t = round(self.clock.now() - start, 3)
                rec = {"cycle": n, "time": self.clock.iso(t) if hasattr(self.clock, "iso") else None, "t": t}
                legs = []
                for goal in (self.b, self.a):
                    leg = self.leg(goal)
                    legs.append(leg)
                    if leg.stop:
                        break
                rec.update(self._record(legs))
                if legs[-1].stop:
                    self._halt(legs[-1].stop, legs[-1].why)
                    yield rec
                    return
                self.done = n
                yield rec
            self.reason = "done"
        except KeyboardInterrupt:
            self._halt("interrupted", "interrupted")
            raise
        except (BadReply, ZkzapError) as e:
            if self.reason is None:
                self._halt("no-reply" if isinstance(e, NoReply) else "device-error", str(e))
            raise

    def _record(self, legs):
        b = legs[0]
        a = legs[1] if len(legs) > 1 else None
        both = [x for x in legs]
        currents = [x.mean for x in both if x.mean is not None]
        volts = [x.min_voltage for x in both if x.min_voltage is not None]
        rec = {"reach_b_s": b.reach_s, "reach_a_s": a.reach_s if a else None, "overshoot_b": b.overshoot,
               "overshoot_a": a.overshoot if a else None, "peak_current_ma": max(x.peak for x in both),
               "mean_current_ma": round(sum(currents) / len(currents), 1) if currents else None,
               "min_voltage_v": min(volts) if volts else None,
               "errors": sorted(set().union(*(x.errors for x in both))), "polls": sum(x.polls for x in both),
               "status": legs[-1].stop or "ok"}
        if self.wire.log_columns:             # Modbus RTU: the voltage raw, its unit undocumented
            rec["min_voltage_raw"], rec["min_voltage_v"] = rec["min_voltage_v"], None
        if self.scale is not None:
            k = abs(self.scale.mm_per_count)
            rec["overshoot_b_mm"] = round(b.overshoot * k, 3)
            rec["overshoot_a_mm"] = round(a.overshoot * k, 3) if a else None
        return rec

    def halt(self, reason="interrupted", why="interrupted") -> None:
        """Stop the rod now (for a caller interrupted outside :meth:`run`); once."""
        if self.reason is None:
            self._halt(reason, why)

    def _halt(self, reason, why):
        self.reason, self.why = reason, why
        try:
            self.held = stop_all(self.link, [self.ident]).get(self.ident)
        except ZkzapError as e:
            self.why += f"; stopping failed: {e}"


class CycleState:
    """How far a cycle run got, in a JSON file rewritten whole after every cycle: its
    parameters (``params``), ``done`` (the last cycle finished; of a run on several buses the
    least any bus finished), the output file it writes and, for a run on several buses,
    ``buses`` ({bus name: the last cycle it finished}; None for one bus)."""

    KEYS = ("id", "between", "dwell", "cycles", "speed", "stall", "limit", "timeout")

    def __init__(self, path, params, done=0, output=None, started=None, buses=None):
        self.path, self.params, self.done, self.output = path, dict(params), done, output
        self.buses = dict(buses) if buses is not None else None
        self.started = started or time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())

    @classmethod
    def load(cls, path) -> "CycleState":
        from . import documents

        doc, name = documents.read(path, "cycle state", "json")
        if not isinstance(doc, dict) or doc.get("format") != STATE_FORMAT:
            raise UsageError(f"{name}: not a zap cycle state file (format {STATE_FORMAT!r})")
        params = doc.get("params")
        if not isinstance(params, dict) or any(k not in params for k in cls.KEYS):
            raise UsageError(f"{name}: params: missing; expected {', '.join(cls.KEYS)}")
        done = doc.get("done")
        if not isinstance(done, int) or isinstance(done, bool) or done < 0:
            raise UsageError(f"{name}: done: {done!r} is not a cycle count")
        buses = doc.get("buses")
        if buses is not None:
            if not isinstance(buses, dict) or not buses:
                raise UsageError(f"{name}: buses: expected an object of bus name -> the last cycle it finished")
            for bus, n in buses.items():
                if not isinstance(n, int) or isinstance(n, bool) or n < 0:
                    raise UsageError(f"{name}: buses.{bus}: {n!r} is not a cycle count")
        return cls(path, params, done, doc.get("output"), doc.get("started"), buses)

    def save(self) -> None:
        from ..outfile import write_whole

        doc = {"format": STATE_FORMAT, "started": self.started,
               "updated": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "params": self.params,
               "done": self.done, "output": self.output}
        if self.buses is not None:
            doc["buses"] = self.buses
        write_whole(self.path, json.dumps(doc, indent=1) + "\n", what="state")

    def exists(self) -> bool:
        return os.path.exists(self.path)


#: One record per cycle of a path (``--path``).
PATH_COLUMNS = ["cycle", "time", "t", "max_tracking_error", "peak_current_ma", "mean_current_ma", "min_voltage_v",
                "errors", "reads", "lateness_p99_ms", "status"]


class PathCycler:
    """Cycles that each play ``plan`` (:class:`zkzap.api.motion.Plan`) once: one record per
    cycle (:data:`PATH_COLUMNS`): the largest tracking error, peak and mean current, lowest
    voltage, error bits of the log reads. Stops (every actuator held) as a play stops; ``cancel``
    as :class:`zkzap.api.motion.Player`'s."""

    def __init__(self, bus, plan, *, cycles=10, first=1, limit=None, scales=None, clock=None, duration=None,
                 cancel=None, cancel_why="another bus stopped"):
        from .motion import Player

        self.bus, self.plan, self.cycles, self.first, self.limit = bus, plan, cycles, first, limit
        self.scales = scales
        self.duration = duration
        self._player = lambda: Player(bus, plan, limit=limit, scales=scales, clock=clock, settle=1.0, cancel=cancel,
                                      cancel_why=cancel_why)
        self.reason = None
        self.why = ""
        self.held = None
        self.done = first - 1
        self.polls = 0
        self.poll_time = 0.0
        self.player = None

    def halt(self, reason="interrupted", why="interrupted") -> None:
        """Stop every actuator now (for a caller interrupted outside :meth:`run`); once."""
        if self.player is not None and self.reason is None:
            self.player.stop(reason, why)
            self.held = self.player.stopped.positions if self.player.stopped else None

    def run(self):
        start = None
        for n in range(self.first, self.cycles + 1):
            player = self.player = self._player()
            if start is None:
                start = player.clock.now()
            elif self.duration is not None and player.clock.now() - start >= self.duration:
                self.reason, self.why = "duration", f"stopped after {self.duration:g} s (--duration)"
                return
            t = round(player.clock.now() - start, 3)
            worst, currents, volts, raws, errors = 0, [], [], [], set()
            t0 = time.monotonic()
            for row in player.rows():
                if row["tracking_error"] is not None:
                    worst = max(worst, abs(row["tracking_error"]))
                if row["current_ma"] is not None:
                    currents.append(row["current_ma"])
                if row["voltage_v"] is not None:
                    volts.append(row["voltage_v"])
                if row.get("voltage_raw") is not None:
                    raws.append(row["voltage_raw"])
                errors.update(row["errors"])
            self.polls += player.reads
            self.poll_time += time.monotonic() - t0
            stopped = player.stopped
            rec = {"cycle": n, "time": player.clock.iso(t), "t": t, "max_tracking_error": worst,
                   "peak_current_ma": max(currents) if currents else None,
                   "mean_current_ma": round(sum(currents) / len(currents), 1) if currents else None,
                   "min_voltage_v": min(volts) if volts else None, "errors": sorted(errors), "reads": player.reads,
                   "lateness_p99_ms": player.summary()["lateness_p99_ms"],
                   "status": stopped.reason if stopped else "ok"}
            if player.wire.log_columns:
                rec["min_voltage_raw"] = min(raws) if raws else None
            if stopped is not None:
                self.reason, self.why = stopped.reason, stopped.message
                self.held = stopped.positions
                yield rec
                return
            self.done = n
            yield rec
        self.reason = "done"

    @property
    def achieved(self) -> float:
        return self.polls / self.poll_time if self.poll_time > 0 else 0.0
