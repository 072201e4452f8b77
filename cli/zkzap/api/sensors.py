"""Declared external sensors: their channels, plausibility ranges, staleness and calibration.

A sensor beside the ECU (a load cell, a flowmeter, a barometer) is a source of text lines
(:mod:`zkzap.api.aux` reads them). It can be declared, so that what it sends is checked before
it becomes a number of the run:

- on the command line, ``--aux SOURCE[@BAUD][,ITEM...]``, each ITEM one of ``format=pairs|csv|json``,
  ``stale=SECONDS``, ``name=LABEL`` or a channel ``KEY[:UNIT][:LO..HI]`` (``thrust_n:N:-50..2000``);
- in a sensors file (TOML or YAML, read by :mod:`zkzap.api.documents`), ``--aux sensors.toml``::

      [[sensor]]
      name = "load cell"
      source = "/dev/ttyUSB1@115200"
      format = "pairs"           # pairs, csv, json or auto (the default: found from the lines)
      stale_s = 1.0              # the default of its channels (2 s)

      [[sensor.channel]]
      name = "thrust_n"          # the record key; the key in the sensor's lines unless key = "..."
      unit = "N"
      range = [-50, 2000]        # plausible calibrated values; others are rejected
      calibration = { tare = 0.12, scale = 1.0, date = "2026-12-03T13:00:00Z" }

A declared sensor gives only its channels (other keys of its lines are ignored and listed); an
undeclared one (``--aux SOURCE``) gives every key it sends, with no range and the default
staleness. Either way a value is a finite number, or it is rejected and counted, never stored.

**Calibration.** A channel's value is ``(raw - tare) * scale``, or, with a curve of two or more
points ``(x, value)`` (x = raw - tare), the straight lines between the points, extended along the
first and the last segment beyond them. ``zk sensor tare`` measures the tare (the raw reading
with no load) and ``zk sensor calibrate`` the scale (one point) or the curve (two or more), and
writes them into the sensors file with the date and the points (:func:`write_calibration`); a
run records the calibration it used in its summary.

**Staleness** is judged in session time (model seconds on a sped-up simulator): a channel with no
valid value for more than its ``stale_s`` is blank in the records until the sensor sends again.
Nothing here imports click, rich or pyserial.
"""

from __future__ import annotations

import math
import re

from ..errors import UsageError

#: A channel without a valid value for longer than this (session seconds) is stale.
DEFAULT_STALE_S = 2.0
#: Line formats: ``auto`` finds the format from the first reading.
FORMATS = ("auto", "pairs", "csv", "json")
#: Suffixes of a sensors file (``--aux FILE``).
FILE_SUFFIXES = (".toml", ".yaml", ".yml")
_RANGE = re.compile(r"^\s*([-+]?[\d.eE+-]+)\s*\.\.\s*([-+]?[\d.eE+-]+)\s*$")


def field_name(name, taken=frozenset()) -> str:
    """A sensor's key as a record key: lower case, ``[a-z0-9_]``; ``aux_`` before a name that is a
    record key already."""
    key = re.sub(r"[^a-z0-9_]", "_", str(name).strip().lower()) or "field"
    if key[0].isdigit():
        key = "_" + key
    return f"aux_{key}" if key in taken else key


def _number(value, what):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        try:
            value = float(str(value).strip())
        except ValueError:
            raise UsageError(f"{what}: {value!r} is not a number") from None
    if not math.isfinite(value):
        raise UsageError(f"{what}: {value!r} is not a finite number")
    return float(value)


