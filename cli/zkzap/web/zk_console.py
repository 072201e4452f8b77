"""The ZK console: an ECU's status stream to every page, and engine control for the page that
controls, as ``zk monitor`` and ``zk send control --for`` do it.

The worker runs the console's :class:`~zkzap.api.stand.StandSession` (the stand's hooks, its
alarm list and the records' sink, as every front end runs it) over the
:class:`~zkzap.api.zk.Ecu`'s source and telemetry, one session after the other: a monitoring session (sends nothing) while nobody runs the
engine, a control session (the live command at ``rate`` Hz) from a start until the engine
command ends. A control session ends like every command's session: on a stop (it sends stop,
throttle 0), on the abort (standby, throttle 0, out of RPM mode, pump off), and also when the
controlling page closes or falls silent for a second (the dead-man rule: standby), on a new ECU
error, a silent ECU, a violated limit (``--on-limit abort``) or when the console shuts down.

Interlocks, as on the command line: a start needs the ENGINE permission on a real port (the
page's consent, given to the ECU's link for that control session; the link refuses every frame
without it, :mod:`.consent`); it is refused while
the ECU is silent or a limit is violated now, and by the stand's alarm list
(:class:`~zkzap.api.alarms.Alarms`): while an alarm is latched (a trip, an abort, the dead-man
rule), until the engine is at rest and cool after a trip, and at any setpoint but 0 for the
first start after one; RPM mode needs protocol version 4 or later and a
target within the max rpm the ECU reports (status ID 6).
"""

from __future__ import annotations

import time
from collections import deque

from ..api.prestart import EcuLimits, Plan
from ..api.schedule import RPM_MAX, rpm_factor_for
from ..api.session import DEFAULT_SILENCE_S, describe_abort
from ..codec import zk
from ..errors import UsageError
from .console import Console, number
from .server import DEADMAN_S

#: Seconds of status records a page that connects gets for its plots.
HISTORY_S = 60.0
#: Status records kept for that (100 Hz x 60 s).
HISTORY_MAX = 6000
#: A page that connects gets at most one record per status ID this often (seconds).
HISTORY_STEP_S = 0.25
#: How often health and limits go to the pages (real seconds).
HEALTH_S = 0.25
#: Keys of a status record that stay on the server.
UNSENT = ("time", "frame", "kind")


class LiveCommand:
    """The command a control session repeats: state run (or another), by throttle or by RPM
    target (a multiple of 10 x ``factor``); the frames it cycles through (one or two)."""

    def __init__(self, mode="throttle", throttle=0.0, rpm=None, factor=1, rpm_used=False, state="run"):
        self.mode = mode
        self.throttle = throttle
        self.rpm = rpm
        self.factor = factor
        self.rpm_used = rpm_used or mode == "rpm"
        self.state = state
        if mode == "rpm":
            self.frames = (zk.encode_control("mode", sw=state, rpm_factor=factor)[0],
                           zk.encode_control("rpm", target_rpm=self.rpm, rpm_factor=factor)[0])
        else:
            id1 = zk.encode_control("control", sw=state, throttle_pct=throttle)[0]
            # after RPM mode, ID 6 with state none hands the state back to ID 1 (ID 6 would override it)
            self.frames = (id1, zk.encode_control("mode", sw="none", rpm_factor=0)[0]) if self.rpm_used else (id1,)
        self._i = 0

    def frame_at(self, t):
        frames = self.frames
        self._i = (self._i + 1) % len(frames)
        return frames[self._i]

    def describe(self) -> dict:
        return {"mode": self.mode, "state": self.state, "throttle": self.throttle, "rpm": self.rpm,
                "rpm_factor": self.factor if self.mode == "rpm" else None}


class _Cuttable:
    """A session's source that a request can end: :meth:`poll` returns None (the end) once cut."""

    def __init__(self, source):
        self._src = source
        self.cut = False

    def poll(self):
        if self.cut:
            return None
        return self._src.poll()

    def __getattr__(self, name):
        return getattr(self._src, name)


