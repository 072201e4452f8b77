"""Play, teach and cycle from the mightyZAP console's page (a part of :class:`~.zap_console.ZapConsole`).

The page only renders what the library's objects do: a play is :class:`zkzap.api.motion.Player`
(what ``zap play`` and ``Bus.play`` run), teaching is :class:`zkzap.api.motion.Teacher`
(``zap teach``), a cycle run is :class:`zkzap.api.cycle.Cycler` (``zap cycle``). A play and a
cycle run are jobs: they have the bus (moves are refused meanwhile), their progress goes to every
page, Cancel stops every actuator where it is (the library's stop) and says so. A play's log rows
are the live view's samples while it plays, and a summary (lateness p50/p99/max, reads) ends it;
a cycle's records go to every page as they come. Teaching takes a waypoint when the page asks
(between two polls of the live view), or on its own at a rate; the waypoints are every page's
to see, to download as a path file and to play.
"""

from __future__ import annotations

import io
import time

from ..codec import zap
from ..errors import UsageError
from .console import number

#: Longest path text a page may send (characters).
PATH_MAX = 2_000_000
#: Cycle records kept for a page that connects.
CYCLES_KEPT = 500


class _CancelFlag:
    """The console's Cancel as the ``cancel`` event a Player or Cycler polls."""

    def __init__(self, console):
        self.console = console

    def is_set(self) -> bool:
        return bool(self.console._cancel) or self.console.closing_now