class Calibration:
    """``(raw - tare) * scale``, or a curve through ``points`` ``[(x, value)]`` (x = raw - tare,
    at least two, x strictly increasing) extended along its end segments. ``date`` (ISO 8601)
    and ``source`` (the file it was read from) say where it came from."""

    def __init__(self, tare=0.0, scale=1.0, points=(), date=None, what="calibration", measured=()):
        self.tare = _number(tare, f"{what}: tare")
        self.scale = _number(scale, f"{what}: scale")
        if self.scale == 0:
            raise UsageError(f"{what}: scale 0 would make every reading 0")
        pts = []
        for p in points or ():
            if not isinstance(p, (list, tuple)) or len(p) != 2:
                raise UsageError(f"{what}: points: {p!r}; each point is [x, value]")
            pts.append((_number(p[0], f"{what}: point"), _number(p[1], f"{what}: point")))
        pts.sort()
        if len(pts) == 1:
            raise UsageError(f"{what}: points: one point is a scale (give scale = value / x), a curve needs two")
        for (a, _), (b, _) in zip(pts, pts[1:]):
            if b <= a:
                raise UsageError(f"{what}: points: x {a:g} is given twice; each point needs its own raw reading")
        if pts and points and scale != 1.0:
            raise UsageError(f"{what}: a curve (points) and a scale: give one of them")
        self.points = pts
        self.date = None if date is None else str(date)
        #: the readings it was computed from, ``[(raw, reference)]`` (``zk sensor calibrate``)
        self.measured = [(_number(a, f"{what}: measured"), _number(b, f"{what}: measured"))
                         for a, b in (measured or ())]

    @classmethod
    def from_doc(cls, doc, what="calibration"):
        if doc is None:
            return None
        if not isinstance(doc, dict):
            raise UsageError(f"{what}: a table of tare, scale, points and date")
        unknown = set(doc) - {"tare", "scale", "points", "date", "measured"}
        if unknown:
            raise UsageError(f"{what}: unknown key {sorted(unknown)[0]!r}; allowed tare, scale, points, date, measured")
        measured = doc.get("measured") or []
        if not isinstance(measured, list) or not all(isinstance(m, list) and len(m) == 2 for m in measured):
            raise UsageError(f"{what}: measured: a list of [raw, reference]")
        return cls(doc.get("tare", 0.0), doc.get("scale", 1.0), doc.get("points") or (), doc.get("date"), what,
                   measured)

    def apply(self, raw: float) -> float:
        """The calibrated value of a raw reading."""
        x = raw - self.tare
        pts = self.points
        if not pts:
            return x * self.scale
        i = 1
        while i < len(pts) - 1 and x > pts[i][0]:
            i += 1
        (x0, y0), (x1, y1) = pts[i - 1], pts[i]
        return y0 + (x - x0) * (y1 - y0) / (x1 - x0)

    @property
    def identity(self) -> bool:
        return self.tare == 0 and self.scale == 1 and not self.points

    def as_doc(self) -> dict:
        """The calibration as a sensors file and a summary hold it."""
        out = {"tare": self.tare}
        if self.points:
            out["points"] = [list(p) for p in self.points]
        else:
            out["scale"] = self.scale
        if self.date:
            out["date"] = self.date
        if self.measured:
            out["measured"] = [list(m) for m in self.measured]
        return out


class Channel:
    """One declared (or found) value of a sensor: ``name`` (the record key), ``key`` (as in the
    sensor's lines, normalized), ``unit``, plausibility range ``lo``..``hi`` (of the calibrated
    value; None: unbounded), ``stale_s`` (session seconds), ``calibration`` (None: the raw value)."""

    def __init__(self, name, key=None, unit=None, lo=None, hi=None, stale_s=DEFAULT_STALE_S, calibration=None,
                 declared=True):
        self.name, self.key = name, key or name
        self.unit = unit or None
        self.lo, self.hi = lo, hi
        self.stale_s = stale_s
        self.calibration = calibration
        self.declared = declared

    def check(self, raw):
        """``(value, None)`` for a raw number, or ``(None, reason)`` when it is rejected."""
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            return None, "not a number"
        if not math.isfinite(raw):
            return None, "not a finite number"
        value = raw if self.calibration is None else self.calibration.apply(raw)
        if (self.lo is not None and value < self.lo) or (self.hi is not None and value > self.hi):
            return None, f"outside {self.range_text()}"
        if self.calibration is not None:
            value = round(value, 6)
        return value, None

    def range_text(self) -> str:
        lo = "" if self.lo is None else f"{self.lo:g}"
        hi = "" if self.hi is None else f"{self.hi:g}"
        return f"{lo}..{hi}" + (f" {self.unit}" if self.unit else "")

    def describe(self) -> dict:
        """The channel as the summary records it (with the calibration it used)."""
        out = {"name": self.name, "key": self.key, "unit": self.unit,
               "range": None if self.lo is None and self.hi is None else [self.lo, self.hi], "stale_s": self.stale_s}
        if self.calibration is not None:
            out["calibration"] = self.calibration.as_doc()
        return out


