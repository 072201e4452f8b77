"""A ZK turbine ECU from Python: :class:`Ecu`, a context manager over one port.

>>> from zkzap import Ecu
>>> with Ecu("sim://zk?speed=10") as ecu:                 # doctest: +SKIP
...     for rec in ecu.hold("control", 3, state="run", throttle_pct=40):
...         if rec.id == 1:
...             print(rec.engine_state_name, rec.rpm)

Status records are :class:`Status` objects: dicts (the keys ``zk monitor`` writes: ``time``,
``t``, ``kind``, ``id``, the fields, ``frame``, ``stale``, ``stale_ids``) whose keys also read
as attributes. Voltages are decoded in the ECU's own unit: until the first status ID 6 reveals
the protocol version, frames are held back (at most a cycle), unless ``protocol_version`` is
given.

Safety: a session that sent a frame controlling the engine (see
:attr:`zkzap.codec.zk.ControlFrame.controls_engine`) sends the abort command (``abort``:
standby or stop with throttle 0; ``none`` sends nothing) when a :meth:`Ecu.hold` ends
abnormally (an exception, Ctrl-C, the generator closed early) and when the Ecu closes. A frame
the ECU cannot follow — an RPM target above the max rpm it reports, a command newer than its
protocol version — is refused before anything is sent (:class:`~zkzap.api.prestart.EcuLimitError`,
exit status 2): :meth:`Ecu.send`, :meth:`Ecu.hold` and :meth:`Ecu.run_profile` first read the
ECU's status ID 6 when a frame needs it (:mod:`zkzap.api.prestart`).

Time is the session's one clock (:mod:`zkzap.link.clock`): ``seconds``, ``duration``,
``silence`` and every record's ``t`` are model seconds on a sped-up simulator
(``sim://zk?speed=10``), real seconds elsewhere. A call that reads status frames and gets none
raises :class:`~zkzap.errors.NoReply`, however short it was.

Built on :class:`~zkzap.link.zk_port.ZkLink` (the port), :class:`~zkzap.link.zk_sources.LiveSource`
(status frames), :class:`~zkzap.api.telemetry.Telemetry` (records), :class:`~zkzap.api.session.Session`
(the control loop) and :class:`~zkzap.api.schedule.Schedule` (throttle and RPM schedules, as
``zk profile`` runs them).
"""

from __future__ import annotations

import contextlib

TYPE_CHECKING = False

if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    import os
    from typing import Any, Callable, Iterable, Iterator, Literal, Optional, Sequence, Union

    from typing_extensions import Self, TypeAlias

    from ..codec.permissions import AllowSpec
    from ..sim.launch import Simulator
    from .prestart import EcuLimits, Plan
    from .schedule import Schedule
    from .session import Outcome

    _StatusBase: TypeAlias = dict[str, Any]
    #: What :meth:`Ecu.run_profile` runs: a Schedule, CSV text, a CSV file's path or rows.
    ScheduleSpec: TypeAlias = Union[Schedule, str, os.PathLike[str], Iterable[Sequence[Union[float, str]]]]
else:
    _StatusBase = dict

from ..codec import zk
from ..errors import DeviceError, UsageError, did_you_mean

__all__ = ["Ecu", "Status", "ProfileResult"]


class Status(_StatusBase):
    """One status record: a dict whose keys also read as attributes (``rec.rpm``, ``rec.egt_c``)."""

    __slots__ = ()

    def __getattr__(self, name: str) -> Any:
        try:
            return self[name]
        except KeyError:
            raise AttributeError(f"status ID {self.get('id')} has no field {name!r}" + did_you_mean(name, self),
                                 name=name) from None


class ProfileResult:
    """How :meth:`Ecu.run_profile` ended: ``outcome`` (:class:`~zkzap.api.session.Outcome`:
    ``reason``, ``error``, ``aborted``, ``exit_code``), ``summary`` (max rpm, max EGT, fuel,
    states, errors, as ``zk profile --summary-json`` writes it), ``records`` written and
    ``notes`` (values the schedule rounded, ``FILE:LINE: ...``)."""

    def __init__(self, outcome: Outcome, summary: dict[str, Any], records: int, notes: Iterable[str] = ()) -> None:
        self.outcome = outcome
        self.summary = summary
        self.records = records
        self.notes = list(notes)

    @property
    def ok(self) -> bool:
        """True when the schedule ran to its end."""
        return self.outcome.ok

    def __repr__(self) -> str:
        return f"ProfileResult(reason={self.outcome.reason!r}, records={self.records})"


