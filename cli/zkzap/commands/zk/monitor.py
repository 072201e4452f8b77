"""``zk monitor``: the ECU's status frames as they arrive — a live dashboard on a terminal, JSON
Lines in a pipe, CSV or JSON on request, to stdout or a file — and the logging machinery
(:class:`Output`, :func:`run_telemetry`) that ``zk send --for`` and ``zk profile`` use too.
"""

from __future__ import annotations

import os
import sys

import click

from ...codec import zk
from ...errors import DeviceError, UsageError
from ...io import COLUMNAR_FORMATS, SESSION_FORMATS, format_for_path
from .. import CONTEXT, Command
from ..options import (FiniteRange, InputPath, IntRange, note, output_file, port_options, protocol_version_option,
                       rate_option)
from .stand import (build_stand, check_output_dir, limit_options, logbook_option, raise_for_status, report,
                    sensor_options, session_sensors, summarizer, summary_option)
from .telemetry import (check_log_options, errors_text, log_options, port_from_env, reconnect_option,
                        resolve_port, session_exits, zk_timeout_help)


class Output:
    """Where records go: a writer (stdout or -o FILE), and the dashboard on a terminal.

    ``-o FILE`` is checked here (before any port opens) and opened by the first record
    (:class:`zkzap.outfile.LazyOutput`; a workbook: written by the first record, renamed over
    the file at the close), never before: a run that writes no record — no port, a silent ECU,
    a run cut short — leaves an existing file exactly as it was (a header is not a record)."""

    def __init__(self, fmt, output, append, snapshot, ids, title, columns_for, inputs=None, view=True):
        from ...io.term import is_tty

        path = output if output and output != "-" else None
        if fmt is None and path:
            fmt = format_for_path(path, SESSION_FORMATS)
        self.file = None
        self._xlsx = fmt == "xlsx"
        self._columnar = fmt in COLUMNAR_FORMATS          # written whole like a workbook
        if self._xlsx:
            from ...io import xlsx

            xlsx.check(output, append)
        if self._columnar:
            from ...io import columnar

            columnar.check(fmt, output, append)
        if fmt == "mcap":
            from .mcap_output import open_mcap

            self.stream, self.writer, self.snapshot = open_mcap(output, append, snapshot, inputs=inputs)
            self.fmt, self._table = fmt, False
            self.dashboard = _dashboard(title) if path and view and is_tty(sys.stdout) else None
            return
        if fmt is None:
            fmt = "table" if is_tty(sys.stdout) else "jsonl"
        self.fmt = fmt
        self.stream = None if path else sys.stdout
        self.dashboard = None
        self.writer = None
        stdout_tty = view and is_tty(sys.stdout)
        if fmt == "table" and not path and stdout_tty:
            self.dashboard = _dashboard(title)
        elif path and stdout_tty:
            self.dashboard = _dashboard(title)
        if snapshot is None:
            snapshot = fmt in ("csv", "xlsx") + COLUMNAR_FORMATS   # tables: every field's latest value on each row
        if fmt == "table" and self.dashboard is not None and not path:
            snapshot = False
        self.snapshot = snapshot
        self._table = fmt == "table"
        if self._table:
            self.snapshot = False
        self._columns = [] if self._table else columns_for(self.snapshot, ids)
        had = False
        if path:
            self.file = output_file(path, append, fmt=fmt, columns=self._columns, inputs=inputs)
            if self._xlsx or self._columnar:
                return                 # the workbook is made by the first record (see write)
            from ...outfile import LazyOutput

            self.stream, had = LazyOutput(self.file), self.file.had
        elif self.dashboard is not None:
            return                     # the dashboard shows the records; stdout is its screen
        from ...io.writers import make_writer

        if self._table:
            self.writer = make_writer("table", self.stream, [], table_columns=_TABLE_COLUMNS)
        else:
            self.writer = make_writer(self.fmt, self.stream, self._columns, header=not had, measurement="status")

    #: The :class:`~zkzap.offload.Lane` the records are written in (None: in the caller's thread).
    lane = None
    #: Declared units of columns the protocol tables do not know (external sensors' channels).
    units = None

    def offload(self, lane):
        """Write the records (and close) in ``lane`` from now on; returns the session's sink."""
        self.lane = lane
        return lane.wrap(self.write)

    def finish(self, sheets=None):
        """The run ended: a workbook that got records gets its steps and summary sheets
        (``sheets``: ``(steps, summary)``). A file no record opened stays as it was."""
        if self.lane is not None:
            self.lane.call(self._finish, sheets)
        else:
            self._finish(sheets)

    def _finish(self, sheets):
        if sheets is not None and self._xlsx and self.writer is not None:
            self.writer.sheets(*sheets)

    def write(self, rec):
        if self.writer is None and self._xlsx and self.file is not None:
            from ...io.xlsx import XlsxWriter

            self.writer = XlsxWriter(self.file.path, self._columns, self.units)   # renamed over the file at the close
        if self.writer is None and self._columnar and self.file is not None:
            from ...io.columnar import writer

            self.writer = writer(self.fmt, self.file.path, self._columns, self.units)
        if self.writer is not None:
            if self._table:
                from .decode import summary

                fields = {k: v for k, v in rec.items() if k not in _NOT_FIELDS}
                rec = dict(rec, _summary=summary(fields))
            self.writer.write(rec)

    def update(self, snapshot, health):
        if self.dashboard is not None:
            self.dashboard.update(snapshot, health)

    def __enter__(self):
        if self.dashboard is not None:
            self.dashboard.__enter__()
        return self

    def __exit__(self, *exc):
        try:
            if self.dashboard is not None:
                self.dashboard.__exit__(*exc)
        finally:
            self.close()
        return False

    def close(self):
        """Close the writer and the file (in the lane, once its records are written: one that
        stays blocked is abandoned, see :mod:`zkzap.offload`)."""
        if self.lane is not None:
            lane, self.lane = self.lane, None
            if self._columnar:
                # a columnar file is assembled at its close, which takes as long as the run is
                # long: the queued records are written in the lane, the file made here
                if lane.finish(None):
                    self._close()
                return
            lane.finish(self._close)
        else:
            self._close()

    def _close(self):
        if self.writer is not None:
            w, self.writer = self.writer, None
            try:
                w.close()
            except BrokenPipeError:
                pass
        if self.stream is not None and self.stream not in (sys.stdout, getattr(sys.stdout, "buffer", None)) \
                and not self.stream.closed:
            self.stream.close()


