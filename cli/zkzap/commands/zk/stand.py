"""Test-stand options shared by ``zk monitor``, ``zk send --for``, ``zk profile`` and ``zk check``:
limits (``--limit``, ``--limits``, ``--on-limit``) and the engine logbook (``--logbook``).

The logic lives in :mod:`zkzap.api.limits`, :mod:`zkzap.api.logbook` and :mod:`zkzap.api.stand`;
this module turns options into a :class:`~zkzap.api.stand.Stand` (everything checked before a port
opens) and reports on it afterwards.
"""

from __future__ import annotations

import click

from ...errors import UsageError
from ..options import Choice, FiniteRange, InputPath, OutputPath, apply_options, note

LIMIT_HELP = ("Stop when a status field leaves a limit: FIELD OP NUMBER with OP one of < <= > >= == != "
              "and an optional warning band (egt_c<=850,warn=800; power_voltage_v>=7.2; error_code==0). "
              "Evaluated on every frame that carries the field. FIELD may be an --aux sensor's field or a "
              "corrected value, FIELD/s its change per second (egt_c/s<=60), and ,when=running (start, "
              "cooling, a state's name; a|b) limits it to those engine states. Repeatable.")


#: The finite float range every float option uses (one definition, in the options module).
Finite = FiniteRange


def limit_options(f):
    opts = [
        click.option("--limit", "limit", multiple=True, metavar="EXPR", help=LIMIT_HELP),
        click.option("--limits", "limits_files", multiple=True, type=InputPath("limits"), metavar="FILE",
                     help="Read limits from FILE: one EXPR per line, '#' comments. Repeatable."),
        click.option("--on-limit", type=Choice(["abort", "exit", "warn"]), default=None,
                     help="On a violated limit: abort or exit end the session with exit 5 (one that "
                          "controls the engine ends with the --abort command either way, as every end "
                          "does; abort is for such sessions only), warn goes on to the run's end (the summary "
                          "names it) and then exits 5 too: a run whose limits were violated is never a clean "
                          "run to a script."),
    ]
    return apply_options(f, opts)


ALARM_HELP = {
    "restart_egt": "After a trip a start waits for the ECU's stop or standby with the rotor stopped and EGT below DEGC "
                   "(default 150; in a shell, a batch and the browser console, where sessions follow one another).",
    "hung_start": "A start still in ignition, preheat, the fuel ramp or restart after S seconds is a hung start: an "
                  "alarm, and a session that controls the engine ends with its abort, exit 5 (default 90; 0: not "
                  "watched).",
    "hot_start": "EGT above DEGC during ignition, preheat or the fuel ramp is a hot start: an alarm, and a session "
                 "that controls the engine ends with its abort, exit 5 (default 850; 0: not watched).",
}


def alarm_options(f):
    """The start watches and the restart rule of the stand's alarms (zkzap.api.alarms)."""
    opts = [
        click.option("--restart-egt", type=FiniteRange(0, 1000), default=None, metavar="DEGC",
                     help=ALARM_HELP["restart_egt"]),
        click.option("--hung-start", type=FiniteRange(0, 3600), default=None, metavar="S",
                     help=ALARM_HELP["hung_start"]),
        click.option("--hot-start", type=FiniteRange(0, 2000), default=None, metavar="DEGC",
                     help=ALARM_HELP["hot_start"]),
    ]
    return apply_options(f, opts)


def alarm_settings(restart_egt=None, hung_start=None, hot_start=None) -> dict:
    """The options given, as :class:`~zkzap.api.alarms.Alarms` keywords."""
    return {k: v for k, v in (("restart_egt_c", restart_egt), ("hung_start_s", hung_start),
                              ("hot_start_egt_c", hot_start)) if v is not None}


def logbook_option(f):
    opts = [
        click.option("--logbook", type=OutputPath("database"), default=None, metavar="FILE",
                     help="Record the run in the engine logbook FILE (SQLite; 'zk logbook FILE' lists "
                          "runs and totals)."),
        click.option("--engine", default=None, metavar="NAME",
                     help="The engine this session runs (its logbook entry and the summary name it; "
                          "'zk logbook FILE --engine NAME' gives its hours, starts and fuel)."),
    ]
    return apply_options(f, opts)


