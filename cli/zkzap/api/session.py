"""The ZK session loop: :class:`Session` reads a source's status frames, decodes them
(:class:`~zkzap.api.telemetry.Telemetry`), hands the records over, sends the current control
frame every ``1/rate`` s, stops on count/duration/end, Ctrl-C (SIGINT), SIGTERM, a port failure,
a silent ECU, a new ECU error or a violated limit, and sends the abort command on the way out
when it was controlling the engine. :class:`Outcome` says how it ended, with its exit status.

Sources are :class:`zkzap.link.zk_sources.LiveSource` and
:class:`zkzap.link.zk_sources.ReplaySource`. Nothing here imports click, rich or pyserial.
"""

from __future__ import annotations

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Optional

from ..codec import zk
from ..codec.ids import id_ranges
from ..errors import DeviceError, NoReply, OutputError, PortError, UsageError
from ..errors import TERMINATED
from ..signals import INTERRUPT_SIGNALS, SignalGuard, name, status
from .alarms import StartRefused
from .prestart import EcuLimitError, listen, silence_error
from .telemetry import describe_error

#: Control frames per second while a session controls the engine (``--rate``).
DEFAULT_RATE = 20.0
#: Longest silence tolerated from the ECU, at the start and while running (``--timeout``).
DEFAULT_SILENCE_S = 2.0
#: Whole status cycles seen before ``--ids`` the ECU never sends are reported.
ID_CHECK_LAPS = 3
#: Abort commands (``--abort``): the control state sent with throttle 0 on an abnormal end.
ABORTS = zk.ABORTS
DEFAULT_ABORT = zk.DEFAULT_ABORT


def controls_engine(frame) -> bool:
    """True when sending ``frame`` controls the engine (see :attr:`zk.ControlFrame.controls_engine`)."""
    return zk.ControlFrame(frame).controls_engine


def abort_frames(kind: str, version=None, pump=False) -> list:
    """The frames of the abort command ``kind`` (``standby``, ``stop`` or ``none``).

    ``standby``/``stop``: control ID 1 with that state and throttle 0; for an ECU of protocol
    version 4 or later (or of unknown version) also ID 6 with state none and RPM factor 0 (leaves
    RPM mode and hands the state back to ID 1, whose SW an ID 6 state would override), then ID 1
    again. With ``pump`` (a pump-on was sent) also the pump-off action.
    """
    if kind not in ABORTS:
        raise UsageError(f"abort: {kind!r}; allowed {', '.join(ABORTS)}")
    if kind == "none":
        return []
    id1 = zk.encode_control("control", sw=kind, throttle_pct=0)[0]
    frames = [id1]
    if version is None or version >= 4:
        frames += [zk.encode_control("mode", sw="none", rpm_factor=0)[0], id1]
    if pump:
        frames.append(zk.encode_control("action", param="pump-off")[0])
    return frames


def describe_abort(kind: str) -> str:
    """The abort command ``kind`` in words: ``standby, throttle 0``."""
    return "nothing (--abort none)" if kind == "none" else f"{kind}, throttle 0"


#: What a session that controls the engine sends when it ends normally (``--end``): ``hold``
#: sends nothing more and leaves the engine at the last command.
ENDS = ("standby", "stop", "hold")
DEFAULT_END = "standby"

#: After an abnormal end that sent the abort (a violated limit, an ECU error, Ctrl-C, a dead-man
#: standby) the session goes on recording the rundown for at most this long (session seconds,
#: ``--rundown``): until the ECU reports stop or standby with the rotor below
#: :data:`RUNDOWN_RPM` (the cool-down over). A second Ctrl-C ends it at once.
DEFAULT_RUNDOWN_S = 120.0
#: The rotor speed below which a stopped or standing-by engine counts as run down (rpm).
RUNDOWN_RPM = 500
#: The ends after which the rundown is recorded (an end the session was asked for, its time or
#: a schedule's end, is no trip; SIGTERM asks the process to go; the port or output failing
#: leaves nothing to record with).
RUNDOWN_AFTER = ("interrupted", "limit", "ecu-error", "alarm")
#: Engine states in which the engine has come to rest (with the rotor stopped).
REST_STATES = (0, 1)   # stop, standby (zk.ENGINE_STATES)