class Ecu:
    """A ZK ECU on one port: a context manager (on exit the abort command goes out if the
    session controlled the engine, then the port closes).

    ``port`` is a device path, any pyserial URL, ``sim://zk?speed=10`` or a simulator started
    with :func:`zkzap.sim.start`; ``baud`` the line speed and ``stop_bits`` (1 or 2);
    ``protocol_version`` the ECU's (None: read from status ID 6); ``silence`` the longest wait
    for a status frame before NoReply (session seconds; None: no limit); ``abort`` the abort
    command (``standby``, ``stop`` or ``none``); ``allow`` the permissions its frames are
    given: a frame that can start the engine or run ECU hardware (state run, the drain, test
    and pump-on actions) needs :attr:`Permission.ENGINE <zkzap.codec.permissions.Permission>`
    on a real port (the simulator waives it), else :class:`~zkzap.errors.PermissionNeeded`
    and nothing is sent. ``send``, ``hold`` and ``run_profile`` take ``allow=`` for one call too.
    """

    def __init__(self, port: Union[str, Simulator], *, baud: int = 115200, protocol_version: Optional[int] = None,
                 silence: Optional[float] = 2.0, abort: Literal["standby", "stop", "none"] = "standby",
                 stop_bits: Literal[1, 2] = 1, allow: AllowSpec = None) -> None:
        from ..link.zk_port import ZkLink
        from ..link.zk_sources import LiveSource
        from .session import ABORTS
        from .telemetry import Telemetry

        if abort not in ABORTS:
            raise UsageError(f"abort: {abort!r}; allowed {', '.join(ABORTS)}")
        url = getattr(port, "url", port)
        if not url:
            raise UsageError("no port given", baud=baud)
        self.url = url
        """The port's device path or URL."""
        self.baud = baud
        """The line speed."""
        self.abort_kind = abort
        """The abort command sent on an abnormal end and at close (standby, stop, none)."""
        self.silence = silence
        self.link = ZkLink.open(url, baud, stop_bits=stop_bits, allow=allow)
        """The :class:`~zkzap.link.zk_port.ZkLink` (the port)."""
        self.source = LiveSource(self.link)
        self.telemetry = Telemetry(protocol_version, clock=self.source.clock)
        """The :class:`~zkzap.api.telemetry.Telemetry`: snapshot, errors, summary."""
        self.controlling = False
        """True once a frame that controls the engine was sent."""
        self.pump_on = False
        self.sent = 0
        self.limits: Optional[EcuLimits] = None
        """What the ECU reported about itself (:class:`~zkzap.api.prestart.EcuLimits`: max rpm,
        protocol version), once a frame needed it."""
        self._rpm_factor = None
        self._last_frame_t = None
        self._closed = False

    # -- context -------------------------------------------------------------------------------

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> Literal[False]:
        self.close()
        return False

    def close(self) -> None:
        """Send the abort command if the session controlled the engine, then close the port."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.controlling:
                self.abort()
        finally:
            self.link.close()

    # -- frames out ----------------------------------------------------------------------------

    @property
    def protocol_version(self) -> int:
        """The ECU's protocol version (from status ID 6, given, or the default 4)."""
        return self.telemetry.decoder.version

    def frame(self, kind: Union[str, int], **fields: Any) -> zk.ControlFrame:
        """The control frame ``kind`` (a ``zk send`` name or ID) with physical ``fields``
        (``state="run", throttle_pct=40``), checked; nothing is sent."""
        values = dict(fields)
        if "state" in values and "sw" not in values:
            values["sw"] = values.pop("state")
        if "action" in values and "param" not in values:
            values["param"] = values.pop("action")
        frame, note = zk.encode_control(kind, **values)
        return zk.ControlFrame(frame)

    def _write(self, cf: zk.ControlFrame) -> None:
        self.link.write(cf.frame)
        self.sent += 1
        if cf.controls_engine:
            self.controlling = True
        if cf.action == "pump-on":
            self.pump_on = True
        elif cf.action == "pump-off":
            self.pump_on = False
        if cf.id == 6:
            self._rpm_factor = cf.rpm_factor

    def check(self, plan: Plan, *, listen: bool = True) -> None:
        """Check a :class:`~zkzap.api.prestart.Plan` against the ECU's reported limits, reading
        its status ID 6 first when the plan needs it and they are not known yet (``listen``
        False: against what is known, nothing read). Raises EcuLimitError (nothing sent) or
        NoReply."""
        from .prestart import EcuLimits, listen as listen_for

        if not plan.needs_ecu:
            return
        if self.limits is None:
            if not listen:
                plan.check(EcuLimits(None, self.telemetry.decoder.given, read=False))
                return
            self.limits = listen_for(self.source, self.silence, given=self.telemetry.decoder.given,
                                     on_frame=self._heard, where=self.url)
        plan.check(self.limits)

    def _heard(self, t, frame):
        self._last_frame_t = t
        self.telemetry.feed(t, frame)          # the snapshot stays current; no record is yielded

    def _plan(self, cf, rpm_factor=None):
        from .prestart import Plan

        return Plan([cf], rpm_factor=rpm_factor or self._rpm_factor,
                    what=cf.command.name if cf.command is not None else f"ID {cf.id}")

    def send(self, kind: Union[str, int, zk.ControlFrame], *, listen: bool = True,
             allow: AllowSpec = None, **fields: Any) -> zk.ControlFrame:
        """Send one control frame (see :meth:`frame`); returns it. ``allow``: permissions for
        this frame besides the session's (refused before anything is read or sent). A frame
        that needs the ECU's limits (an ID 7 target, a command newer than protocol version 1)
        is checked against them first (see :meth:`check`; ``listen`` False: nothing is read,
        the frame is checked against the version given or assumed, and an RPM target is
        refused)."""
        cf = kind if isinstance(kind, zk.ControlFrame) else self.frame(kind, **fields)
        with self._allowing(allow):
            self.link.authorize(cf.frame)          # refused before anything is read or sent
            self.check(self._plan(cf, fields.get("rpm_factor")), listen=listen)
            self._write(cf)
        return cf

    @contextlib.contextmanager
    def _allowing(self, allow):
        """The session's permissions, with ``allow`` added while the block runs."""
        if allow is None:
            yield
            return
        from ..codec.permissions import as_permission

        saved = self.link.allow
        self.link.allow = saved | as_permission(allow)
        try:
            yield
        finally:
            self.link.allow = saved

    def abort(self) -> list[bytes]:
        """Send the abort command now (control ID 1 with state standby/stop and throttle 0;
        on protocol version 4 or later also leaves RPM mode; pump-off after a pump-on).
        Returns the frames sent."""
        from .session import abort_frames

        frames = abort_frames(self.abort_kind, self.telemetry.decoder.known, pump=self.pump_on)
        for f in frames:
            self.link.write(f)
        if frames:
            self.source.clock.sleep(0.02)
            self.link.write(frames[0])
            self.controlling = False
            self.pump_on = False
        return frames

    # -- status in -----------------------------------------------------------------------------

    def _records(self, control: Optional[zk.ControlFrame] = None, period: Optional[float] = None,
                 duration: Optional[float] = None, count: Optional[int] = None) -> Iterator[Status]:
        from .prestart import silence_error

        src, tel = self.source, self.telemetry
        start = src.now()
        since = None                          # silence counts from this call's first read
        if period is not None:
            src.pace(period)
        next_send = start
        n = 0
        heard = False
        while True:
            now = src.now()
            if duration is not None and now - start >= duration:
                if not heard:
                    # held up for the whole call (a loaded machine)? What came meanwhile is waiting
                    for t, frame in src.poll():
                        self._last_frame_t, heard = t, True
                        for rec in tel.feed(t, frame):
                            yield Status(rec)
                if not heard:                 # a silent device never passes, however short the call
                    raise silence_error(src, now - start, heard=False, where=self.url, ran=True)
                return
            if control is not None and now >= next_send:
                self._write(control)
                next_send += period
                if next_send <= now - period:     # a stall: skip the backlog
                    next_send = now + period
            got = src.poll()
            polled = src.now()               # a silence is judged by reads, never by a stall
            if since is None:
                since = polled
            for t, frame in got:
                self._last_frame_t = since = t
                heard = True
                for rec in tel.feed(t, frame):
                    yield Status(rec)
                    n += 1
                    if count is not None and n >= count:
                        return
            if not got and self.silence is not None and polled - since > self.silence:
                raise silence_error(src, self.silence, heard=self._last_frame_t is not None, where=self.url)
            if tel.new_error is not None and control is not None and self.controlling:
                code, name, et = tel.new_error
                tel.new_error = None
                from .telemetry import describe_error

                raise DeviceError(describe_error(code, name, et), ecu_error=code)

    def status(self, *, count: Optional[int] = None, duration: Optional[float] = None) -> Iterator[Status]:
        """Status records as they arrive (forever, or ``count`` records / ``duration`` s).
        Raises NoReply when the ECU is silent for ``silence`` s."""
        return self._records(count=count, duration=duration)

    def hold(self, kind: Union[str, int, zk.ControlFrame], seconds: float, *, rate: float = 20.0,
             allow: AllowSpec = None, **fields: Any) -> Iterator[Status]:
        """Send control frame ``kind`` with ``fields`` every ``1/rate`` s for ``seconds`` s,
        yielding the status records received meanwhile. A new ECU error while controlling
        raises DeviceError; any abnormal end sends the abort command — Ctrl-C, and SIGTERM too
        (and every other signal that would end the process: SIGHUP, SIGQUIT, ...):
        while the hold runs (in the main thread) such a signal raises
        :class:`~zkzap.signals.Terminated` (a KeyboardInterrupt) instead of ending the process
        where it stands, and the previous handler comes back after. A frame the ECU cannot
        follow is refused before the first is sent (see :meth:`check`); a hold that read no
        status frame raises NoReply."""
        if not 1 <= rate <= 200:
            raise UsageError(f"rate: {rate:g} is out of range; allowed 1..200 Hz")
        from ..signals import INTERRUPT_SIGNALS, STOP_SIGNALS, Terminated, handle, held, restore

        cf = kind if isinstance(kind, zk.ControlFrame) else self.frame(kind, **fields)
        with self._allowing(allow):
            self.link.authorize(cf.frame)          # refused before anything is sent
        self.check(self._plan(cf, fields.get("rpm_factor")))
        done = False

        def terminated(signum, frame):
            raise Terminated(signum)

        # while the engine is held, SIGTERM (SIGHUP, ...: every signal that would end the process)
        # ends the hold as Ctrl-C does (so the abort goes out) instead of killing the process where
        # it stands; the previous handlers come back after. SIGINT keeps its handler (Ctrl-C's
        # KeyboardInterrupt, or the program's), and so does a signal the process handles itself
        import signal

        old = handle([s for s in STOP_SIGNALS if s not in INTERRUPT_SIGNALS
                      and (s == signal.SIGTERM or signal.getsignal(s) in (signal.SIG_DFL, None))], terminated)
        try:
            with self._allowing(allow):
                yield from self._records(cf, 1.0 / rate, duration=seconds)
            done = True
        finally:
            try:
                if not done and self.controlling and self.abort_kind != "none":
                    with held():             # a second signal does not cut the abort short
                        try:
                            self.abort()
                        except Exception:  # noqa: BLE001 - the port may be what failed; the first error wins
                            pass
            finally:
                restore(old)

    def keepalive(self, seconds: float, *, rate: float = 20.0) -> Iterator[Status]:
        """Send keep-alives (ID 0) for ``seconds`` s, yielding status records (ECUs before
        protocol version 5 report loss of control signal when the host falls silent)."""
        return self.hold("keepalive", seconds, rate=rate)

    @property
    def health(self) -> dict[str, Any]:
        """Link health: ``frames``, ``frames_per_s`` (over the last second), ``crc_errors``,
        ``skipped`` bytes, ``stale`` (and :meth:`stale_ids`), ``protocol_version`` and
        ``version_source``."""
        now = self.source.now()
        h = self.telemetry.health(now, self.source.framer)
        h["stale_ids"] = self.telemetry.stale_ids(now)
        return h

    def stale_ids(self) -> list[int]:
        """Status IDs not seen for more than three of their periods."""
        return self.telemetry.stale_ids(self.source.now())

    @property
    def snapshot(self) -> dict[str, Any]:
        """Every status field's latest value."""
        return self.telemetry.snapshot(self.source.now())

    # -- schedules -----------------------------------------------------------------------------

    def run_profile(self, schedule: ScheduleSpec, *, rate: float = 20.0,
                    interpolate: Literal["step", "linear"] = "step",
                    on_record: Optional[Callable[[Status], None]] = None, check: bool = True,
                    allow: AllowSpec = None) -> ProfileResult:
        """Run a throttle or RPM schedule as ``zk profile`` does: a
        :class:`~zkzap.api.schedule.Schedule`, CSV text (``time_s,throttle_pct[,state]`` or
        ``time_s,rpm=N[,state]`` rows, optionally under a header), the path of a CSV file
        (``os.PathLike``, or a one-line string that names a file or is no CSV row), or a list of
        ``(time_s, throttle_pct[, state])``. ``interpolate`` (``step`` or ``linear``) applies
        to what is parsed here.

        Control frames go out at ``rate`` Hz; every status record goes to ``on_record``.
        Ends at the schedule's last row (the abort command follows when it ends in state run or
        in RPM mode), or on Ctrl-C/SIGTERM, a port failure, a silent ECU or a new ECU error (the
        abort command is sent). An RPM target above the ECU's max rpm (or an ECU too old for RPM
        mode) is refused before the schedule's first frame
        (:class:`~zkzap.api.prestart.EcuLimitError`, exit status 2, nothing sent). With
        ``check`` a failure is raised (EcuLimitError, DeviceError, NoReply, PortError,
        KeyboardInterrupt) after the abort; otherwise the result says how it ended. A schedule
        that can start the engine needs the ENGINE permission on a real port (``allow``),
        checked on every frame it can send before the first goes out."""
        import os

        from ..link.zk_sources import LiveSource
        from .schedule import Schedule
        from .session import Session
        from .telemetry import Telemetry

        sched = schedule
        if isinstance(schedule, os.PathLike) or (isinstance(schedule, str) and "\n" not in schedule and (
                os.path.isfile(schedule) or not any(sep in schedule for sep in ",;\t"))):
            sched = Schedule.load(os.fspath(schedule), interpolate=interpolate)
        elif isinstance(schedule, str):
            sched = Schedule.parse(schedule, interpolate=interpolate)
        elif not isinstance(schedule, Schedule):
            text = "\n".join(",".join(str(c) for c in row) for row in schedule)
            sched = Schedule.parse(text, interpolate=interpolate)
        sched.check_length()
        with self._allowing(allow):
            for frame in sched.frames():            # every frame it can send, before the first
                self.link.authorize(frame)
        plan = sched.plan_check()
        if self.limits is not None:
            plan.check(self.limits)            # known already: nothing to listen for
        source = LiveSource(self.link)
        source.framer, source.signal = self.source.framer, self.source.signal
        tel = Telemetry(self.telemetry.decoder.known, clock=source.clock)
        sink = (lambda rec: on_record(Status(rec))) if on_record is not None else (lambda rec: None)
        session = Session(source, tel, sink, control=sched.frame_at, rate=rate, abort=self.abort_kind,
                          duration=sched.length, silence=self.silence, stop_on_error=True,
                          abort_at_end=sched.final_state == "run" or sched.ends_in_rpm_mode,
                          plan=plan if self.limits is None else None)
        with self._allowing(allow):
            outcome = session.run()
        if session.ecu_limits is not None:
            self.limits = session.ecu_limits
        if session.controlling:
            self.controlling = True
        summary = {"outcome": outcome.reason, "exit_status": outcome.exit_code, "aborted": outcome.aborted,
                   "duration_s": round(session.ended_t or 0.0, 3), "schedule_s": sched.length,
                   "crc_errors": source.framer.bad}
        summary.update(tel.summary())
        result = ProfileResult(outcome, summary, session.written, sched.notes)
        if check:
            outcome.raise_for_status()
        return result