class ZkConsole(Console):
    """The console over ``ecu`` (an open :class:`~zkzap.api.zk.Ecu`). ``session``: the
    :class:`~zkzap.api.stand.StandSession` it runs (the stand's hooks and alarm list, made by the
    front end from its options, with its records' output when it has one:
    :meth:`~zkzap.api.stand.StandSession.record`); without one, ``conditions`` and ``on_limit``
    (``abort`` or ``warn``) are the limits and ``alarms`` the alarm list's settings.
    ``record``: where the records go when the session has no output yet (a writer of
    :mod:`zkzap.io`, given to the session's :meth:`~zkzap.api.stand.StandSession.record`,
    closed with the console); ``rate`` the control rate (Hz);
    ``silence`` the longest an ECU may be silent while controlled."""

    kind = "zk"
    watch_ops = frozenset({"abort"})

    def __init__(self, ecu, *, session=None, conditions=(), on_limit="abort", rate=20.0, silence=DEFAULT_SILENCE_S,
                 alarms=None, record=None, command="zkzap web zk"):
        from ..api.alarms import Alarms
        from ..api.limits import LimitSet
        from ..api.stand import Stand, StandSession
        from ..link.zk_port import is_simulator

        super().__init__(ecu.url, simulated=is_simulator(ecu.url))

        self.ecu = ecu
        self.tel = ecu.telemetry
        self.rate = rate
        self.silence = silence
        self.abort_kind = ecu.abort_kind
        if session is None:
            limits = LimitSet(conditions, on_limit) if conditions else None
            stand = Stand(limits) if limits is not None else None
            if stand is not None:
                stand.alarm_settings = dict(alarms or {})
            session = StandSession(stand, alarms=Alarms(**(alarms if stand is None and alarms else {})))
        #: The stand session (:class:`~zkzap.api.stand.StandSession`: the test-stand hooks —
        #: limits, external sensors, corrected values, the ESR answer, the logbook's figures —
        #: and the alarm list) and where the records go (``record.write(rec)``, closed with the
        #: console): as on the command line.
        self.stand_session = session
        self.stand = session.stand
        if record is not None:
            # the one sink of the records: the stand session's (written off the worker, and a full
            # queue ends the console safely — its run with the abort — never the worker blocked)
            session.record(record, f"--output {getattr(record, 'path', '')}", wait=False)
        self.record = session.output
        self.command_name = command
        self.limits = session.limits
        if self.limits is not None:
            self.limits.notify = lambda m: self.log(m, "warn")
        # every frame: limits, sensors, ESR answers; the records into the stand session's one
        # sink (its output), each then handed to the pages
        session.attach(ecu.source, self.tel, watch=self._seen)
        #: The stand's alarm list and start interlock, shared by every session of the console;
        #: the console says and shows what it raises.
        self.alarms = session.alarms
        self.alarms.tell_limits = True
        self.alarms.notify = lambda m: self.log(m, "error")
        self.alarms.on_change = self._alarms_changed
        self._cut_as = None           # how a request ended the control session: abort, dead-man
        self._esr_said = False        # the ECU's unanswered request for the air pressure was said
        self.history = deque(maxlen=HISTORY_MAX)
        self.command = None           # the LiveCommand of the running control session
        self.controller = None        # who started it
        self.since = None
        self._session = None
        self._source = None
        self._next = None             # ("control", LiveCommand, label, allow) to run after the session ends
        self._oneshot = None          # ("abort"|"stop", label): frames to send between sessions
        self._last_frame = None       # real time of the last status frame
        self._last_t = None           # its time on the source's clock
        self._last_health = 0.0
        self.ended = None             # how the last control session ended (for the pages)

    # -- the worker -----------------------------------------------------------------------------

    def run(self):
        while not self.closing_now:
            self.handle_requests()
            if self._oneshot is not None:
                kind, label = self._oneshot
                self._oneshot = None
                self._send_once(kind, label)
            nxt, self._next = self._next, None
            if nxt is not None and not self.closing_now:
                self._control(nxt[1], nxt[2], nxt[3])
            else:
                self._monitor()

    def _session_for(self, control=None, **kw):
        self._source = _Cuttable(self.ecu.source)
        kw.setdefault("limits", None)       # a monitoring session ends on no limit
        s = self.stand_session.make_session(source=self._source, control=control, rate=self.rate,
                                            abort=self.abort_kind, on_update=self._update, notify=self._note,
                                            update_interval=0.02, restart=False, **kw)
        s._esr_said = self._esr_said       # said once for the console, not once a session
        # the source goes on from session to session: a session's silence counts from the last
        # frame any of them saw, not from the source's start
        s.last_frame_t = self._last_t
        self._session = s
        return s

    def _monitor(self):
        s = self._session_for(silence=None, rundown=None)
        outcome = s.run()
        self._session = None
        if outcome.reason not in ("end", "duration", "count"):
            outcome.raise_for_status()

    def _control(self, command, label, allow):
        link = self.ecu.link
        saved = link.allow
        link.allow = saved | allow              # what the page granted, for this control session
        try:
            self._control_session(command, label)
        finally:
            link.allow = saved

    def _control_session(self, command, label):
        self.tel.new_error = None               # an error before the start is not a new one
        self.command, self.controller, self.since = command, label, time.time()
        self.ended = None
        self._cut_as = None
        # the rundown after a trip is recorded by the monitoring session that follows (a page may
        # be told why a start is refused meanwhile, and watch the engine run down)
        s = self._session_for(control=lambda t: self.command.frame_at(t), silence=self.silence,
                              stop_on_error=True, limits=self.limits, end=self.abort_kind,
                              end_label="end of control", rundown=None)
        self._engine_message()
        self.log(f"{label} starts the engine: {self._describe(command)}")
        outcome = s.run()
        self._session = None
        self.command = None
        sent = outcome.aborted
        if outcome.ok:
            why = s.end_label
        else:
            why = str(outcome.error) if outcome.error is not None else outcome.reason
        self.ended = {"t": round(time.time(), 3), "reason": outcome.reason, "why": why,
                      "sent": describe_abort(sent) if sent and sent not in ("hold", "failed") else sent}
        if outcome.ok and self._cut_as is not None:      # an abort or the dead-man rule: a trip too
            self.stand_session.mark_trip(self._cut_as, why, sent if sent not in ("hold", "failed") else None,
                                         t=s.ended_t)
        self._engine_message()
        if not outcome.ok:
            self.log(f"engine control ended: {why}", "error")
            if outcome.reason in ("port", "output", "error"):
                outcome.raise_for_status()

    def _cut(self, end=None, label=None, trip=None):
        """End the running session (on the worker); a control session sends ``end`` (stop,
        standby) as it ends; ``trip`` (abort, dead-man) latches an alarm for it."""
        s = self._session
        if s is None:
            return False
        if end is not None and s.control is not None:
            s.end = end
            s.end_label = label or s.end_label
            if trip is not None:
                self._cut_as = trip
        self._source.cut = True
        return True

    def _send_once(self, kind, label):
        """Send the abort (standby) or stop frames while no session runs (nobody controls)."""
        from ..api.session import abort_frames

        frames = abort_frames(kind, self.tel.decoder.known)
        for f in frames:
            self.ecu.link.write(f)
        time.sleep(0.02)
        self.ecu.link.write(frames[0])
        self.log(f"{label}: sent {describe_abort(kind)}", "warn" if kind == self.abort_kind else "info")

    def closing(self):
        with self._wake:
            self._wake.notify_all()
        # the worker takes it from here: _update sees closing_now and ends the session

    def shutdown(self):
        src = self.ecu.source
        ended = src.now()
        try:
            self.ecu.close()
        finally:
            self.stand_session.close_output()
            self.stand_session.close()
            if self.stand is not None:
                self._log_run(ended)

    def _log_run(self, ended):
        """The console's whole time as one run of the logbook (``--logbook``)."""
        from ..api.session import Outcome

        f = self.failure
        outcome = Outcome("end") if f is None else Outcome(getattr(f, "reason", None) or "port", f)

        files = (getattr(self.record, "path", None),)
        run_id = self.stand_session.log_run(command=self.command_name, port=self.url, files=files, outcome=outcome,
                                            ended_t=ended)
        if run_id is not None:
            self.log(f"logbook {self.stand.logbook}: run {run_id} recorded")

    # -- session hooks (on the worker) ----------------------------------------------------------

    def _seen(self, rec):
        """A record the stand session wrote (or queued): to the pages' plots."""
        if rec.get("kind") in ("trip", "rundown", "gap"):
            return                            # a session's event: the file's only
        now = time.time()
        self._last_frame = now
        self._last_t = rec["t"]
        item = {k: v for k, v in rec.items() if k not in UNSENT}
        item["w"] = round(now * 1000, 1)
        self.history.append(item)
        if self.hub is not None:
            self.hub.sample(item)

    def _note(self, message):
        if message.startswith("the ECU asks for the air pressure"):
            self._esr_said = True
        level = "warn" if ("sent" in message or "error" in message or "limit" in message) else "info"
        self.log(message, level)

    def _update(self, snapshot, health):
        if self.closing_now:
            self._cut(self.abort_kind, "the console is shutting down", trip="abort")
            return
        self.handle_requests()
        now = time.time()
        if now - self._last_health >= HEALTH_S:
            self._last_health = now
            self.broadcast(self._health(health))

    def _health(self, health=None) -> dict:
        h = dict(health or {})
        h.pop("stale_ids", None)
        silent = None if self._last_frame is None else round(time.time() - self._last_frame, 3)
        msg = {"type": "health", **h, "silent_s": silent, "stale_ids": self.tel.stale_ids(self.ecu.source.now()),
               "version_note": self.tel.version_note}
        if self.limits is not None:
            msg["limits"] = self.limits.summary()
        msg["interlock"] = self.stand_session.refusal() if self.command is None else None
        return msg

    def _alarms(self) -> dict:
        a = self.alarms
        return {"type": "alarms", "items": a.to_list(), "latched": len(a.latched), "zero_setpoint": a.zero_setpoint,
                "restart_egt_c": a.restart_egt_c}

    def _alarms_changed(self):
        self.broadcast(self._alarms())

    def _engine_message(self):
        self.broadcast(self._engine())

    def _engine(self) -> dict:
        cmd = self.command
        return {"type": "engine", "controlling": cmd is not None, "by": self.controller if cmd else None,
                "since": self.since if cmd else None, "command": cmd.describe() if cmd else None,
                "ended": self.ended}

    @staticmethod
    def _describe(cmd) -> str:
        if cmd.mode == "rpm":
            return f"state {cmd.state}, RPM mode, target {cmd.rpm:,} rpm (RPM_X {cmd.factor})"
        return f"state {cmd.state}, throttle {cmd.throttle:g} %"

    # -- for the pages --------------------------------------------------------------------------

    def hello(self) -> dict:
        out = super().hello()
        out.update({
            "rate": self.rate, "abort": self.abort_kind, "abort_text": describe_abort(self.abort_kind),
            "deadman_s": DEADMAN_S, "silence_s": self.silence, "rpm_max": RPM_MAX,
            "limits": [{"text": c.text, "field": c.field, "op": c.op, "threshold": c.threshold, "warn": c.warn,
                        "rate": getattr(c, "rate", False), "when": getattr(c, "when_text", None)}
                       for c in (self.limits.conditions if self.limits else ())],
            "on_limit": self.limits.on_limit if self.limits else None,
            "states": zk.ENGINE_STATES, "errors": zk.ERRORS,
            "alarms": {"restart_egt_c": self.alarms.restart_egt_c, "hung_start_s": self.alarms.hung_start_s,
                       "hot_start_egt_c": self.alarms.hot_start_egt_c},
        })
        return out

    def snapshot(self) -> list:
        return super().snapshot() + [self._engine(), {"type": "history", "items": self._history()}, self._health(),
                                     self._alarms()]

    def _history(self) -> list:
        """The last :data:`HISTORY_S` of records for a page's plots, at most one per status ID
        every :data:`HISTORY_STEP_S` (a plot shows no more; a page that connects has little to
        take in)."""
        cutoff = time.time() * 1000 - HISTORY_S * 1000
        last = {}
        out = []
        for r in list(self.history):
            w = r["w"]
            if w < cutoff or w - last.get(r["id"], -1e18) < HISTORY_STEP_S * 1000:
                continue
            last[r["id"]] = w
            out.append(r)
        return out

    def deadman(self):
        return self.command is not None

    def control_lost(self, label, reason):
        super().control_lost(label, reason)
        self.request(None, label, {"op": "_lost", "reason": reason})

    # -- requests (on the worker) ---------------------------------------------------------------

    def _ready(self):
        """Refuse a start while the ECU is silent."""
        if self._last_frame is None:
            raise UsageError("start: no status frame from the ECU yet; check the port, baud rate and wiring")
        silent = time.time() - self._last_frame
        if silent > self.silence:
            raise UsageError(f"start: the ECU is silent (no status frame for {silent:.1f} s)")

    def _command_from(self, msg, rpm_used=False) -> LiveCommand:
        mode = msg.get("mode", "throttle")
        if mode == "throttle":
            pct = number(msg, "throttle", float, 0, 100, "throttle")
            return LiveCommand("throttle", throttle=round(pct, 1), rpm_used=rpm_used)
        if mode != "rpm":
            raise ValueError(f"mode: {mode!r}; allowed throttle, rpm")
        target = number(msg, "rpm", float, 0, RPM_MAX, "rpm")
        latest = self.tel.latest
        max_rpm = latest.get("max_rpm")
        version = self.tel.decoder.known
        if max_rpm is None:
            raise UsageError("rpm: the ECU's max rpm is not known yet (status ID 6); wait for it")
        Plan([zk.encode_control("mode", sw="none", rpm_factor=1)[0]], targets=[(target, "rpm")],
             what="rpm target").check(EcuLimits.reported(max_rpm, version))
        factor = rpm_factor_for(max_rpm)
        step = 10 * factor
        value = round(target / step) * step
        if value > max_rpm:
            value -= step
        return LiveCommand("rpm", rpm=value, factor=factor)

    def op_start(self, ctx, msg):
        if self.command is not None:
            raise UsageError("start: the engine is already running under this console; change the throttle "
                             "or target instead")
        cmd = self._command_from(msg)
        self._ready()
        self.stand_session.check_start(cmd.throttle if cmd.mode == "throttle" else cmd.rpm)
        self.policy.zk_frames(cmd.frames, ctx.granted)      # refused before the session starts
        self._next = ("control", cmd, ctx.label, self.policy.allow(ctx.granted))
        self._cut()
        self.reply(ctx, command=cmd.describe())

    def op_set(self, ctx, msg):
        """A new throttle or RPM target for the running engine (no new consent: same start)."""
        if self.command is None:
            raise UsageError("the engine is not running under this console; start it first")
        cmd = self._command_from(msg, rpm_used=self.command.rpm_used)
        for f in cmd.frames:
            self.ecu.link.authorize(f)          # with the session's permissions, before it goes out
        was = self.command
        self.command = cmd
        if (cmd.mode, cmd.throttle, cmd.rpm) != (was.mode, was.throttle, was.rpm):
            self._engine_message()
            if cmd.mode != was.mode:
                self.log(f"{ctx.label}: {self._describe(cmd)}")
        self.reply(ctx, command=cmd.describe())

    def op_stop(self, ctx, msg):
        self._end_or_send("stop", f"stop from {ctx.label}")
        self.reply(ctx)

    def op_abort(self, ctx, msg):
        self._end_or_send(self.abort_kind, f"abort from {ctx.label}", trip="abort")
        self.reply(ctx)

    def op_ack(self, ctx, msg):
        """The controlling operator acknowledges the latched alarms (``ids``: only these)."""
        ids = msg.get("ids")
        if ids is not None and (not isinstance(ids, list) or not all(isinstance(i, int) for i in ids)):
            raise ValueError("ids: a list of alarm numbers")
        done = self.alarms.acknowledge(ctx.label, ids)
        self.reply(ctx, acknowledged=[a.id for a in done])

    def _end_or_send(self, kind, label, trip=None):
        """End the control session with ``kind`` (stop, standby), or, while nobody runs the engine
        from here, send it once."""
        if self.command is not None:
            self._cut(kind, label, trip)
        else:
            self._oneshot = (kind, label)
            self._cut()

    def failsafe(self, reason):
        super().failsafe(reason)
        self.request(None, "the console", {"op": "_failsafe", "reason": reason})

    def op__failsafe(self, ctx, msg):
        if self.command is not None:
            self._cut(self.abort_kind, f"failsafe: {msg.get('reason')}")

    def op__lost(self, ctx, msg):
        if self.command is not None:
            self._cut(self.abort_kind, f"dead-man: {ctx.label} lost control ({msg.get('reason')})", trip="dead-man")