def at_rest(latest) -> bool:
    """True when the ECU reports stop or standby and the rotor is below :data:`RUNDOWN_RPM`
    (``latest``: a telemetry's latest values)."""
    return latest.get("engine_state") in REST_STATES and (latest.get("rpm") or 0) <= RUNDOWN_RPM


class Outcome:
    """How a session ended. ``reason``: ``count``, ``duration``, ``end`` (replay or schedule
    done), ``interrupted``, ``terminated``, ``port``, ``silence`` (no status frame within the
    timeout, or none at all in a session that ended by its time), ``ecu-error``, ``limit``,
    ``alarm`` (a hung or hot start, :mod:`zkzap.api.alarms`),
    ``pipe``, ``output`` (an output file could not be written), ``refused`` (the ECU's reported
    limits refuse the plan: nothing was sent). ``rundown``: after a trip, how the recording of
    the rundown went (``{"s": seconds, "ended": "rest"|"max"|"cut"|"silence"|"end"|"port"}``)."""

    def __init__(self, reason: str, error: Optional[BaseException] = None, aborted: Optional[str] = None) -> None:
        self.reason = reason
        self.error = error
        self.aborted = aborted   # the abort kind sent, or None
        self.rundown = None
        self.signum = None       # ``terminated``: the signal (SIGTERM, SIGHUP, ...)

    @property
    def ok(self) -> bool:
        """True for a normal end: ``count``, ``duration`` or ``end``."""
        return self.reason in ("count", "duration", "end")

    @property
    def exit_code(self) -> int:
        """The exit status that goes with this outcome."""
        from ..errors import INTERRUPTED

        if self.ok or self.reason == "pipe":
            return 0
        if self.reason == "interrupted":
            return INTERRUPTED
        if self.reason == "terminated":
            return status(self.signum) if self.signum is not None else TERMINATED
        return getattr(self.error, "code", 1)

    def raise_for_status(self) -> None:
        """Raise the exception (exit status) that goes with this outcome, if any."""
        r = self.reason
        if r == "interrupted":
            raise KeyboardInterrupt
        if r == "terminated":
            from ..signals import Terminated

            raise Terminated(self.signum) if self.signum is not None else Terminated()
        if r == "pipe":
            raise BrokenPipeError
        if self.error is not None:
            raise self.error


def trip_record(outcome, t, clock, why=None) -> dict:
    """The record that marks a trip in a session's records: ``kind`` ``trip``, ``trip`` (what
    tripped and what was sent, in words), ``reason`` (the outcome's), ``sent``; for a violated
    limit also ``limit``, ``field``, ``value`` and the violation's ``t``. ``why``: the words
    when the outcome has no error (an abort from a console, the dead-man rule)."""
    sent = describe_abort(outcome.aborted) if outcome.aborted in ABORTS else outcome.aborted
    err = outcome.error
    what = str(err) if err is not None else (why or _WHY.get(outcome.reason, outcome.reason))
    rec = {"time": clock.iso(t), "t": round(t, 3), "kind": "trip", "trip": f"{what}; sent {sent}" if sent else what,
           "reason": outcome.reason, "sent": sent}
    cond = getattr(err, "condition", None)
    if cond is not None:
        at = getattr(err, "t", None)
        rec.update(limit=cond.text, field=cond.field, value=getattr(err, "value", None),
                   t=round(at, 3) if at is not None else rec["t"])
    return rec


