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
from .. import CONTEXT, Command
from ..options import note, open_output, port_options, protocol_version_option
from .telemetry import (EXIT_HELP, FORMAT_BY_SUFFIX, check_log_options, errors_text, log_options, port_from_env,
                        resolve_port, zk_timeout_help)


class Output:
    """Where records go: a writer (stdout or -o FILE), and the dashboard on a terminal."""

    def __init__(self, fmt, output, append, snapshot, ids, title, columns_for):
        from ...io.term import is_tty

        path = output if output and output != "-" else None
        if fmt is None and path:
            fmt = FORMAT_BY_SUFFIX.get(os.path.splitext(path)[1].lower(), "jsonl")
        self.stream, had = open_output(output, append)
        if fmt is None:
            fmt = "table" if is_tty(self.stream) else "jsonl"
        self.fmt = fmt
        self.dashboard = None
        self.writer = None
        stdout_tty = is_tty(sys.stdout)
        if fmt == "table" and self.stream is sys.stdout and stdout_tty:
            self.dashboard = _dashboard(title)
        elif path and stdout_tty:
            self.dashboard = _dashboard(title)
        if snapshot is None:
            snapshot = fmt == "csv"
        if fmt == "table" and self.dashboard is not None and self.stream is sys.stdout:
            snapshot = False
        self.snapshot = snapshot
        if self.dashboard is None or self.stream is not sys.stdout:
            from ...io.writers import make_writer

            if fmt == "table":
                self.snapshot = False
                self.writer = make_writer("table", self.stream, [], table_columns=_TABLE_COLUMNS)
                self._table = True
            else:
                self.writer = make_writer(fmt, self.stream, columns_for(self.snapshot, ids), header=not had)
                self._table = False

    def write(self, rec):
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
        if self.writer is not None:
            w, self.writer = self.writer, None
            try:
                w.close()
            except BrokenPipeError:
                pass
        if self.stream is not sys.stdout and not self.stream.closed:
            self.stream.close()


_TABLE_COLUMNS = [("t", "t"), ("id", "id"), ("_summary", "fields"), ("stale", "stale")]
_NOT_FIELDS = {"time", "t", "stale", "stale_ids"}


def _dashboard(title):
    from ...io.dashboard import Dashboard

    return Dashboard(sys.stdout, title)


def run_telemetry(*, url=None, baud=None, replay=None, fast=False, fmt=None, output=None, append=False,
                  snapshot=None, ids=None, stale_after=3, raw_log=None, protocol_version=None, timeout=None,
                  count=None, duration=None, control=None, rate=None, abort="none", stop_on_error=False,
                  abort_at_end=False, title=None, end=None, end_label="end of schedule"):
    """Log status records from a port (or a replay) while optionally sending control frames.

    Returns ``(outcome, telemetry, session)``; the caller raises ``outcome.raise_for_status()``
    after its own reporting. Files are closed (whole) before this returns.
    """
    from ...link import zk_link as L

    id_set = L.parse_ids(ids) if ids is not None else None
    if raw_log == "-":
        raise UsageError("raw-log: '-' is not a file here (stdout carries the records); give a file name")
    out = Output(fmt, output, append, snapshot, id_set, title or f"ZK ECU on {url or replay}", L.record_columns)
    raw = None
    source = None
    # While the dashboard holds the screen, the session's messages (the abort notice...) wait: the
    # view would redraw over them. They go to stderr once it has closed, below the last view.
    held = []
    notify = note if out.dashboard is None else held.append
    if out.dashboard is not None:
        out.dashboard.duration = duration
    try:
        if raw_log:
            try:
                raw = open(raw_log, "ab" if append else "wb")
            except OSError as e:
                raise UsageError(f"raw-log: cannot open {raw_log}: {e.strerror}") from None
        if replay is not None:
            source = L.ReplaySource(replay, fast=fast)
        else:
            # reads block at most half a control period, so frames go out on time up to 200 Hz
            slice_s = min(L.READ_SLICE_S, 0.5 / (rate or L.DEFAULT_RATE)) if control else L.READ_SLICE_S
            source = L.LiveSource(L.ZkLink.open(url, baud, raw_log=raw, slice_s=slice_s))
        tel = L.Telemetry(protocol_version, id_set, out.snapshot, stale_after, wall0=source.wall0,
                          speed=getattr(source, "speed", 1.0))
        session = L.Session(source, tel, out.write, control=control, rate=rate or L.DEFAULT_RATE, abort=abort,
                            count=count, duration=duration,
                            silence=timeout if timeout is not None else L.DEFAULT_SILENCE_S,
                            stop_on_error=stop_on_error, abort_at_end=abort_at_end, end=end, end_label=end_label,
                            on_update=out.update if out.dashboard is not None else None, notify=notify)
        with out:
            outcome = session.run()
    finally:
        if source is not None:
            source.close()
        out.close()
        if raw is not None:
            raw.close()
        for message in held:
            note(message)
    if tel.version_note:
        note(tel.version_note)
    framer = source.framer
    if framer.bad:
        note(f"{framer.bad} status frame{'s' if framer.bad > 1 else ''} with a bad CRC skipped "
             f"({framer.skipped} byte{'' if framer.skipped == 1 else 's'})")
    return outcome, tel, session