SENSOR_HELP = {
    "aux": "Read an external sensor (load cell, flowmeter, barometer) from SOURCE: a serial port or URL "
           "(9600 baud, or SOURCE@BAUD), a FIFO, a file (followed as it grows) or '-', optionally declared: "
           "SOURCE,KEY[:UNIT][:LO..HI],...[,stale=S][,format=pairs|csv|json], or a sensors file (.toml, .yaml) "
           "with channels, ranges and calibration. Lines of name=value pairs, CSV with a header, or JSON objects; "
           "lines that are no reading are skipped, values that are no finite number, out of range or given twice "
           "are rejected (both counted in the summary). Repeatable.",
    "thrust": "Use this --aux field as the thrust (FIELD:UNIT, UNIT kgf, kg, N, daN, lbf or g; or implied by the "
              "name: load_n) for TSFC and the corrections instead of the ECU's 0.1 kg reading.",
    "flow": "Use this --aux field as the fuel flow (FIELD:UNIT, UNIT L/min, mL/min, cc/min, L/h, kg/h, g/min or "
            "g/s; or implied by the name: flow_ml_min) for TSFC and the corrections.",
    "temp": "Ambient temperature, degC (or an --aux FIELD[:UNIT], UNIT C, K, F): adds the standard-day corrected "
            "values N/sqrt(theta), F/delta, Wf/(delta*sqrt(theta)) and TSFC, theta = T/288.15 K.",
    "pressure": "Ambient pressure for the corrections, hPa (or an --aux FIELD[:UNIT], UNIT hPa, mbar, Pa, kPa, "
                "bar, psi, inHg); default: the ECU's own air pressure (status ID 3). delta = p/1013.25 hPa.",
    "air": "Answer the ECU's request for the air pressure (status ID 8's ESR bit) with control ID 8: HPA, or "
           "an --aux barometer FIELD[:UNIT]. Sent when ESR is seen, at most once a second while it stays set.",
}


def sensor_options(f):
    """External sensors, standard-day corrections and the ESR answer (monitor, send --for, profile)."""
    opts = [
        click.option("--aux", "aux", multiple=True, metavar="SOURCE", help=SENSOR_HELP["aux"]),
        click.option("--thrust-from", default=None, metavar="FIELD[:UNIT]", help=SENSOR_HELP["thrust"]),
        click.option("--fuel-flow-from", default=None, metavar="FIELD[:UNIT]", help=SENSOR_HELP["flow"]),
        click.option("--ambient-temp", default=None, metavar="DEGC|FIELD", help=SENSOR_HELP["temp"]),
        click.option("--ambient-pressure", default=None, metavar="HPA|FIELD", help=SENSOR_HELP["pressure"]),
        click.option("--air-pressure", default=None, metavar="HPA|FIELD", help=SENSOR_HELP["air"]),
    ]
    return apply_options(f, opts)


class Sensors:
    """The sensor options, parsed and checked before anything opens."""

    def __init__(self, aux=(), thrust_from=None, fuel_flow_from=None, ambient_temp=None, ambient_pressure=None,
                 air_pressure=None):
        from ...api.ambient import Quantity
        from ...api.aux import parse_specs

        self.specs = parse_specs(aux, taken=_record_keys())
        units = {c.name: c.unit for s in self.specs for c in s.decl.channels or () if c.unit}
        self.thrust = (Quantity.parse(thrust_from, "thrust", "thrust-from", constant=False, declared=units)
                       if thrust_from else None)
        self.flow = (Quantity.parse(fuel_flow_from, "fuel_flow", "fuel-flow-from", constant=False, declared=units)
                     if fuel_flow_from else None)
        temp = (Quantity.parse(ambient_temp, "temperature", "ambient-temp", declared=units)
                if ambient_temp is not None else None)
        press = (Quantity.parse(ambient_pressure, "pressure", "ambient-pressure", declared=units)
                 if ambient_pressure is not None else None)
        self.air = (Quantity.parse(air_pressure, "pressure", "air-pressure", declared=units)
                    if air_pressure is not None else None)
        if press is not None and temp is None:
            raise UsageError("ambient-pressure: the corrections need --ambient-temp too (theta = T/288.15 K)")
        if temp is not None and temp.field is None and not -60 <= temp.value <= 60:
            raise UsageError(f"ambient-temp: {temp.value:g} is out of range; allowed -60..60 degC (or an --aux "
                             f"field)")
        for q in (press, self.air):
            if q is not None and q.field is None and not 300 <= q.value <= 1100:
                raise UsageError(f"{q.option}: {q.value:g} is out of range; allowed 300..1100 hPa (or an --aux "
                                 f"field)")
        self.ambient = (temp, press) if temp is not None else None
        for q in (self.thrust, self.flow, temp, press, self.air):
            if q is not None and q.field is not None and not self.specs:
                raise UsageError(f"{q.option}: {q.field} is a field of an external sensor: give --aux SOURCE")

    def __bool__(self):
        return bool(self.specs or self.ambient or self.air)

    def given(self) -> dict:
        """The options given, by their spelling (for 'not with' and 'only with' messages)."""
        return {k: v for k, v in (("aux", self.specs), ("thrust-from", self.thrust), ("fuel-flow-from", self.flow),
                                  ("ambient-temp", self.ambient), ("air-pressure", self.air)) if v}