class MotionTools:
    """The play, teach and cycle requests of the zap console (mixed into ZapConsole)."""

    def motion_init(self):
        self.teacher = None
        self.waypoints = []            # the teacher's rows so far
        self.teach_rate = None         # waypoints a second while teaching on its own
        self._teach_next = None
        self.cycles = []               # the last cycle run's records (the newest CYCLES_KEPT)
        self.last_play = None          # the last play's summary

    def motion_snapshot(self) -> list:
        out = [self._teach_message()]
        if self.cycles:
            out.append({"type": "cycles", "items": list(self.cycles), "reset": True})
        if self.last_play is not None:
            out.append({"type": "played", **self.last_play})
        return out

    # -- play ---------------------------------------------------------------------------------

    def _plan(self, msg):
        from ..api import motion

        if msg.get("taught"):
            if not self.waypoints:
                raise UsageError("play: nothing taught yet")
            text, name = _path_text(self.waypoints), "the taught path"
        else:
            text = msg.get("text")
            name = str(msg.get("name") or "path")[:200]
            if not isinstance(text, str) or not text.strip():
                raise UsageError("play: no path (choose a file of rows t, id, position)")
            if len(text) > PATH_MAX:
                raise UsageError(f"play: {name} is over {PATH_MAX} characters")
        link = self.bus.link
        wire = motion.wire_of(link)          # the bus's protocol: its IDs, ranges and frames
        rows = motion.read_path(io.StringIO(text), name=name, protocol=wire)
        interpolate = msg.get("interpolate") or None
        if interpolate not in (None, "linear"):
            raise UsageError(f"interpolate: {interpolate!r}; allowed linear")
        rate = None if msg.get("rate") in (None, "") else number(msg, "rate", float, 0.1, 1000, "rate")
        plan = motion.plan(rows, baud=link.baud, stop_bits=link.stop_bits, interpolate=interpolate, rate=rate,
                           protocol=wire)
        for ident in plan.ids:
            self._known({"id": ident})
        return plan, name

    def op_plan(self, ctx, msg):
        """The plan of a path and its frames, nothing sent (``zap play -n``)."""
        plan, name = self._plan(msg)
        steps = [{"t": round(s.t, 4), "frames": [f.hex(" ").upper() for f in s.frames]} for s in plan.steps[:400]]
        self.reply(ctx, note=plan.note, steps=steps, total=len(plan.steps), frames=plan.frames,
                   duration=plan.duration, ids=plan.ids, name=name)

    def op_play(self, ctx, msg):
        from ..api import motion

        plan, name = self._plan(msg)
        loops = number(msg, "loops", int, 1, 100000, "loops") if msg.get("loops") not in (None, "") else 1
        limit = None if msg.get("limit") in (None, "") else number(msg, "limit", float, 1, self._current_hi(), "limit")
        stop_mode = msg.get("stop") or "hold"
        player = motion.Player(self.bus, plan, loops=loops, limit=limit, stop_mode=stop_mode,
                               on_progress=lambda done, total: self._progress_quiet("play", done, total,
                                                                              f"step {done} of {total}"),
                               cancel=_CancelFlag(self), cancel_why="cancelled from the page")
        self.log(f"{ctx.label} plays {name}: {plan.note}; {len(plan.steps)} steps"
                 + (f" x {loops}" if loops > 1 else ""))
        worst = {}
        try:
            for row in player.rows():
                self._played(row)
                if row["tracking_error"] is not None:
                    worst[row["id"]] = max(worst.get(row["id"], 0), abs(row["tracking_error"]))
        finally:
            if player.stopped is None and self._cancel:
                player.stop("cancelled", "cancelled from the page")
        s = player.summary()
        stopped = player.stopped
        result = {"name": name, "summary": s, "worst": {str(k): v for k, v in worst.items()},
                  "stopped": None if stopped is None else {"reason": stopped.reason, "message": stopped.message,
                                                          "positions": {str(k): v for k, v in
                                                                        stopped.positions.items()}},
                  "unsettled": player.unsettled}
        self.last_play = result
        self.broadcast({"type": "played", **result})
        text = (f"play {name}: {s['steps']} of {player.total} steps; lateness p50 {_ms(s['lateness_p50_ms'])}, "
                f"p99 {_ms(s['lateness_p99_ms'])}, max {_ms(s['lateness_max_ms'])}; {s['reads']} log reads")
        if stopped is not None:
            text += f"; stopped every actuator ({stopped.message}): {motion.describe_stop(stopped.positions, stopped.mode)}"
        self.log(text, "warn" if stopped is not None else "info")
        self.reply(ctx, **result)

    def _played(self, row):
        """A play's log row as a live sample (the table and plots follow the play)."""
        if row["status"] != "ok":
            return
        self.hub.sample({"w": round(time.time() * 1000, 1), "id": row["id"], "status": "ok", "errors": row["errors"],
                         "rtt": None, "goal": row["goal"], "pos": row["present"], "cur": row["current_ma"],
                         "volt": row["voltage_v"] if row["voltage_v"] is not None else row.get("voltage_raw"),
                         "gspeed": None, "gcur": None, "moving": None, "play": True})

    # -- teach --------------------------------------------------------------------------------

    def _teach_message(self):
        return {"type": "teach", "ids": self.teacher.ids if self.teacher else [], "rows": self.waypoints[-2000:],
                "count": self.teacher.count if self.teacher else 0, "rate": self.teach_rate}

    def op_teach(self, ctx, msg):
        """Start teaching ``ids`` (every polled actuator by default); ``rate`` (Hz): waypoints
        on their own, timed; none: one each time the page asks (``teach-take``)."""
        from ..api.motion import Teacher

        ids = msg.get("ids")
        if ids in (None, "", []):
            ids = [i for i, a in self.actuators.items() if a["polled"] and a["baud"] == self.bus.baud]
        elif isinstance(ids, str):
            try:
                ids = zap.parse_id_list(ids, "ids")
            except ValueError as e:
                raise UsageError(str(e)) from None
        if not isinstance(ids, list) or not ids:
            raise UsageError("teach: no actuator to teach; scan first")
        ids = [self._known({"id": i}) for i in ids]
        rate = None if msg.get("rate") in (None, "", 0) else number(msg, "rate", float, 0.1, 50, "rate")
        interval = 1.0 if msg.get("interval") in (None, "") else number(msg, "interval", float, 0.01, 3600,
                                                                        "interval")
        self.teacher = Teacher(self.bus, ids, interval=interval, timed=rate is not None)
        self.waypoints = []
        self.teach_rate = rate
        self._teach_next = time.monotonic() if rate else None
        self.log(f"{ctx.label} teaches IDs {zap.id_ranges(ids)}" + (f" at {rate:g} waypoints/s" if rate else ""))
        self.broadcast(self._teach_message())
        self.reply(ctx, ids=ids, rate=rate)

    def op_teach_take(self, ctx, msg):
        if self.teacher is None:
            raise UsageError("teach: start teaching first")
        rows = self._take()
        self.reply(ctx, rows=rows, count=self.teacher.count)

    def op_teach_stop(self, ctx, msg):
        if self.teacher is not None:
            self.log(f"{ctx.label} ends teaching: {self.teacher.count} waypoints of IDs {zap.id_ranges(self.teacher.ids)}")
        self.teach_rate = None
        self._teach_next = None
        self.broadcast(self._teach_message())
        self.reply(ctx, count=self.teacher.count if self.teacher else 0)

    def op_teach_file(self, ctx, msg):
        fmt = str(msg.get("format") or "csv")
        if fmt not in ("csv", "json", "jsonl"):
            raise UsageError(f"format: {fmt!r}; allowed csv, json, jsonl")
        if not self.waypoints:
            raise UsageError("teach: nothing taught yet")
        self.reply(ctx, text=_path_text(self.waypoints, fmt), filename=f"taught-{time.strftime('%Y%m%d-%H%M%S')}.{fmt}")

    def _take(self):
        rows = self.teacher.take()
        self.waypoints.extend(rows)
        self.broadcast({"type": "teach", "ids": self.teacher.ids, "rows": rows, "count": self.teacher.count,
                        "rate": self.teach_rate, "append": True})
        return rows

    def teach_due(self) -> bool:
        return self._teach_next is not None and time.monotonic() >= self._teach_next

    def teach_tick(self) -> None:
        """On the worker between polls: a timed waypoint when one is due."""
        if not self.teach_due() or self.busy:
            return
        self._teach_next += 1.0 / self.teach_rate
        if self._teach_next < time.monotonic():      # fell behind (a job had the bus): no burst
            self._teach_next = time.monotonic() + 1.0 / self.teach_rate
        try:
            self._take()
        except Exception as e:  # noqa: BLE001 - a failed read ends the timed teaching, said
            from ..errors import PortError, ZkzapError

            if isinstance(e, PortError) or not isinstance(e, ZkzapError):
                raise
            self.teach_rate = self._teach_next = None
            self.log(f"teach: {e}; teaching on its own ends", "error")
            self.broadcast(self._teach_message())

    # -- cycle --------------------------------------------------------------------------------

    def op_cycle(self, ctx, msg):
        from ..api.cycle import Cycler

        ident = self._known(msg)
        goal = self.reg("goal-position")            # the bus's map: its range, not the IR table's
        a = number(msg, "a", int, goal.lo, goal.hi, "A")
        b = number(msg, "b", int, goal.lo, goal.hi, "B")
        opt = {"dwell": ("dwell", float, 0, 3600, 0.5), "cycles": ("cycles", int, 1, 100_000_000, 10),
               "stall": ("stall", float, 0.01, 600, 1.0), "timeout": ("leg timeout", float, 0.01, 3600, 10.0)}
        kw = {k: (default if msg.get(k) in (None, "") else number(msg, k, kind, lo, hi, what))
              for k, (what, kind, lo, hi, default) in opt.items()}
        speed = None if msg.get("speed") in (None, "") else number(msg, "speed", int, 1, self.reg("goal-speed").hi,
                                                                   "speed")
        limit = None if msg.get("limit") in (None, "") else number(msg, "limit", float, 1, self._current_hi(), "limit")
        runner = Cycler(self.bus, ident, a, b, speed=speed, limit=limit, cancel=_CancelFlag(self), **kw)
        self.cycles = []
        self.broadcast({"type": "cycles", "items": [], "reset": True, "id": ident, "between": [a, b]})
        self.log(f"{ctx.label} cycles ID {ident} between {a} and {b}, {kw['cycles']} cycles")
        started = time.monotonic()
        self._progress("cycle", 0, kw["cycles"], "starting")
        for rec in runner.run():
            self.cycles.append(rec)
            del self.cycles[:-CYCLES_KEPT]
            self.broadcast({"type": "cycles", "items": [rec]})
            self._progress_quiet("cycle", rec["cycle"], kw["cycles"], f"cycle {rec['cycle']} of {kw['cycles']}")
        limit_hz = runner.wire_limit()
        n = runner.done
        summary = {"id": ident, "cycles": n, "seconds": round(time.monotonic() - started, 2),
                   "polls_per_s": round(runner.achieved, 1), "wire_limit": round(limit_hz, 1),
                   "ratio": round(runner.achieved / limit_hz, 3) if limit_hz else None,
                   "reason": runner.reason, "why": runner.why, "held": runner.held}
        text = (f"cycle ID {ident}: {n} cycles in {summary['seconds']:g} s; {summary['polls_per_s']:g} polls/s "
                f"({summary['ratio']:.2f}x the wire limit of {limit_hz:.1f}/s)")
        if runner.reason not in ("done", None):
            text += f"; stopped: {runner.why}" + (f"; held at {runner.held}" if runner.held is not None else "")
        self.log(text, "info" if runner.reason == "done" else "warn")
        self.broadcast({"type": "cycled", **summary})
        self.reply(ctx, **summary)

    def _current_hi(self) -> int:
        """The highest current limit a play or cycle takes: goal-current's in the bus's map."""
        return self.reg("goal-current").hi

    def _progress_quiet(self, job, done, total, text):
        """Progress that never raises for a Cancel (the Cycler stops itself, safely)."""
        cancel, self._cancel = self._cancel, False
        try:
            self._progress(job, done, total, text)
        finally:
            self._cancel = cancel


def _path_text(rows, fmt="csv") -> str:
    from ..api.motion import write_path

    out = io.StringIO()
    write_path(out, rows, fmt=fmt)
    return out.getvalue()


def _ms(v) -> str:
    return "–" if v is None else f"{v:.2f} ms"
