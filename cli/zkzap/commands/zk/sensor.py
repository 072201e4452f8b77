"""``zk sensor``: an external sensor of the stand on its own — its live values (``read``), its
tare (``tare``) and its calibration against known references (``calibrate``), written into the
sensors file that ``--aux FILE`` reads."""

from __future__ import annotations

import click

from ...errors import NO_REPLY, OK, OUTPUT_ERROR, PORT_ERROR, USAGE, UsageError
from .. import CONTEXT, Command, Group
from ..options import FiniteRange, InputPath, IntRange, exits, format_option, note

_TIMEOUT = click.option("--timeout", type=FiniteRange(0, 3600, min_open=True), default=2.0, show_default=True,
                        metavar="SECONDS", help="Wait this long for the sensor's first reading.")
_PICK = [click.option("--sensor", "sensor_name", default=None, metavar="NAME|N",
                      help="The sensor of the file (its name, or its number from 1) when it declares several."),
         click.option("--channel", default=None, metavar="NAME",
                      help="The channel (when the sensor declares several).")]
_AVERAGE = click.option("--average", type=FiniteRange(0, 600, min_open=True), default=3.0, show_default=True,
                        metavar="SECONDS", help="Average each measurement over this long.")
_SETTLE = click.option("--settle", type=FiniteRange(0, 600), default=0.5, show_default=True, metavar="SECONDS",
                       help="Wait this long before each measurement (the lines still on their way are not of it).")


class PointType(click.ParamType):
    """``REF`` or ``REF=RAW``: a calibration point, finite numbers -> ``(ref, raw or None)``."""

    name = "point"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        import math

        ref, eq, raw = str(value).partition("=")
        try:
            got = (float(ref), float(raw) if eq else None)
        except ValueError:
            self.fail(f"{value!r}: REF or REF=RAW, numbers", param, ctx)
        if not all(v is None or math.isfinite(v) for v in got):
            self.fail(f"{value!r}: not a finite number", param, ctx)
        return got


def _pick(f):
    for opt in reversed(_PICK):
        f = opt(f)
    return f


@click.group(cls=Group, context_settings=CONTEXT)
def sensor():
    """An external sensor of the stand on its own: read, tare, calibrate.

    The sensor is given as --aux takes it: a source (serial port or URL, FIFO, file, '-') with
    its declared channels, or a sensors file (.toml, .yaml). tare and calibrate write the
    calibration into the sensors file, with the date and the readings it was computed from;
    a run with --aux FILE then uses it and records it in its summary.
    """


@exits({OK: "read until --duration, --count or the source's end", NO_REPLY: "no reading within --timeout",
        PORT_ERROR: "the sensor's port cannot be opened or failed"})
@sensor.command(cls=Command, context_settings=CONTEXT)
@click.argument("source", metavar="SOURCE|FILE", type=InputPath("sensors"))
@click.option("--duration", type=FiniteRange(0, min_open=True), default=None, metavar="SECONDS",
              help="Stop after SECONDS (default: at Ctrl-C or the source's end).")