_TABLE_COLUMNS = [("t", "t"), ("id", "id"), ("_summary", "fields"), ("stale", "stale")]
_NOT_FIELDS = {"time", "t", "stale", "stale_ids"}


def _dashboard(title):
    from ...io.dashboard import Dashboard

    return Dashboard(sys.stdout, title)


def _header_without_trip(output, columns, snapshot, ids, fmt) -> bool:
    """An existing CSV file appended to has the header of a run without the ``trip`` column (a
    monitor's, or an older version's): the records keep its columns (a trip's row still has its
    time and limit)."""
    if not output or output == "-" or fmt not in (None, "csv") or not output.lower().endswith(".csv"):
        return False
    if not os.path.isfile(output):
        return False                          # a FIFO or a device: nothing to read a header from
    try:
        with open(output, encoding="utf-8", errors="replace") as f:
            head = f.readline().strip()
    except OSError:
        return False
    rows = snapshot if snapshot is not None else True
    return bool(head) and head == ",".join(columns(rows, ids))


def session_output(fmt, output, append, snapshot, ids, title, stand, *, controls, view=True) -> Output:
    """The :class:`Output` of a session's records: their columns with the stand's (limits, sensors,
    corrected values) and, for a session that controls the engine, ``trip`` (a trip and the
    rundown after it are marked). ``view``: the dashboard on a terminal."""
    from ...api.telemetry import record_columns

    columns = record_columns if stand is None else stand.columns(record_columns)
    if controls and not (append and _header_without_trip(output, columns, snapshot, ids, fmt)):
        base = columns

        def columns(snapshot, ids=None):
            return base(snapshot, ids) + ["trip"]

    out = Output(fmt, output, append, snapshot, ids, title, columns, view=view)
    if stand is not None and stand.aux is not None:
        out.units = stand.aux.units()         # a sensor's declared units, for the files that keep units
    return out


def capture_lane():
    """The lane of the ``--capture`` file, when one is open (imports nothing otherwise)."""
    capture = sys.modules.get("zkzap.link.capture")
    return capture.lane() if capture is not None else None


def _outputs_settled(outcome, lanes):
    """The session's outcome once its outputs have written what was queued: a write that failed
    after the session's last record, or an output still blocked at the end (abandoned: said on
    stderr), makes an end that was normal an output failure (exit 7)."""
    from ...api.session import Outcome
    from ...offload import abandoned

    failed = None
    given_up = abandoned()
    for lane in lanes:
        # the records and the raw log are closed already; the capture closes with the command
        if lane in given_up or not lane.drain():
            lane.abandon()
            note(lane.lost())
            failed = failed or lane.stalled()
            continue
        try:
            lane.check()
        except BrokenPipeError:
            pass                                  # the reader went away: ends quietly, as always
        except Exception as e:
            failed = failed or e
    if failed is not None and (outcome.ok or outcome.reason == "pipe"):
        return Outcome("output", failed, aborted=outcome.aborted)
    return outcome