def _range(text, what):
    m = _RANGE.match(text)
    if not m:
        return None
    lo, hi = _number(m.group(1), what), _number(m.group(2), what)
    if lo > hi:
        raise UsageError(f"{what}: range {text}: the low end is above the high end")
    return lo, hi


def _stale(value, what):
    v = _number(value, f"{what}: stale")
    if not 0 < v <= 86400:
        raise UsageError(f"{what}: stale {value}: allowed above 0 up to 86400 s")
    return v


class SensorDecl:
    """A declared sensor: where it is read (``source``, an :class:`~zkzap.api.aux.Spec` text),
    its ``format``, ``label``, ``channels`` (None: every key it sends) and where it was declared
    (``file``, ``index`` in the file's list of sensors: where a calibration is written)."""

    def __init__(self, source, fmt="auto", channels=None, label=None, stale_s=DEFAULT_STALE_S, file=None, index=None):
        self.source, self.format, self.channels = source, fmt, channels
        self.label = label or source
        self.stale_s = stale_s
        self.file, self.index = file, index

    def channel(self, name):
        for c in self.channels or ():
            if c.name == name or c.key == name:
                return c
        return None


def _channel_item(text, what, stale_s, taken):
    parts = text.split(":")
    name = parts[0].strip()
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", name):
        raise UsageError(f"{what}: {text!r}: a channel is KEY[:UNIT][:LO..HI], KEY a name")
    unit, lo, hi = None, None, None
    for p in parts[1:]:
        p = p.strip()
        r = _range(p, f"{what}: {name}")
        if r is not None:
            lo, hi = r
        elif p:
            unit = p
    key = field_name(name)
    return Channel(field_name(name, taken), key=key, unit=unit, lo=lo, hi=hi, stale_s=stale_s)


def parse_decl(text, taken=frozenset()) -> list:
    """``--aux`` text -> [:class:`SensorDecl`]: a sensors file's sensors, or one source with its
    items (see the module's text). UsageError (exit 2) for anything it cannot use."""
    text = str(text).strip()
    if text.lower().endswith(FILE_SUFFIXES) and "," not in text:
        import os

        if os.path.isfile(text):
            return load_file(text, taken)
    source, _, rest = text.partition(",")
    what = f"aux: {source.strip()}"
    fmt, label, stale_s, items = "auto", None, DEFAULT_STALE_S, []
    for item in (i.strip() for i in rest.split(",")) if rest else ():
        if not item:
            continue
        k, eq, v = item.partition("=")
        k = k.strip().lower()
        if eq and k == "format":
            fmt = v.strip().lower()
            if fmt not in FORMATS:
                raise UsageError(f"{what}: format {v.strip()!r}; allowed {', '.join(FORMATS)}")
        elif eq and k == "stale":
            stale_s = _stale(v.strip().rstrip("s"), what)
        elif eq and k == "name":
            label = v.strip()
        elif eq:
            raise UsageError(f"{what}: {item!r}: allowed format=, stale=, name= or a channel KEY[:UNIT][:LO..HI]")
        else:
            items.append(item)
    channels = [_channel_item(i, what, stale_s, taken) for i in items] or None
    _no_twice(channels, what)
    return [SensorDecl(source.strip(), fmt, channels, label, stale_s)]


def _no_twice(channels, what):
    seen = set()
    for c in channels or ():
        for k in {c.name, c.key}:
            if k in seen:
                raise UsageError(f"{what}: channel {k} is declared twice")
        seen |= {c.name, c.key}


def load_file(path, taken=frozenset()) -> list:
    """The sensors declared in the sensors file ``path`` (TOML or YAML)."""
    from . import documents

    fmt = "toml" if path.lower().endswith(".toml") else "yaml"
    doc, name = documents.read(path, "aux", fmt, expected="a sensors file")
    return decls_of(doc, name, path, taken)