def session_sensors(aux, thrust_from, fuel_flow_from, ambient_temp, ambient_pressure, air_pressure, *,
                    averaging=False, steps=False) -> Sensors:
    """The sensor options of a session; --thrust-from/--fuel-flow-from need something that uses
    them: the corrections, or (``steps``: zk profile) the step averages (``averaging``)."""
    sensors = Sensors(aux, thrust_from, fuel_flow_from, ambient_temp, ambient_pressure, air_pressure)
    for q in (sensors.thrust, sensors.flow):
        if q is not None and sensors.ambient is None and not averaging:
            raise UsageError(f"{q.option}: applies with --ambient-temp (the corrected values)"
                             + (" or the step averages (--settle, --average, --steps-csv)" if steps else ""))
    return sensors


#: Record keys an external sensor's field must not shadow (it gets the prefix aux_).
def _record_keys():
    from ...api.ambient import RecordCorrections
    from ...codec import zk

    return set(zk.STATUS_KEYS) | {"time", "t", "kind", "id", "frame", "payload", "stale", "stale_ids", "warnings",
                                  "limit", "reserved", "out_of_range"} | set(RecordCorrections.KEYS)


def summary_option(f):
    return click.option("--summary-json", type=OutputPath("document"), default=None, metavar="FILE",
                        help="Write the run's summary (frames, max rpm and EGT, fuel, states, errors, each "
                             "limit's verdict, extreme value and first violation) as JSON to FILE ('-': stdout).")(f)


def check_output_dir(path, what, records_to_stdout=False):
    """Refuse an output file that cannot be written (a directory, a missing directory, no
    permission), before the run (and ``-`` when the records already go to stdout)."""
    if path == "-" and records_to_stdout:
        raise UsageError(f"{what}: '-' needs -o FILE for the records (both would go to stdout)")
    if not path or path == "-":
        return
    from ...outfile import check_path

    check_path(path, what)


def session_summary(*, command, port, outcome, tel, session, stand) -> dict:
    """The run summary of ``zk monitor`` and ``zk send --for`` (``--summary-json``, a workbook's
    summary sheet)."""
    out = {"command": command, "port": port, "outcome": outcome.reason,
           "exit_status": stand.exit_status(outcome) if stand is not None else outcome.exit_code,
           "aborted": outcome.aborted, "duration_s": round(session.ended_t or 0.0, 3),
           "crc_errors": session.source.framer.bad}
    out.update(tel.summary())
    out.update(stand_entries(session, stand))
    return out


def stand_entries(session, stand) -> dict:
    """The stand session's entries of a run summary (its hooks' and the alarm list), or the
    hooks' alone for a session that ran without one."""
    ss = getattr(session, "stand_session", None)
    if ss is not None:
        return ss.summary()
    return stand.summary() if stand is not None else {}


def summarizer(stand, *, command, port):
    """``summarize`` for :func:`.monitor.run_telemetry`: no steps, the session's summary."""
    return lambda outcome, tel, session: (None, session_summary(command=command, port=port, outcome=outcome,
                                                                tel=tel, session=session, stand=stand))