class Session:
    """Run a source through telemetry into ``sink`` while sending control frames.

    ``control(t)`` returns the frame to send at time ``t`` (None: nothing); it is called every
    ``1/rate`` s. Ends on ``count`` records, ``duration`` seconds, the end of a replay, a signal,
    a port failure, ``silence`` seconds without a status frame, or (``stop_on_error``) a new ECU
    error. A live session that received no status frame at all ends as ``silence`` (exit 3)
    whatever its length. On an abnormal end — or at the end when ``abort_at_end`` — the abort
    command is sent if the frames sent controlled the engine (see :func:`controls_engine`);
    a session that leaves the engine running (``--abort none``, ``--end hold``) says so through
    ``notify``.

    ``plan`` (:class:`~zkzap.api.prestart.Plan`): the frames ``control`` can send. When they
    need the ECU's limits, the session first listens for its status ID 6 and refuses the plan
    (``refused``, exit 2) before the first frame goes out; the session's time 0 is then the end
    of that listening (the frames heard meanwhile only set the protocol version).

    Every time is the source's clock (session seconds: model time on a sped-up simulator), which
    the session restarts at its start unless ``restart`` is False (the sessions of a console, one
    after the other on one clock: their records' ``t`` and the status rate's window go on).
    """

    def __init__(self, source, telemetry, sink, *, control=None, rate=DEFAULT_RATE, abort=DEFAULT_ABORT,
                 count=None, duration=None, silence=DEFAULT_SILENCE_S, stop_on_error=False,
                 abort_at_end=False, on_update=None, notify=None, update_interval=0.1, limits=None, end=None,
                 end_label="end of schedule", plan=None, rundown=DEFAULT_RUNDOWN_S, alarms=None, restart=True,
                 answers_esr=False):
        self.source = source
        self.telemetry = telemetry
        self.alarms = alarms     # an api.alarms.Alarms: the stand's alarm list and start interlock
        self.restart = restart   # False: the source's clock goes on (one of a console's sessions)
        self.answers_esr = answers_esr   # something answers the ECU's ESR request (an air pressure)
        self._esr_said = False
        self.sink = sink
        self.control = control
        self.period = 1.0 / rate
        self.abort = abort
        self.count = count
        self.duration = duration
        self.silence = silence
        self.stop_on_error = stop_on_error
        self.abort_at_end = abort_at_end
        self.end = end                  # sent at a normal end (ENDS); None: the abort if abort_at_end
        self.end_label = end_label
        self.on_update = on_update
        self.notify = notify or (lambda message: None)
        self.update_interval = update_interval
        self.limits = limits     # an api.limits.LimitSet: its first violation ends the session
        self.plan = plan         # an api.prestart.Plan: checked against the ECU before sending
        self.rundown = rundown   # longest rundown recorded after a trip (None or 0: none)
        self.ecu_limits = None   # what the ECU reported (api.prestart.EcuLimits), once listened
        self.sent = 0
        self.last_sent = None
        self.ended_t = None
        self.written = 0
        self.controlling = False
        self.pump_on = False
        self.rpm_factor = None           # the RPM_X of the last ID 6 sent
        self.last_frame_t = None
        # the status IDs seen, until the ECU's cycle is known (an ID comes again): then --ids
        # that the ECU never sends are reported (all of them: the session ends)
        self._cycle = set() if telemetry.ids is not None else None
        self._back_t = 0.0
        self._started = False             # a state-run frame went out (the interlock passed)
        self.interrupted = None           # PortError text when a reconnect cut engine control
        self.abort_error = None           # the PortError that kept the abort from going out
        #: Once the abort went out: its frames, the only ones :meth:`_send` still sends.
        self.sealed: Optional[frozenset] = None

    def _check_ids(self, sid):
        cycle = self._cycle
        if not cycle:
            self._first, self._laps = sid, 0
        cycle.add(sid)
        if sid == self._first:
            self._laps += 1
        if self._laps <= ID_CHECK_LAPS:     # whole cycles, so a lost frame is not a missing ID
            return None
        self._cycle = None
        wanted = self.telemetry.ids
        never = sorted(wanted - cycle)
        if not never:
            return None
        sends = id_ranges(cycle)
        if len(never) == len(wanted):
            return Outcome("silence", NoReply(
                f"ids: the ECU never sends status ID{'s' if len(never) > 1 else ''} {id_ranges(never)} "
                f"(its cycle is IDs {sends}); nothing to log"))
        self.notify(f"ids: the ECU never sends status ID{'s' if len(never) > 1 else ''} {id_ranges(never)} "
                    f"(its cycle is IDs {sends})")
        return None

    def _reconnected(self, gap):
        """The port is back after a drop-out: abort first (a session that controlled the engine
        stops controlling it), then a gap record, then logging goes on."""
        down, up, reason = gap
        self._back_t = up
        if self.controlling and self.abort != "none":
            frames = abort_frames(self.abort, self.telemetry.decoder.known, pump=self.pump_on)
            self.sealed = frozenset(frames)
            for f in frames:
                self.source.write(f)
            self.notify(f"port back after {up - down:.1f} s: sent {describe_abort(self.abort)}; "
                        "no longer controlling the engine")
            self.control = None
            self.interrupted = (f"{reason}; the port came back after {up - down:.1f} s and the abort "
                                f"({describe_abort(self.abort)}) was sent")
        elif self.controlling:
            self.notify(f"port back after {up - down:.1f} s (--abort none: nothing sent); "
                        "no longer controlling the engine")
            self.control = None
            self.interrupted = f"{reason}; the port came back after {up - down:.1f} s"
        else:
            self.notify(f"port back after {up - down:.1f} s ({reason})")
        rec = {"time": self.source.clock.iso(up), "t": round(up, 3), "kind": "gap",
               "gap_s": round(up - down, 3), "since_t": round(down, 3), "reason": reason}
        self.sink(rec)

    def _send(self, frame):
        if self.sealed is not None and frame not in self.sealed:
            return                            # after the abort nothing but the abort leaves the port
        if self.alarms is not None and not self._started and frame[1] >> 4 in (1, 6):
            c = zk.ControlFrame(frame)
            if c.sw == 3:                     # state run: a start (refused: nothing sent)
                self.alarms.check_start(setpoint=(((frame[1] & 3) << 8) | frame[2]) / 10 if c.id == 1 else None)
                self._started = True
                self.alarms.started()
        self.source.write(frame)
        self.sent += 1
        self.last_sent = frame
        if not self.controlling and controls_engine(frame):
            self.controlling = True
        if frame[1] >> 4 == 6:
            self.rpm_factor = zk.ControlFrame(frame).rpm_factor
        if frame[1] >> 4 == 2:
            action = zk.ACTIONS.get(frame[2])
            if action == "pump-on":
                self.pump_on = True
            elif action == "pump-off":
                self.pump_on = False

    def _prestart(self):
        """Listen for the ECU's limits and check the plan against them (EcuLimitError), then
        start the session's clock."""
        src, tel = self.source, self.telemetry
        self.ecu_limits = limits = listen(src, self.silence, given=tel.decoder.given)
        if limits.frame is not None:
            tel.seed(limits.frame)
        self.plan.check(limits)
        if self.restart:
            src.restart()

    def run(self) -> Outcome:
        """Run until an end (see the class); returns the :class:`Outcome` (the abort, if sent,
        is in ``aborted``). ``written`` counts the records handed to the sink."""
        src, tel = self.source, self.telemetry
        written = 0
        next_send = 0.0
        next_update = 0.0
        outcome = None
        told = False
        first_poll = None
        if self.limits is not None:
            self.limits.tripped = None      # a violation seen before this session is not this one's
        if self.control is not None:
            src.pace(self.period)           # reads never hold a control frame up
        hooked = tel.on_frame
        if self.alarms is not None:
            tel.on_frame = self._observing(hooked)
        try:
            return self._run(src, tel, written, next_send, next_update, outcome, told, first_poll)
        finally:
            tel.on_frame = hooked

    def _observing(self, hooked):
        """The telemetry's frame hook with the alarms' watch added: every decoded status frame
        (those ``--ids`` writes no record for too: the start watches need ID 1's state and EGT
        whatever is recorded) with the limits' entries the stand's hooks gave it."""
        observe = self.alarms.observe

        def on_frame(t, rec):
            extra = hooked(t, rec) if hooked is not None else None
            observe(t, dict(rec, **extra) if extra else rec)
            return extra

        return on_frame

    def _run(self, src, tel, written, next_send, next_update, outcome, told, first_poll):
        with SignalGuard() as guard:
            try:
                if self.plan is not None and self.plan.needs_ecu and src.live:
                    try:
                        self._prestart()
                    except EcuLimitError as e:
                        outcome = Outcome("refused", e)
                    except NoReply as e:
                        outcome = Outcome("silence", e)
                    if guard.signum is not None and outcome is None:
                        outcome = _signalled(guard.signum)
                elif src.live and self.restart:
                    src.restart()               # the session's time 0: now, not when the port opened
                while outcome is None:
                    if guard.signum is not None:
                        outcome = _signalled(guard.signum)
                        break
                    now = src.now()
                    if self.duration is not None and now >= self.duration:
                        if self.control is not None:     # the command in force at the end (a
                            frame = self.control(self.duration)   # schedule's last row)
                            if frame is not None and frame != self.last_sent:
                                self._send(frame)
                        if src.live and self.last_frame_t is None:
                            # held up for the whole session (a loaded machine): what the ECU sent
                            # meanwhile is waiting to be read, and it is no silence
                            for t, frame in src.poll():
                                self.last_frame_t = t
                                for rec in tel.feed(t, frame):
                                    if self.count is None or written < self.count:
                                        self.sink(rec)
                                        written += 1
                        outcome = Outcome("duration")
                        break
                    if self.control is not None and now >= next_send:
                        frame = self.control(now)
                        if frame is not None:
                            self._send(frame)
                        next_send += self.period
                        if next_send <= now - self.period:     # a stall: skip the backlog
                            next_send = now + self.period
                    got = src.poll()
                    polled = src.now()          # a silence is judged by reads, never by a stall
                    if first_poll is None:
                        first_poll = polled     # (nor by one before the first read)
                    if got is None:
                        outcome = Outcome("end")
                        break
                    if getattr(src, "gap", None) is not None:
                        self._reconnected(src.take_gap())
                    for t, frame in got:
                        if self.duration is not None and t + 1e-9 >= self.duration:
                            # read after the end (a fast replay's batch; a live read after a stall):
                            # no record, but the ECU was heard
                            self.last_frame_t = t
                            outcome = Outcome("duration")
                            break
                        self.last_frame_t = t
                        if self._cycle is not None:
                            outcome = self._check_ids(frame[0] & 0x0F)
                            if outcome is not None:
                                break
                        if not told and tel.initial_error is not None and self.controlling:
                            told = True
                            self.notify(f"the ECU reports error {tel.initial_error[0]} ({tel.initial_error[1]}) "
                                        f"from before; an ECU starts again only after stop or standby")
                        for rec in tel.feed(t, frame):
                            self.sink(rec)
                            written += 1
                            if self.count is not None and written >= self.count:
                                outcome = Outcome("count")
                                break
                        if outcome is not None:
                            break
                        if not self._esr_said and not self.answers_esr and tel.latest.get("esr"):
                            self._esr_said = True
                            self.notify(f"the ECU asks for the air pressure (status ID 8's ESR bit, at t={t:.2f} s) "
                                        f"and nothing answers it: --air-pressure HPA (or an --aux barometer's "
                                        f"field) does")
                        if tel.new_error is not None and self.stop_on_error:
                            code, name, et = tel.new_error
                            outcome = Outcome("ecu-error", DeviceError(describe_error(code, name, et)))
                            break
                        if self.limits is not None and self.limits.tripped is not None:
                            outcome = Outcome("limit", self.limits.tripped)
                            break
                        if self.alarms is not None and self.alarms.tripped is not None:
                            tripped, self.alarms.tripped = self.alarms.tripped, None
                            if self.controlling:         # a hung or hot start under this session
                                outcome = Outcome("alarm", tripped)
                                break
                    if outcome is not None:
                        break
                    now = src.now()
                    if self.on_update is not None and now >= next_update:
                        self.on_update(tel.snapshot(now), tel.health(now, src.framer))
                        next_update = now + self.update_interval
                    if src.live and self.silence is not None and getattr(src, "down", None) is None:
                        since = self.last_frame_t if self.last_frame_t is not None else first_poll
                        since = max(since, self._back_t)
                        if not got and polled - since > self.silence:
                            outcome = Outcome("silence", silence_error(
                                src, self.silence, heard=self.last_frame_t is not None))
                            break
            except StartRefused as e:           # the stand's interlock: nothing was sent
                outcome = Outcome("refused", e)
            except PortError as e:
                outcome = Outcome("port", e)
            except OutputError as e:           # a full disk under -o or --raw-log
                outcome = Outcome("output", e)
            except BrokenPipeError:
                outcome = Outcome("pipe")
            finally:
                if outcome is None:            # an unexpected exception: still try to abort
                    self._abort(Outcome("error"))
            if outcome.reason not in ("count", "refused"):
                try:
                    for rec in tel.flush():
                        if self.count is not None and written >= self.count:
                            break
                        self.sink(rec)
                        written += 1
                except BrokenPipeError:
                    outcome = Outcome("pipe")
            if outcome.ok and src.live and self.last_frame_t is None and self.ecu_limits is None:
                # a silent device never passes: no status frame in the whole session, however
                # short, is the silence it would have been given more time
                ran = self.duration if self.duration is not None else src.now()
                outcome = Outcome("silence", silence_error(src, ran, heard=False, ran=True))
            self._abort(outcome)
            if self.alarms is not None and self.controlling and not outcome.ok and outcome.reason != "pipe":
                self._trip_alarm(outcome)
            if src.live and outcome.reason in RUNDOWN_AFTER and outcome.aborted in ("standby", "stop"):
                try:
                    self.sink(trip_record(outcome, src.now(), src.clock))
                except (OutputError, BrokenPipeError):
                    pass
                else:
                    if self.rundown:
                        written += self._record_rundown(outcome, guard)
        if self.alarms is not None:
            self.alarms.seen(tel.latest)
        if outcome.aborted == "failed" and (outcome.ok or outcome.reason in ("interrupted", "terminated")):
            # the end or abort command did not go out: the engine is in no stated state
            outcome = Outcome("port", self.abort_error, aborted="failed")
        if self.interrupted is not None and (outcome.ok or outcome.reason in ("interrupted", "terminated")):
            # engine control was cut by the port failure: that is how the session ended, whatever
            # ended the logging afterwards (its time, Ctrl-C, SIGTERM)
            outcome = Outcome("port", PortError(self.interrupted), aborted=self.abort)
        self.ended_t = now = src.now()
        if self.on_update is not None:
            self.on_update(tel.snapshot(now), tel.health(now, src.framer))
        self.written = written
        return outcome

    def _trip_alarm(self, outcome):
        """The stand's alarm for this abnormal end (latched until acknowledged)."""
        err = outcome.error
        what = str(err) if err is not None else _WHY.get(outcome.reason, outcome.reason)
        sent = outcome.aborted
        if sent in ABORTS and sent != "none":
            what += f"; sent {describe_abort(sent)}"
        cond = getattr(err, "condition", None)
        self.alarms.trip(outcome.reason, what, t=self.source.now(), limit=cond.text if cond is not None else None,
                         field=cond.field if cond is not None else None, value=getattr(err, "value", None))

    def _record_rundown(self, outcome, guard) -> int:
        """After a trip (its record written): the ECU's records until the engine is at rest
        (:func:`at_rest`), :attr:`rundown` seconds, a new signal, a silent ECU or the port's end,
        the abort's state command repeated at the rate meanwhile; then a ``rundown`` record.
        Returns the records written."""
        src, tel = self.source, self.telemetry
        t0 = src.now()
        written = 0
        frame = abort_frames(outcome.aborted, tel.decoder.known)[0]
        signum, repeats = guard.signum, guard.repeats
        ended = None
        try:
            if at_rest(tel.latest):
                ended = "rest"
            else:
                again = "Ctrl-C again ends it" if signum is not None else "Ctrl-C ends it"
                self.notify(f"recording the rundown until the ECU reports stop or standby and the rotor is below "
                            f"{RUNDOWN_RPM} rpm (at most {self.rundown:g} s; {again})")
            next_send = t0 + self.period
            last = t0
            while ended is None:
                if guard.signum != signum or guard.repeats != repeats:
                    ended = "cut"
                    break
                now = src.now()
                if now - t0 >= self.rundown:
                    ended = "max"
                    break
                if now >= next_send:
                    src.write(frame)            # the abort's state, held (an ECU wants a host that sends)
                    next_send = max(next_send + self.period, now)
                got = src.poll()
                if got is None:
                    ended = "end"
                    break
                for t, f in got:
                    last = t
                    for rec in tel.feed(t, f):
                        self.sink(rec)
                        written += 1
                if at_rest(tel.latest):
                    ended = "rest"
                elif self.silence is not None and src.now() - last > self.silence:
                    ended = "silence"
                elif self.on_update is not None:
                    self.on_update(tel.snapshot(src.now()), tel.health(src.now(), src.framer))
        except PortError:
            ended = "port"
        except (OutputError, BrokenPipeError):
            ended = "output"
        now = src.now()
        latest = tel.latest
        state = latest.get("engine_state_name") or "unknown"
        egt, rpm = latest.get("egt_c"), latest.get("rpm")
        where = f"state {state}, EGT {_num(egt)} °C, {_num(rpm)} rpm"
        outcome.rundown = {"s": round(now - t0, 3), "ended": ended, "records": written}
        if ended != "output":
            try:
                self.sink({"time": src.clock.iso(now), "t": round(now, 3), "kind": "rundown",
                           "trip": f"rundown {now - t0:.1f} s: {_RUNDOWN_SAID[ended]} ({where})",
                           "rundown_s": round(now - t0, 3), "ended": ended})
            except (OutputError, BrokenPipeError):
                pass
        if ended == "rest":
            if now > t0:
                self.notify(f"rundown recorded: {now - t0:.1f} s until the engine was at rest ({where})")
        elif ended == "cut":
            self.notify(f"rundown recording cut after {now - t0:.1f} s: not recorded from there ({where})")
        elif ended == "max":
            self.notify(f"rundown recording ended after its {self.rundown:g} s maximum: the engine is not at rest "
                        f"({where})")
        else:
            self.notify(f"rundown recording ended after {now - t0:.1f} s ({_RUNDOWN_END[ended]}; {where})")
        return written

    def _left(self) -> str:
        """What the engine keeps doing after the last frame sent, in words."""
        if self.last_sent is None:
            return "the last command"
        left = zk.ControlFrame(self.last_sent).leaves(self.rpm_factor)
        return f"the engine is left {left}" if left else "the engine keeps the last command"

    def _abort(self, outcome):
        if outcome.aborted is not None or not self.controlling:
            return
        kind = self.abort
        if outcome.ok:
            kind = self.end if self.end is not None else (self.abort if self.abort_at_end else None)
            if kind == "hold":
                outcome.aborted = "hold"
                self.notify(f"{self.end_label}: --end hold: nothing more sent; {self._left()}")
                return
        if kind is None:
            return
        if kind == "none":
            why = self.end_label if outcome.ok else _WHY.get(outcome.reason, outcome.reason)
            self.notify(f"{why}: --abort none: nothing sent; {self._left()}")
            return
        known = self.telemetry.decoder.known
        frames = abort_frames(kind, known, pump=self.pump_on)
        self.sealed = frozenset(frames)
        try:
            for f in frames:
                self.source.write(f)
            self.source.clock.sleep(0.02)
            self.source.write(frames[0])
        except PortError as e:
            self.notify(f"could not send the abort command ({describe_abort(kind)}): {e}")
            outcome.aborted = "failed"
            self.abort_error = e
            return
        outcome.aborted = kind
        why = _WHY.get(outcome.reason, self.end_label)
        if outcome.reason == "terminated" and outcome.signum not in (None, TERMINATED - 128):
            why = f"terminated ({name(outcome.signum)})"     # SIGHUP, SIGQUIT, ...: which one
        self.notify(f"{why}: sent {describe_abort(kind)}")


def _signalled(signum) -> Outcome:
    """The outcome of a session a signal ended: ``interrupted`` (Ctrl-C) or ``terminated``."""
    outcome = Outcome("interrupted" if signum in INTERRUPT_SIGNALS else "terminated")
    outcome.signum = signum
    return outcome


#: How a session's end is worded in its notes (an ok end: the session's ``end_label``).
_WHY = {"interrupted": "interrupted", "terminated": "terminated", "port": "port failure",
        "silence": "ECU silent", "ecu-error": "ECU error", "pipe": "output closed",
        "output": "output failed", "error": "error", "limit": "limit violated",
        "alarm": "start alarm"}
_RUNDOWN_SAID = {"rest": "the engine at rest", "cut": "recording cut", "max": "its maximum reached, not at rest",
                 "silence": "the ECU fell silent", "end": "the source ended", "port": "the port failed",
                 "output": "the output failed"}
_RUNDOWN_END = {"silence": "the ECU fell silent", "end": "the source ended", "port": "the port failed",
                "output": "the output failed"}


def _num(value):
    return "?" if value is None else f"{value:,.0f}"