def decls_of(doc, name, path=None, taken=frozenset()) -> list:
    """A sensors document's value -> [:class:`SensorDecl`] (``name``: the file, in messages)."""
    if not isinstance(doc, dict) or not isinstance(doc.get("sensor"), list) or not doc["sensor"]:
        raise UsageError(f"aux: {name}: a sensors file has a list 'sensor' of sensors ([[sensor]] in TOML)")
    out = []
    for i, s in enumerate(doc["sensor"]):
        where = f"aux: {name}: sensor {i + 1}"
        if not isinstance(s, dict):
            raise UsageError(f"{where}: a table of source, format, name, stale_s and channel")
        unknown = set(s) - {"source", "format", "name", "stale_s", "channel"}
        if unknown:
            raise UsageError(f"{where}: unknown key {sorted(unknown)[0]!r}; allowed source, format, name, stale_s, "
                             f"channel")
        if not isinstance(s.get("source"), str) or not s["source"].strip():
            raise UsageError(f"{where}: no source (a serial port or URL, a FIFO, a file or -)")
        fmt = str(s.get("format", "auto")).lower()
        if fmt not in FORMATS:
            raise UsageError(f"{where}: format {fmt!r}; allowed {', '.join(FORMATS)}")
        stale_s = _stale(s.get("stale_s", DEFAULT_STALE_S), where)
        channels = None
        if s.get("channel") is not None:
            if not isinstance(s["channel"], list):
                raise UsageError(f"{where}: channel: a list of channels ([[sensor.channel]] in TOML)")
            channels = [_channel_doc(c, f"{where}: channel {j + 1}", stale_s, taken)
                        for j, c in enumerate(s["channel"])]
            _no_twice(channels, where)
        out.append(SensorDecl(s["source"].strip(), fmt, channels, s.get("name"), stale_s, file=path, index=i))
    return out


def _channel_doc(c, where, stale_s, taken):
    if not isinstance(c, dict) or not isinstance(c.get("name"), str):
        raise UsageError(f"{where}: a table with a name (and key, unit, range, stale_s, calibration)")
    unknown = set(c) - {"name", "key", "unit", "range", "stale_s", "calibration"}
    if unknown:
        raise UsageError(f"{where}: unknown key {sorted(unknown)[0]!r}; allowed name, key, unit, range, stale_s, "
                         f"calibration")
    lo = hi = None
    if c.get("range") is not None:
        r = c["range"]
        if not isinstance(r, list) or len(r) != 2:
            raise UsageError(f"{where}: range: [low, high]")
        lo = None if r[0] is None else _number(r[0], f"{where}: range")
        hi = None if r[1] is None else _number(r[1], f"{where}: range")
        if lo is not None and hi is not None and lo > hi:
            raise UsageError(f"{where}: range: the low end is above the high end")
    name = c["name"]
    return Channel(field_name(name, taken), key=field_name(c.get("key") or name), unit=c.get("unit"), lo=lo, hi=hi,
                   stale_s=_stale(c.get("stale_s", stale_s), where),
                   calibration=Calibration.from_doc(c.get("calibration"), f"{where}: calibration"))


def write_calibration(path, index, channel, calibration) -> None:
    """Write ``calibration`` for ``channel`` (its name) of sensor ``index`` into the sensors file
    ``path``, keeping the rest of the file: TOML through tomlkit (comments kept; the ``toml``
    extra), YAML through PyYAML (the file is written again, without its comments). The file is
    replaced whole (written beside it, then renamed)."""
    from . import documents
    from .textfile import read_text
    from ..errors import MissingExtra

    text, name = read_text(path, "sensors file")
    doc = calibration.as_doc()
    if path.lower().endswith(".toml"):
        try:
            import tomlkit
        except ImportError:
            raise MissingExtra("zk sensor: writing a TOML sensors file", "tomlkit", "toml") from None
        tree = tomlkit.parse(text)
        target = _find_channel(tree, index, channel, name)
        table = tomlkit.inline_table()
        table.update(doc)
        target["calibration"] = table
        out = tomlkit.dumps(tree)
    else:
        import yaml

        tree = documents.load_yaml(text, name)
        _find_channel(tree, index, channel, name)["calibration"] = doc
        out = yaml.safe_dump(tree, sort_keys=False, allow_unicode=True)
    from ..outfile import write_whole

    write_whole(path, out, what="sensors file")