def run_telemetry(*, url=None, baud=None, replay=None, fast=False, fmt=None, output=None, append=False,
                  snapshot=None, ids=None, stale_after=3, raw_log=None, protocol_version=None, timeout=None,
                  stop_bits=1, count=None, duration=None, control=None, rate=None, abort="none",
                  stop_on_error=False, abort_at_end=False, title=None, stand=None, inputs=None, extra_outputs=None,
                  reconnect=None, end=None, end_label="end of schedule", summarize=None, plan=None, allow=None):
    """Log status records from a port (or a replay) while optionally sending control frames.

    Returns ``(outcome, telemetry, session)``; the caller raises ``outcome.raise_for_status()``
    after its own reporting. Files are closed (whole) before this returns. ``stand``: the
    test-stand hooks (:class:`.stand.Stand`: limits, step averages, logbook statistics).
    ``allow``: the permissions the control frames were given (see :func:`..options.authorize`).
    ``inputs`` and ``extra_outputs`` (option -> path) name the caller's other files: none may be
    an output. ``summarize(outcome, tel, session)`` gives ``(steps, summary)`` for the sheets of
    an ``-o FILE.xlsx`` workbook (``steps``: ``(columns, rows)`` or None). ``plan``: the
    :class:`~zkzap.api.prestart.Plan` of the frames ``control`` sends (checked against the ECU's
    reported limits before the first).
    """
    from ...api.session import DEFAULT_RATE, DEFAULT_SILENCE_S
    from ...api.stand import StandSession
    from ...api.telemetry import Telemetry, parse_ids
    from ...outfile import OutFile, refuse_same_files
    from contextlib import nullcontext

    from ...offload import Lane, Proxy, urgent
    from ...link.port import fit_note
    from ...link.zk_port import ZkLink
    from ...link.zk_sources import LiveSource
    from .bridging import make_bridges

    id_set = parse_ids(ids) if ids is not None else None
    if raw_log == "-":
        raise UsageError("raw-log: '-' is not a file here (stdout carries the records); give a file name")
    refuse_same_files({"--output": output, "--raw-log": raw_log, **(extra_outputs or {})},
                      {"--replay": replay, **(inputs or {})})
    if control is not None and url is not None:
        told = fit_note("control rate", rate or DEFAULT_RATE, 4, baud, stop_bits)
        if told:
            note(told)
    bridges = make_bridges(notify=note)
    if fmt == "mcap" or (fmt is None and output and output.lower().endswith(".mcap")):
        from .mcap_output import check_mcap

        check_mcap(output, append, snapshot)
    # the one stand session (zkzap.api.stand): hooks, alarms, the session loop and its ends;
    # this function makes what it writes to and reads from (the writers, the port, the bridges)
    stand_session = StandSession(stand, notify=note)
    # external sensors first (their first lines name the fields the records get): a silent
    # load cell is found before the ECU is sent anything
    stand_session.start(timeout if timeout is not None else DEFAULT_SILENCE_S)
    try:
        out = session_output(fmt, output, append, snapshot, id_set, title or f"ZK ECU on {url or replay}", stand,
                             controls=control is not None and abort in ("standby", "stop"))
    except BaseException:
        stand_session.close()
        raise
    # opened by the first bytes received: a port that fails to open leaves an old log as it was
    raw = OutFile(raw_log, append=append, binary=True, what="raw-log").check() if raw_log else None
    try:
        if bridges:
            bridges.start()          # an unreachable peer is exit 4 before the port opens or a file is written
    except BaseException:
        bridges.close()
        stand_session.close()
        out.close()
        raise
    source = None
    raw_lane = raw_proxy = None
    # While the dashboard holds the screen, every message (the session's, the limits', the
    # sensors'...) is printed above it: a line beside it would be drawn over by the next refresh
    notify = note
    if out.dashboard is not None:
        out.dashboard.duration = duration
    try:
        if replay is not None:
            from ...api.capture import replay_source

            source = replay_source(replay, fast=fast)
        else:
            # the raw log is written off the control path, like the records (zkzap.offload)
            if raw is not None:
                raw_lane = Lane(f"--raw-log {raw_log}")
                raw_proxy = Proxy(raw, raw_lane, ("write", "flush"))
            source = LiveSource(ZkLink.open(url, baud, raw_log=raw_proxy, stop_bits=stop_bits, allow=allow),
                                reconnect=reconnect)
        tel = Telemetry(protocol_version, id_set, out.snapshot, stale_after, clock=source.clock)
        # the session's one sink of the records (written in a lane of their own, zkzap.offload)
        stand_session.record(out, "stdout" if output in (None, "-") else f"--output {output}")
        on_update = out.update if out.dashboard is not None else None
        on_update = stand_session.attach(source, tel, on_update=on_update)
        sink = stand_session.sink
        if bridges or out.fmt == "mcap":
            from .taps import tap_session

            source, sink, on_update = tap_session(source, tel, out, bridges, on_update, sink)
            stand_session.rebind(source)         # ESR answers are recorded like every control frame
            stand_session.sink = sink
        session = stand_session.make_session(
            control=control, rate=rate or DEFAULT_RATE, abort=abort, count=count, duration=duration,
            silence=timeout if timeout is not None else DEFAULT_SILENCE_S, stop_on_error=stop_on_error,
            abort_at_end=abort_at_end, end=end, end_label=end_label, on_update=on_update, notify=notify, plan=plan)
        stand_session.session = session
        session.stand_session = stand_session    # what the summary and the logbook entry ask
        session.bridges = bridges.stats() if bridges else None
        lanes = [lane for lane in (out.lane, raw_lane, capture_lane()) if lane is not None]
        from ..options import notes_above

        with out, notes_above(out.dashboard.note) if out.dashboard is not None else nullcontext():
            with urgent() if control is not None else nullcontext():
                outcome = session.run()
            stand_session.close()        # the sensors stop with the session: one count for every summary
            if summarize and out.fmt == "xlsx" and outcome.reason != "refused":
                out.finish(summarize(outcome, tel, session))
    finally:
        stand_session.close()
        if source is not None:
            source.close()
        out.close()
        if raw is not None:
            if raw_lane is not None:
                raw_lane.finish(raw.close)
            else:
                raw.close()
        if bridges:
            bridges.close()
            session_stats = bridges.stats()
            for line in bridges.lines():
                note(line)
    if outcome.reason == "refused":
        raise outcome.error          # the ECU's limits refuse the plan: nothing was sent or written
    outcome = _outputs_settled(outcome, lanes)
    if bridges:
        session.bridges = session_stats
    if tel.version_note:
        note(tel.version_note)
    if url is not None and tel.frames:
        told = fit_note(f"the ECU's status rate ({tel.rate} Hz)", tel.rate, 7, baud, stop_bits)
        if told:
            note(told + "; expect fewer status frames")
    framer = source.framer
    if framer.bad and getattr(source, "signal", None) is not None and not source.signal.accepted:
        pass                         # noise, not an ECU's frames: the error says what came
    elif framer.bad:
        note(f"{framer.bad} status frame{'s' if framer.bad > 1 else ''} with a bad CRC skipped "
             f"({framer.skipped} byte{'' if framer.skipped == 1 else 's'})")
    return outcome, tel, session