@click.option("-c", "--count", type=IntRange(1), default=None, metavar="N", help="Stop after N readings.")
@click.option("--raw", is_flag=True, help="The raw readings: no calibration, no range check.")
@_TIMEOUT
@format_option()
def read(source, duration, count, raw, timeout, fmt):
    """Show a sensor's live values, to check its wiring, format and calibration.

    One row per reading (a file is read to its end, or followed as it grows for --duration): the time (s since the start), each channel's calibrated value (and its
    raw reading, when calibrated) and what was rejected; at the end the sensor's counts (lines,
    skipped, rejected) on stderr.

    \b
    Examples:
      zk sensor read /dev/ttyUSB1@115200
      zk sensor read '/dev/ttyUSB1@115200,thrust_n:N:-50..2000' --count 20
      zk sensor read stand.toml --duration 10 -f csv > check.csv
    """
    from ...api.sensors import Probe, parse_decl
    from ..options import write_rows

    decls = parse_decl(source)
    probe = Probe(decls, timeout=timeout, raw=raw, notify=note, follow=duration is not None)
    try:
        names = list(probe.hub.fields)
        calibrated = [k for k in names if probe.hub.channels[k].calibration is not None]
        cols = ["t", "sensor"] + [c for k in names for c in ((k, f"{k}_raw") if k in calibrated else (k,))]
        cols.append("rejected")

        def rows():
            for t, reading in probe.readings(duration=duration, count=count):
                row = {"t": round(t, 3), "sensor": decls[0].label if len(decls) == 1 else None}
                row.update(reading.values)
                row.update({f"{k}_raw": v for k, v in reading.raw.items()})
                row["rejected"] = "; ".join(f"{k}: {why} ({text})" for k, why, text in reading.rejected) or None
                yield row

        try:
            write_rows(rows(), cols, fmt)
        finally:
            probe.close()
            for s in probe.summary():
                note(_counts(s))
    finally:
        probe.close()


def _counts(s):
    out = (f"{s['sensor']}: {s['lines']} lines, {s['readings']} readings, {s['skipped']} skipped, "
           f"{s['rejected']} values rejected")
    for c in s["channels"]:
        if c["rejected"]:
            out += f"; {c['name']}: " + ", ".join(f"{n} {why}" for why, n in c["rejected"].items())
    if s["ignored"]:
        out += f"; not declared: {', '.join(s['ignored'])}"
    return out


def _target(path, sensor_name, channel):
    """(decl, channel) of the sensors file ``path``."""
    from ...api.sensors import load_file

    if not path.lower().endswith((".toml", ".yaml", ".yml")):
        raise UsageError(f"sensors file: {path}: a calibration is written into a sensors file (.toml, .yaml) "
                         f"that declares the sensor and its channels")
    decls = load_file(path)
    if sensor_name is None:
        if len(decls) > 1:
            raise UsageError(f"sensor: {path} declares {len(decls)} sensors ({', '.join(d.label for d in decls)}); "
                             f"give --sensor NAME or N")
        decl = decls[0]
    else:
        found = [d for i, d in enumerate(decls) if d.label == sensor_name or str(i + 1) == sensor_name]
        if not found:
            from ...errors import unknown_name

            raise unknown_name("sensor", sensor_name, [d.label for d in decls], noun="sensor")
        decl = found[0]
    chans = decl.channels or []
    if not chans:
        raise UsageError(f"sensor: {decl.label} declares no channel in {path}; declare the one to calibrate")
    if channel is None:
        if len(chans) > 1:
            raise UsageError(f"channel: {decl.label} has {len(chans)} channels ({', '.join(c.name for c in chans)}); "
                             f"give --channel NAME")
        return decl, chans[0]
    c = decl.channel(channel)
    if c is None:
        from ...errors import unknown_name

        raise unknown_name("channel", channel, [c.name for c in chans], noun="channel")
    return decl, c


def _now():
    import datetime

    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def _unit(c):
    return f" {c.unit}" if c.unit else ""


_WRITE_EXITS = {OK: "measured and written into the sensors file", USAGE: "bad usage, or no valid reading",
                NO_REPLY: "no reading within --timeout", PORT_ERROR: "the sensor's port cannot be opened or failed",
                OUTPUT_ERROR: "the sensors file could not be written"}