def _find_channel(tree, index, channel, name):
    try:
        sensor = tree["sensor"][index]
        for c in sensor["channel"]:
            if field_name(c["name"]) == channel or field_name(c.get("key") or c["name"]) == channel:
                return c
    except (KeyError, IndexError, TypeError):
        pass
    raise UsageError(f"sensors file {name}: no channel {channel} in sensor {index + 1}")


def uncalibrated(decl) -> SensorDecl:
    """A copy of ``decl`` whose channels give their raw readings: no calibration, no range (what
    ``zk sensor tare`` and ``calibrate`` measure)."""
    chans = None
    if decl.channels is not None:
        chans = [Channel(c.name, c.key, c.unit, None, None, c.stale_s, None, c.declared) for c in decl.channels]
    return SensorDecl(decl.source, decl.format, chans, decl.label, decl.stale_s, decl.file, decl.index)


class Probe:
    """Declared sensors read outside an engine session (``zk sensor``): readings stamped on a
    clock of their own (seconds since the first reading was awaited). ``raw``: the channels'
    raw readings (:func:`uncalibrated`); ``follow``: a file source is followed as it grows (False:
    read to its end)."""

    def __init__(self, decls, *, timeout=2.0, raw=False, notify=None, follow=True):
        import time

        from .. import checking
        from .aux import AuxHub, Spec

        self.decls = [uncalibrated(d) if raw else d for d in decls]
        specs = [Spec(d.source, d, follow) for d in self.decls]        # a source that is none: exit 2
        checking.effect("sensors")         # opening a sensor's port is as far as a check goes
        self.hub = AuxHub(specs, notify=notify)
        self._time = time
        t0 = time.monotonic()
        self.hub.start(timeout)
        self.hub.bind(lambda: time.monotonic() - t0)

    def readings(self, duration=None, count=None, stop=None):
        """``(t, Reading)`` as they come, for ``duration`` seconds or ``count`` readings (or until
        ``stop()`` is true); a source that ends ends it too."""
        n = 0
        clock = self.hub._clock
        while duration is None or clock() < duration:
            got = self.hub.drain()
            for t, reading in got:
                yield t, reading
                n += 1
                if count is not None and n >= count:
                    return
            if stop is not None and stop():
                return
            if not got:
                if all(not r.is_alive() for r in self.hub._readers) and self.hub._queue.empty():
                    return
                self._time.sleep(0.02)

    def measure(self, name, seconds, settle=0.5) -> dict:
        """The mean, standard deviation and count of channel ``name``'s valid values that arrive in
        the ``seconds`` after ``settle`` seconds (what came before, and the lines still on their way
        from before — a serial driver's buffer — are not of it); UsageError when none came."""
        import statistics

        start = self.hub._clock() + settle
        values = [r.values[name] for t, r in self.readings(duration=start + seconds) if t >= start and name in r.values]
        if not values:
            raise UsageError(f"sensor: no valid value of {name} in {seconds:g} s")
        return {"mean": statistics.fmean(values), "std": statistics.stdev(values) if len(values) > 1 else 0.0,
                "n": len(values)}

    def summary(self) -> list:
        return self.hub.summary()

    def close(self) -> None:
        self.hub.close()


def solve(tare, points) -> Calibration:
    """The calibration of measured ``points`` ``[(raw, reference)]`` over ``tare`` (raw at no
    load): one point gives the scale, two or more the curve through them (x = raw - tare)."""
    pts = [(raw - tare, ref) for raw, ref in points]
    if len(pts) == 1:
        x, ref = pts[0]
        if x == 0:
            raise UsageError(f"calibrate: the reading at {ref:g} is the tare's ({tare:g}): no load reached the sensor")
        return Calibration(tare, ref / x, measured=points)
    return Calibration(tare, points=pts, measured=points)