@session_exits("done (--count, --duration, end of replay)", "with --fail-on-error, an ECU error code was seen")
@click.command(cls=Command, context_settings=CONTEXT)
@port_options("zk", baud_auto=True)
@click.option("--replay", type=InputPath("zk capture"), metavar="FILE",
              help="Decode a raw log (--raw-log) or a pcapng capture (--capture) instead of a port, "
                   "paced in real time.")
@click.option("--fast", is_flag=True, help="With --replay: as fast as possible.")
@log_options
@click.option("-c", "--count", type=IntRange(1), default=None, metavar="N",
              help="Stop after N records.")
@click.option("--duration", type=FiniteRange(0, min_open=True), default=None, metavar="SECONDS",
              help="Stop after SECONDS.")
@click.option("--keepalive", is_flag=True,
              help="Send keep-alives (ID 0) at --rate: ECUs before protocol version 5 report loss of "
                   "control signal when the host falls silent.")
@rate_option(help="Keep-alive rate (default 20 Hz).")
@protocol_version_option
@reconnect_option
@click.option("--fail-on-error", is_flag=True,
              help="Exit with status 5 if any ECU error code was seen (after writing every record).")
@limit_options
@sensor_options
@logbook_option
@summary_option
def monitor(port, baud, stop_bits, timeout, sim, replay, fast, fmt, output, append, snapshot, ids, stale_after,
            raw_log, count, duration, keepalive, rate, protocol_version, fail_on_error, limit, limits_files, on_limit,
            logbook, summary_json, reconnect=None, aux=(), thrust_from=None, fuel_flow_from=None, ambient_temp=None,
            ambient_pressure=None, air_pressure=None, engine=None):
    """Show or log the ECU's status frames as they arrive.

    On a terminal: a live dashboard. In a pipe: JSON Lines, one record per frame (as 'zk decode'
    gives them). CSV (-f csv, or -o FILE.csv) gets snapshot rows: every field's latest value on
    each row, one row per frame. Every record has 'time' (ISO 8601 UTC), 't' (seconds since the
    start), 'stale' and 'stale_ids' (IDs not seen for --stale-after periods). Each record is
    flushed as it is written: Ctrl-C or a vanished port leaves a whole file.

    Voltages are decoded in the ECU's own unit: frames are held back until the first status ID 6
    (the protocol version; at most 12 frames) unless --protocol-version is given.

    A raw log's 't' is rebuilt from the status rate the frames report (a raw log holds bytes, not
    times); a pcapng capture's 't' and 'time' are its own timestamps.

    \b
    Examples:
      zk monitor --sim                                  # the dashboard, on the simulator
      zk monitor -p /dev/ttyUSB0 --count 50 -f jsonl | jq -c 'select(.id==1)'
      zk monitor -p /dev/ttyUSB0 -o run.csv --raw-log run.bin
      zk monitor --replay run.bin --fast -f csv
      zk monitor -p /dev/ttyUSB0 --duration 10 --fail-on-error --ids 1 -f jsonl
    """
    if replay is not None:
        if port and port_from_env():
            port = None
        if port or sim:
            raise UsageError("replay: give --replay FILE or a port (-p/--sim), not both")
        if keepalive or raw_log:
            raise UsageError(f"{'keepalive' if keepalive else 'raw-log'}: not with --replay")
        from ...infile import is_input

        if not is_input(replay):
            raise UsageError(f"replay: cannot read {replay}: no such file")
        if baud == "auto":
            raise UsageError("baud: auto makes no sense with --replay (a recording has no line settings); "
                             "allowed with a port only")
        url = None
    else:
        if fast:
            raise UsageError("fast: only with --replay")
        url = resolve_port(port, sim)
    if rate is not None and not keepalive:
        raise UsageError("rate: applies only with --keepalive")
    check_log_options(ids, snapshot, fmt)
    sensors = session_sensors(aux, thrust_from, fuel_flow_from, ambient_temp, ambient_pressure, air_pressure)
    if replay is not None and (sensors.specs or sensors.air):
        raise UsageError(f"{'aux' if sensors.specs else 'air-pressure'}: not with --replay (a recording has no "
                         f"sensors beside it and cannot be answered)")
    stand = build_stand(limit=limit, limits_files=limits_files, on_limit=on_limit, logbook=logbook, sensors=sensors,
                        engine=engine)
    check_output_dir(summary_json, "summary-json", records_to_stdout=output in (None, "-"))
    control = None
    if keepalive:
        frame = zk.encode_control("keepalive")[0]

        def control(t):
            return frame

    if baud == "auto":
        baud, stop_bits = detect_line(url)
    outcome, tel, session = run_telemetry(
        url=url, baud=baud, replay=replay, fast=fast, fmt=fmt, output=output, append=append, snapshot=snapshot,
        ids=ids, stale_after=stale_after, raw_log=raw_log, protocol_version=protocol_version, timeout=timeout,
        stop_bits=stop_bits, count=count, duration=duration, control=control, rate=rate, stand=stand,
        reconnect=reconnect, summarize=summarizer(stand, command="zk monitor", port=url or replay))
    report(stand, command="zk monitor", port=url or replay, files=(output, raw_log), outcome=outcome, tel=tel,
           session=session, summary_json=summary_json)
    if 13 in tel.errors and not keepalive and (tel.decoder.known or 99) < 5:
        note("error 13 (loss of control signal): ECUs before protocol version 5 need a host that keeps "
             "sending; --keepalive does")
    raise_for_status(outcome, stand)
    if fail_on_error and tel.errors:
        raise DeviceError(errors_text(tel))


zk_timeout_help(monitor)


def detect_line(url):
    """``--baud auto`` (monitor, check): the ECU's baud rate and stop bits, found by listening first."""
    from ...api.detect import no_answer
    from .detect import run_detection
    from ...api.detect import BAUDS

    result = run_detection(url, list(BAUDS), (1, 2), None, None, False)
    if not result.found:
        raise no_answer(result)
    extra = ""
    if result.protocol_version is not None:
        extra = f", protocol version {result.protocol_version}, {result.status_rate_hz} Hz"
    note(f"detected {result.baud} baud, {result.stop_bits} stop bit{'s' if result.stop_bits == 2 else ''}"
         f"{extra} on {url} in {result.elapsed:.1f} s")
    return result.baud, result.stop_bits