@click.command(cls=Command, context_settings=CONTEXT, epilog=EXIT_HELP)
@port_options("zk")
@click.option("--replay", type=click.Path(dir_okay=False, allow_dash=False), metavar="FILE",
              help="Decode a raw log (--raw-log) instead of a port, paced in real time.")
@click.option("--fast", is_flag=True, help="With --replay: as fast as possible.")
@log_options
@click.option("-c", "--count", type=click.IntRange(1), default=None, metavar="N",
              help="Stop after N records.")
@click.option("--duration", type=click.FloatRange(0, min_open=True), default=None, metavar="SECONDS",
              help="Stop after SECONDS.")
@click.option("--keepalive", is_flag=True,
              help="Send keep-alives (ID 0) at --rate: ECUs before protocol version 5 report loss of "
                   "control signal when the host falls silent.")
@click.option("--rate", type=click.FloatRange(1, 200), default=None, metavar="HZ",
              help="Keep-alive rate (default 20 Hz).")
@protocol_version_option
@click.option("--fail-on-error", is_flag=True,
              help="Exit with status 5 if any ECU error code was seen (after writing every record).")
def monitor(port, baud, timeout, sim, replay, fast, fmt, output, append, snapshot, ids, stale_after, raw_log,
            count, duration, keepalive, rate, protocol_version, fail_on_error):
    """Show or log the ECU's status frames as they arrive.

    On a terminal: a live dashboard. In a pipe: JSON Lines, one record per frame (as 'zk decode'
    gives them). CSV (-f csv, or -o FILE.csv) gets snapshot rows: every field's latest value on
    each row, one row per frame. Every record has 'time' (ISO 8601 UTC), 't' (seconds since the
    start), 'stale' and 'stale_ids' (IDs not seen for --stale-after periods). Each record is
    flushed as it is written: Ctrl-C or a vanished port leaves a whole file.

    Voltages are decoded in the ECU's own unit: frames are held back until the first status ID 6
    (the protocol version; at most 12 frames) unless --protocol-version is given.

    A replay's 't' is rebuilt from the status rate the frames report (a raw log holds bytes, not
    times).

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
        if not os.path.isfile(replay):
            raise UsageError(f"replay: cannot read {replay}: no such file")
        url = None
    else:
        if fast:
            raise UsageError("fast: only with --replay")
        url = resolve_port(port, sim)
    if rate is not None and not keepalive:
        raise UsageError("rate: applies only with --keepalive")
    check_log_options(ids, snapshot, fmt)
    control = None
    if keepalive:
        frame = zk.encode_control("keepalive")[0]

        def control(t):
            return frame

    outcome, tel, _ = run_telemetry(
        url=url, baud=baud, replay=replay, fast=fast, fmt=fmt, output=output, append=append, snapshot=snapshot,
        ids=ids, stale_after=stale_after, raw_log=raw_log, protocol_version=protocol_version, timeout=timeout,
        count=count, duration=duration, control=control, rate=rate)
    if 13 in tel.errors and not keepalive and (tel.decoder.known or 99) < 5:
        note("error 13 (loss of control signal): ECUs before protocol version 5 need a host that keeps "
             "sending; --keepalive does")
    outcome.raise_for_status()
    if fail_on_error and tel.errors:
        raise DeviceError(errors_text(tel))


zk_timeout_help(monitor)