def write_summary(path, *, command, port, outcome, tel, session, stand):
    """The run summary as JSON (``-``: stdout)."""
    from ...io.writers import dumps

    out = session_summary(command=command, port=port, outcome=outcome, tel=tel, session=session, stand=stand)
    text = dumps(out, indent=2) + "\n"
    if path == "-":
        click.echo(text, nl=False)
        return
    from ...outfile import write_whole

    write_whole(path, text, what="summary-json")


def _limit_fields(sensors):
    """What a limit may name: a status key; a corrected value (with --ambient-temp); with --aux
    any name, checked against the sensors' fields once their first lines came."""
    from ...api.ambient import RecordCorrections
    from ...api.limits import FIELDS

    if sensors.specs:
        return None
    if sensors.ambient is not None:
        return FIELDS | set(RecordCorrections.KEYS)
    return FIELDS


def build_stand(*, limit=(), limits_files=(), on_limit=None, logbook=None, controls=False, averager=None,
                force=False, sensors=None, engine=None, density=None, alarms=None):
    """A Stand for these options (None when none applies); raises UsageError (exit 2) first."""
    from ...api import limits as L
    from ...api.stand import Stand

    sensors = sensors or Sensors()
    conditions = L.read_limits(limit, limits_files, fields=_limit_fields(sensors))
    if on_limit is not None and not conditions:
        raise UsageError("on-limit: give --limit EXPR or --limits FILE with it")
    if on_limit == "abort" and not controls:
        raise UsageError("on-limit: abort: this session does not control the engine; use exit or warn")
    if on_limit is None:
        on_limit = "abort" if controls else "exit"
    if logbook == "-":
        raise UsageError("logbook: a file is needed ('-' is not a database)")
    if logbook:
        from ...api import logbook as lb

        lb.check_writable(logbook)
    if engine is not None and not engine.strip():
        raise UsageError("engine: an empty name; give the engine's name or serial (--engine K100-1234)")
    if (not conditions and not logbook and averager is None and not force and not sensors and engine is None
            and not alarms):
        return None
    aux = corrections = answer = None
    if sensors.specs:
        from ...api.aux import AuxHub

        aux = AuxHub(sensors.specs, taken=_record_keys(), notify=note)
    if sensors.ambient is not None:
        from ...api.ambient import RecordCorrections

        corrections = RecordCorrections(*sensors.ambient, thrust=sensors.thrust, flow=sensors.flow,
                                        density=density or 0.8)
    if sensors.air is not None:
        from ...api.esr import PressureAnswer

        q = sensors.air
        if q.field is None:
            def pressure(t):
                return q.value
        else:
            def pressure(t):
                return q.convert(aux.value(q.field, t))
        answer = PressureAnswer(pressure, q.describe(), notify=note)
        answer.quantity = q
    stand = Stand(L.LimitSet(conditions, on_limit, notify=note) if conditions else None, averager, logbook,
                  aux=aux, corrections=corrections, answer=answer, engine=engine.strip() if engine else None)
    stand.alarm_settings = dict(alarms or {})       # --restart-egt, --hung-start, --hot-start
    return stand


def raise_for_status(outcome, stand) -> None:
    """After the reporting: the outcome's exit status, or (``--on-limit warn``) exit 5 for a run
    that went on through a violated limit: a script never takes it for a clean run."""
    outcome.raise_for_status()
    err = stand.warned_violation(outcome) if stand is not None else None
    if err is not None:
        raise err


def report(stand, *, command, port, schedule=None, files=(), outcome, tel, session, quiet=False, summary_json=None):
    """After a run: the limits summary on stderr, the logbook entry and the ``--summary-json`` file."""
    if summary_json:
        write_summary(summary_json, command=command, port=port, outcome=outcome, tel=tel, session=session,
                      stand=stand)
    if stand is None:
        return
    if stand.limits is not None and not quiet:
        from ...api.limits import summary_lines

        click.echo("limits:\n" + "\n".join(summary_lines(stand.limits.summary())), err=True)
    ss = getattr(session, "stand_session", None)
    if ss is not None:
        run_id = ss.log_run(command=command, port=port, schedule=schedule, files=files, outcome=outcome)
    else:
        run_id = stand.log_run(command=command, port=port, schedule=schedule, files=files, outcome=outcome, tel=tel,
                               session=session)
    if run_id is not None:
        note(f"logbook {stand.logbook}: run {run_id} recorded")