@exits(_WRITE_EXITS)
@sensor.command(cls=Command, context_settings=CONTEXT)
@click.argument("sensors_file", metavar="FILE", type=InputPath("sensors"))
@_pick
@_AVERAGE
@_SETTLE
@_TIMEOUT
def tare(sensors_file, sensor_name, channel, average, settle, timeout):
    """Measure a channel's zero (its raw reading with no load) and write it as the tare.

    The raw readings over --average seconds are averaged; the calibration's scale or curve is
    kept (its points are over the raw reading minus the tare). The file gets the tare and the
    date.

    \b
    Examples:
      zk sensor tare stand.toml
      zk sensor tare stand.toml --sensor 'load cell' --channel thrust_n --average 5
    """
    from ...api.sensors import Calibration, Probe, write_calibration

    decl, c = _target(sensors_file, sensor_name, channel)
    old = c.calibration or Calibration()
    probe = Probe([decl], timeout=timeout, raw=True, notify=note)
    try:
        got = probe.measure(c.name, average, settle)
    finally:
        probe.close()
    new = Calibration(got["mean"], old.scale, old.points, _now(), measured=old.measured)
    write_calibration(sensors_file, decl.index, c.name, new)
    note(f"{sensors_file}: {c.name} tare {got['mean']:.6g}{_unit(c)} raw (mean of {got['n']} readings, std "
         f"{got['std']:.3g}), written {new.date}")


@exits(_WRITE_EXITS)
@sensor.command(cls=Command, context_settings=CONTEXT)
@click.argument("sensors_file", metavar="FILE", type=InputPath("sensors"))
@click.option("--point", "points", multiple=True, required=True, metavar="REF[=RAW]", type=PointType(),
              help="A reference value in the channel's unit (a known weight, a measured flow): apply it, press "
                   "Enter, and the raw reading is averaged; REF=RAW gives the raw reading instead. One point sets "
                   "the scale, two or more a curve. Repeatable.")
@_pick
@_AVERAGE
@_SETTLE
@_TIMEOUT
def calibrate(sensors_file, points, sensor_name, channel, average, settle, timeout):
    """Calibrate a channel against known references and write the calibration.

    For each --point REF the command asks (on stderr) for that reference to be applied and
    waits for a line on standard input (Enter on a terminal), then averages the raw reading
    over --average seconds. Over the tare (zk sensor tare), one point gives the scale
    REF / (raw - tare), two or more the curve through the points. The file gets the scale or
    the curve, the date and the measured points [raw, REF].

    \b
    Examples:
      zk sensor tare stand.toml
      zk sensor calibrate stand.toml --point 98.0665               # a 10 kg weight, in N
      zk sensor calibrate stand.toml --point 0 --point 49.03 --point 98.0665
      zk sensor calibrate stand.toml --point 98.0665=1002.4       # a reading taken before
    """
    import sys

    from ...api.sensors import Probe, solve, write_calibration

    decl, c = _target(sensors_file, sensor_name, channel)
    refs = list(points)
    if len({r for r, _ in refs}) != len(refs):
        raise UsageError("point: a reference is given twice")
    tare_raw = c.calibration.tare if c.calibration is not None else 0.0
    probe = None
    measured = []
    try:
        for n, (ref, raw) in enumerate(refs, 1):
            if raw is None:
                if probe is None:
                    probe = Probe([decl], timeout=timeout, raw=True, notify=note)
                click.echo(f"point {n}: apply {ref:g}{_unit(c)} to {c.name}, then press Enter", err=True)
                if not sys.stdin.readline():
                    raise UsageError(f"point: standard input ended before point {n} ({ref:g}); nothing written")
                got = probe.measure(c.name, average, settle)
                raw = got["mean"]
                note(f"point {n}: {ref:g}{_unit(c)} = raw {raw:.6g} (mean of {got['n']} readings, std {got['std']:.3g})")
            measured.append((raw, ref))
    finally:
        if probe is not None:
            probe.close()
    cal = solve(tare_raw, measured)
    cal.date = _now()
    write_calibration(sensors_file, decl.index, c.name, cal)
    what = f"scale {cal.scale:.6g}" if not cal.points else f"a curve of {len(cal.points)} points"
    note(f"{sensors_file}: {c.name} calibrated: tare {cal.tare:.6g}, {what}, written {cal.date}")
