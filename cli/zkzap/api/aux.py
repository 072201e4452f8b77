"""External sensors beside the ECU (``--aux SOURCE``): a load cell, a flowmeter, a barometer.

A source is a serial port or any pyserial URL (``/dev/ttyUSB1``, ``socket://host:port``; 9600
baud unless ``@BAUD`` follows: ``/dev/ttyUSB1@115200``), a FIFO, a file (read from its start,
then followed as it grows, like ``tail -f``) or ``-`` (standard input), optionally declared with
its channels, their units, ranges, staleness and calibration (:mod:`zkzap.api.sensors`). It
sends lines of text in one of three formats (declared, or found from the first reading):

- ``name=value`` pairs, separated by spaces, commas or semicolons (``thrust_n=123.4 t_c=21.5``);
- CSV with a header line (``thrust_n,flow_ml_min``, then ``123.4,250``; ``,`` ``;`` or tab);
- JSON objects, one per line (``{"thrust_n": 123.4}``).

A line that is not a reading (a boot banner, a prompt, a blank line, a CSV row of the wrong
width) is skipped and counted. A value that is not a finite number, lies outside its channel's
range or is given twice in one line is rejected and counted, never stored. A found format's
CSV header is only taken as one when the next line is a row of its width with a number in it,
so a banner before the header is skipped, not taken for the field names.

Each reading is stamped when its line arrives (on the session's clock, so on a sped-up
simulator too); every record carries each channel's latest valid value, blank (None) once it
is older than the channel's ``stale_s`` of session time. Names are lower-cased with other
characters than letters, digits and ``_`` turned into ``_``; a name that is already a record key
(``rpm``, ``thrust_kg``, ``t``) gets the prefix ``aux_``.

:class:`AuxHub` runs one reader thread per source and hands the readings to the session's
thread in arrival order (:meth:`AuxHub.drain`); :meth:`AuxHub.start` waits for every source's
first reading, so a sensor that is silent, unplugged or on the wrong port is found before the
engine is asked for anything (exit 3). :meth:`AuxHub.summary` gives per sensor the lines read,
skipped and rejected, and per channel its values, rejections and stale time.
"""

from __future__ import annotations

import csv
import json
import os
import queue
import re
import stat
import threading
import time

from ..errors import NoReply, PortError, UsageError
from .sensors import DEFAULT_STALE_S, Channel, SensorDecl, field_name, parse_decl

#: Baud rate of a serial aux source without ``@BAUD``.
DEFAULT_BAUD = 9600
#: The default staleness of a channel (session seconds).
STALE_S = DEFAULT_STALE_S
#: Longest line read (a sensor that never sends a newline is not held in memory).
MAX_LINE = 4096
#: Longest integer kept as an integer (longer ones are floats; beyond a float's range: rejected).
_INT_DIGITS = 15
_SEP = re.compile(r"[,;\s]+")
_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*")


def _num(text):
    """The number ``text`` spells (int or float; inf for one beyond a float's range), or None."""
    t = text.strip()
    try:
        v = float(t)
    except ValueError:
        return None
    if re.fullmatch(r"[+-]?\d{1,%d}" % _INT_DIGITS, t):
        return int(t)
    return v


class _NotNumber:
    """A JSON value that is no number (NaN, Infinity, text, a list...), as the line gave it."""

    __slots__ = ("text",)

    def __init__(self, text):
        self.text = text


_JSON = json.JSONDecoder(object_pairs_hook=list, parse_constant=lambda c: float(c),
                         parse_int=lambda s: int(s) if len(s.lstrip("-")) <= _INT_DIGITS else float(s))


def _json_items(line):
    try:
        pairs = _JSON.decode(line)
    except (ValueError, RecursionError):      # not JSON, or nested beyond the parser's depth
        return None
    if not isinstance(pairs, list) or (pairs and not isinstance(pairs[0], tuple)):
        return None
    out = []
    for k, v in pairs:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            v = _NotNumber(str(v))
        out.append((str(k), v))
    return out


def _pair_items(line):
    out = []
    for part in _SEP.split(line):
        k, eq, v = part.partition("=")
        if eq and _KEY.fullmatch(k):
            n = _num(v)
            out.append((k, _NotNumber(v) if n is None else n))
    return out or None


class Reading:
    """One line's reading: ``values`` (channel name -> valid value), ``raw`` (the raw number of
    each calibrated channel), ``rejected`` (``[(channel, reason, text)]``)."""

    __slots__ = ("values", "raw", "rejected")

    def __init__(self, values, raw, rejected):
        self.values, self.raw, self.rejected = values, raw, rejected


class LineParser:
    """Lines -> :class:`Reading` (None for a line that is not one), by the declaration ``decl``
    (:class:`~zkzap.api.sensors.SensorDecl`; None: every key, the format found from the lines).
    ``taken``: record keys a found channel's name must not shadow."""

    def __init__(self, taken=frozenset(), decl=None):
        self.taken = taken
        self.decl = decl = decl or SensorDecl("-")
        self.shape = None if decl.format == "auto" else decl.format
        self.header = None
        self.sep = ","
        self._pending = None               # a candidate CSV header, until a row confirms it
        self.declared = decl.channels is not None
        self.channels = list(decl.channels or ())
        self._by_key = {c.key: c for c in self.channels}
        self.skipped = 0
        self.first_skipped = None
        self.ignored = []                  # keys of a declared sensor's lines it does not declare
        self._was_header = False
        self.stats = {}                    # channel name -> [values, {reason: rejections}]

    def _channel(self, key):
        k = field_name(key)
        c = self._by_key.get(k)
        if c is None and not self.declared:
            c = self._by_key[k] = Channel(field_name(key, self.taken), key=k, stale_s=self.decl.stale_s,
                                          declared=False)
            self.channels.append(c)
        elif c is None and k not in self.ignored and len(self.ignored) < 50:
            self.ignored.append(k)
        return c

    def _cells(self, line, sep=None):
        try:
            return next(csv.reader([line], delimiter=sep or self.sep), [])
        except csv.Error:                  # a stray carriage return, a field beyond csv's limit
            return None

    def _csv(self, line):
        if self.header is not None:
            cells = self._cells(line)
            if cells is None or len(cells) != len(self.header) or cells == self.header:
                return None                # not a row of its width, or the header again
            return [(h, _NotNumber(c) if _num(c) is None else _num(c)) for h, c in zip(self.header, cells)]
        sep = next((s for s in (";", "\t") if s in line), ",")
        cells = self._cells(line, sep)
        if not cells:
            return None
        names = all(c.strip() and _num(c) is None for c in cells)
        if names:
            keys = {field_name(c) for c in cells}
            if self.declared and self.shape == "csv":
                if all(c.key in keys for c in self.channels):
                    self.header, self.sep, self._was_header = cells, sep, True
                return None
            self._pending = (cells, sep)   # a header, if the next line is a row of its width
            return None
        pending, self._pending = self._pending, None
        if pending is not None and len(pending[0]) == len(cells) and sep == pending[1]:
            self.header, self.sep, self.shape = pending[0], sep, "csv"
            self.skipped -= 1              # the header line was counted as skipped
            for h in self.header:
                self._channel(h)
            return self._csv(line)
        return None

    def _items(self, line):
        shape = self.shape
        if shape == "json":
            return _json_items(line) if line.startswith("{") else None
        if shape == "pairs":
            return _pair_items(line)
        if shape == "csv":
            return self._csv(line)
        if line.startswith("{"):
            items = _json_items(line)
            if items is not None:
                self.shape = "json"
                return items
        items = _pair_items(line)
        if items is not None:
            self.shape = "pairs"
            return items
        return self._csv(line)

    def feed(self, line):
        """The :class:`Reading` of one line, or None (a header, a blank line, a line that is not a
        reading: counted in :attr:`skipped`)."""
        line = line.strip().lstrip("\ufeff")
        items = self._items(line) if line else None
        reading = None
        if items:
            seen = {}
            for key, value in items:
                c = self._channel(key)
                if c is not None:
                    seen.setdefault(c.name, []).append((c, value))
            if seen:
                reading = Reading({}, {}, [])
                for name, got in seen.items():
                    c, value = got[0]
                    stats = self.stats.setdefault(name, [0, {}])
                    if len(got) > 1:
                        v, why = None, "given twice in one line"
                        value = _NotNumber(" ".join(_text(v) for _, v in got))
                    else:
                        v, why = c.check(None if isinstance(value, _NotNumber) else value)
                    if why is not None:
                        reading.rejected.append((name, why, _text(value)))
                        stats[1][why] = stats[1].get(why, 0) + 1
                    else:
                        stats[0] += 1
                        reading.values[name] = v
                        if c.calibration is not None:
                            reading.raw[name] = value
        if reading is None and not self._was_header:
            self.skipped += 1
            if self.first_skipped is None and line:
                self.first_skipped = line[:60]
        self._was_header = False
        return reading

    def fields(self):
        """The channel names known so far, in their order."""
        return [c.name for c in self.channels]


def _text(value):
    return value.text if isinstance(value, _NotNumber) else repr(value) if isinstance(value, float) else str(value)


class Spec:
    """One ``--aux SOURCE`` as given: ``kind`` (stdin, fifo, file, serial), ``path``, ``baud``, and
    its declaration ``decl`` (:class:`~zkzap.api.sensors.SensorDecl`; None: nothing declared)."""

    def __init__(self, text, decl=None, follow=True):
        self.decl = decl
        self.follow = follow                # a file: followed as it grows (False: read to its end)
        self.text = text = str(text).strip()
        if not text:
            raise UsageError("aux: an empty source; give a serial port, a URL, a FIFO, a file or -")
        self.baud = DEFAULT_BAUD
        path = text
        m = re.fullmatch(r"(.+)@(\d+)", text)
        if m:
            path, self.baud = m.group(1), int(m.group(2))
            if not 300 <= self.baud <= 4_000_000:
                raise UsageError(f"aux: {text}: baud {self.baud} is out of range; allowed 300..4000000")
        self.path = path
        if path == "-":
            self.kind = "stdin"
        elif "://" in path:
            self.kind = "serial"
        else:
            try:
                mode = os.stat(path).st_mode
            except OSError as e:
                raise UsageError(f"aux: cannot open {path}: {e.strerror.lower()}") from None
            if stat.S_ISFIFO(mode):
                self.kind = "fifo"
            elif stat.S_ISCHR(mode):
                self.kind = "serial"
            elif stat.S_ISREG(mode):
                self.kind = "file"
            else:
                raise UsageError(f"aux: {path}: not a serial port, FIFO or file")


def parse_specs(texts, taken=frozenset()) -> list:
    """``--aux`` values (sources with their items, sensors files) -> :class:`Spec` (UsageError
    first); at most one ``-``, no channel name given by two sensors."""
    specs = []
    for t in texts:
        for d in parse_decl(t, taken):
            specs.append(Spec(d.source, d))
    if sum(s.kind == "stdin" for s in specs) > 1:
        raise UsageError("aux: '-' given twice; standard input is one source")
    names = {}
    for s in specs:
        for c in s.decl.channels or ():
            if c.name in names:
                raise UsageError(f"aux: channel {c.name} is declared by {names[c.name]} and {s.decl.label}; "
                                 f"give one of them another name")
            names[c.name] = s.decl.label
    return specs


class _Reader(threading.Thread):
    """Reads one source's lines, parses and checks them, stamps them (monotonic) and queues the
    readings."""

    def __init__(self, spec, index, out, taken, stop):
        super().__init__(name=f"zkzap-aux-{index}", daemon=True)
        self.spec, self.index, self.out, self.stop = spec, index, out, stop
        self.parser = LineParser(taken, spec.decl)
        self.ready = threading.Event()     # the first reading came (or the source failed or ended)
        self.error = None
        self.lines = 0
        self.readings = 0
        self.rejected = 0
        self.ended = False
        self._port = None
        self._file = None

    def run(self):
        try:
            for line in self._lines():
                if self.stop.is_set():
                    return
                self.lines += 1
                reading = self.parser.feed(line)
                if reading is not None:
                    self.readings += 1
                    self.rejected += len(reading.rejected)
                    self.out.put((time.monotonic(), self.index, reading))
                    self.ready.set()
            self.ended = True
        except (OSError, PortError, UsageError, TypeError, ValueError) as e:
            if not self.stop.is_set():          # not a port closed under the reader at the end
                self.error = f"{self.spec.text}: {getattr(e, 'strerror', None) or e}"
        finally:
            self.ready.set()

    def _lines(self):
        kind = self.spec.kind
        if kind == "serial":
            yield from self._serial()
            return
        if kind == "stdin":
            import sys

            stream = sys.stdin.buffer
        else:
            stream = self._file = open(self.spec.path, "rb", buffering=0)  # a FIFO: blocks until a writer opens
        buf = b""
        for chunk in self._chunks(stream):
            buf += chunk
            while b"\n" in buf or len(buf) >= MAX_LINE:
                line, nl, rest = buf.partition(b"\n")
                if not nl:
                    line, rest = buf[:MAX_LINE], buf[MAX_LINE:]
                buf = rest
                yield (line + nl).decode("utf-8", "replace")
        # a last line without its newline is dropped: its writer may have died in mid-number

    def _chunks(self, stream):
        """What the source sends, as it comes; the stop is seen within 0.1 s even while a pipe
        or FIFO stays open and silent (a blocking read would hold the session's end until its
        writer closed it)."""
        import select

        try:
            fd = stream.fileno()
        except (AttributeError, OSError, ValueError):
            fd = None
        while not self.stop.is_set():
            if fd is not None:
                try:
                    ready, _, _ = select.select([fd], [], [], 0.1)
                except (OSError, ValueError):          # a descriptor select cannot wait on
                    ready, fd = [fd], None
                if not ready:
                    continue
                chunk = os.read(fd, MAX_LINE) if fd is not None else stream.read(MAX_LINE)
            else:
                chunk = stream.read(MAX_LINE)
            if not chunk:
                if self.spec.kind == "file" and self.spec.follow:
                    time.sleep(0.05)                              # followed as it grows
                    continue
                return                                            # a FIFO's writer or stdin closed
            yield chunk

    def _serial(self):
        from ..link.port import open_port

        # never into the session's --capture: that file is the ECU's line
        self._port = port = open_port(self.spec.path, self.spec.baud, timeout=0.1, capture=())
        buf = b""
        while not self.stop.is_set():
            try:
                data = port.read(256)
            except Exception as e:          # pyserial's SerialException: the port went away
                if self.stop.is_set():
                    return
                raise PortError(f"{e}") from None
            if not data:
                continue
            buf += data
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                yield line.decode("utf-8", "replace")
            if len(buf) > MAX_LINE:
                buf = b""

    def close(self):
        for f in (self._port, self._file):
            if f is not None:
                try:
                    f.close()
                except Exception:
                    pass

    def describe_silence(self):
        p = self.parser
        if not self.lines:
            return "no line"
        what = f"{self.lines} line{'s' if self.lines != 1 else ''}, none a reading"
        if p.first_skipped:
            what += f" (the first: {p.first_skipped!r})"
        if p.declared:
            what += f"; it declares {', '.join(c.key for c in p.channels)}"
            if p.ignored:
                what += f" and sends {', '.join(p.ignored[:5])}"
        elif p._pending is not None or p.shape is None:
            what += "; a CSV sensor starts with its header (the field names)"
        return what


class AuxHub:
    """The ``--aux`` sources of a session (see the module's text).

    ``taken``: the record keys a sensor field must not shadow. After :meth:`start`,
    :attr:`fields` lists the channel names (:attr:`channels` the channels); :meth:`bind` gives the
    session's clock; the session's thread calls :meth:`drain` (readings with session times) and
    :meth:`merge`; :meth:`close` stops the readers and freezes :meth:`summary`.
    """

    def __init__(self, specs, taken=frozenset(), notify=None):
        self.specs = list(specs)
        for s in self.specs:
            if s.decl is None:
                s.decl = SensorDecl(s.text)
        self.taken = frozenset(taken)
        self.notify = notify or (lambda message: None)
        self._queue = queue.Queue()
        self._stop = threading.Event()
        self._readers = [_Reader(s, i, self._queue, self.taken, self._stop) for i, s in enumerate(self.specs)]
        self.fields = []
        self.channels = {}                 # name -> Channel
        self._owner = {}                   # name -> reader index
        self.latest = {}                   # name -> (session t, value)
        self.readings = 0
        self._clock = None
        self._speed = 1.0
        self._silent = set()
        self._source_t = {}
        self._stale = {}                   # name -> stale session seconds so far
        self._last_ok = {}                 # name -> session t of the last valid value
        self._stale_now = set()            # channels stale at the last merge
        self._end = None
        self._closed = False

    def __bool__(self):
        return bool(self.specs)

    def _learn(self, index):
        for c in self._readers[index].parser.channels:
            if c.name not in self.channels:
                self.channels[c.name] = c
                self._owner[c.name] = index
                self.fields.append(c.name)

    def start(self, timeout) -> None:
        """Start the readers and wait up to ``timeout`` real seconds for each source's first
        reading. A source that sends no reading is :class:`NoReply` (exit 3); one that cannot be
        opened or read is :class:`PortError` (exit 4)."""
        for r in self._readers:
            r.start()
        deadline = time.monotonic() + timeout
        for r in self._readers:
            r.ready.wait(max(0.0, deadline - time.monotonic()))
            if r.error is not None:
                self.close()
                raise PortError(f"aux: {r.error}")
            if not r.readings:
                how = "before it ended" if r.ended else f"within {timeout:g} s"
                self.close()
                baud = f" ({r.spec.baud})" if r.spec.kind == "serial" else ""
                raise NoReply(f"aux: no reading from {r.spec.text} {how} ({r.describe_silence()}; check the "
                              f"sensor, its port and baud rate{baud})")
        for i in range(len(self._readers)):
            self._learn(i)

    def bind(self, clock, speed=1.0) -> None:
        """Stamp readings on the session's clock (``clock()``: session seconds; ``speed``: session
        seconds per real second)."""
        self._clock, self._speed = clock, speed

    def drain(self) -> list:
        """The readings that arrived since the last call, as ``[(t, reading)]`` in arrival order
        (``t`` on the session's clock, ``reading`` a :class:`Reading`)."""
        out = []
        if self._clock is None or self._closed:
            return out
        now_mono, now = time.monotonic(), self._clock()
        while True:
            try:
                mono, index, reading = self._queue.get_nowait()
            except queue.Empty:
                break
            t = max(0.0, now - (now_mono - mono) * self._speed)
            for k in list(reading.values) + [r[0] for r in reading.rejected]:
                if k not in self.channels:
                    self._learn(index)
                    self.notify(f"aux: field {k} from {self.specs[index].text} appeared after the start: "
                                f"in JSON records, not in a CSV's columns")
            for k, v in reading.values.items():
                self._fresh(k, t)
                self.latest[k] = (t, v)
            self._source_t[index] = t
            if index in self._silent:
                self._silent.discard(index)
                self.notify(f"aux: {self.specs[index].text} sends again at t={t:.2f} s")
            self.readings += 1
            out.append((t, reading))
        for i, r in enumerate(self._readers):
            last = self._source_t.get(i)
            stale_s = min((c.stale_s for c in r.parser.channels), default=r.spec.decl.stale_s)
            if i not in self._silent and last is not None and now - last > stale_s:
                self._silent.add(i)
                why = f" ({r.error})" if r.error else ""
                self.notify(f"aux: nothing from {r.spec.text} since t={last:.2f} s{why}; its fields are empty "
                            f"until it sends again")
        return out

    def _fresh(self, name, t):
        span = stale_span(self._last_ok.get(name), t, self.channels[name].stale_s)
        if span is not None:
            self._stale[name] = self._stale.get(name, 0.0) + span[1] - span[0]
        self._last_ok[name] = max(t, self._last_ok.get(name, t))

    def value(self, key, now):
        """The latest value of ``key`` if it is fresh at session time ``now``, else None."""
        got = self.latest.get(key)
        c = self.channels.get(key)
        if got is None or now - got[0] > (c.stale_s if c is not None else STALE_S):
            return None
        return got[1]

    def merge(self, now) -> dict:
        """Every channel's latest fresh value at session time ``now`` (None when stale)."""
        return {k: self.value(k, now) for k in self.fields}

    def units(self) -> dict:
        """The declared unit of each channel that has one."""
        return {k: c.unit for k, c in self.channels.items() if c.unit}

    def summary(self) -> list:
        """Per sensor: its source, format, lines read, readings, lines skipped, values rejected,
        the keys it sent that it does not declare, its error; per channel: unit, range,
        staleness, calibration, values, rejections by reason and stale time (session s)."""
        end = self._end if self._end is not None else (self._clock() if self._clock is not None else None)
        out = []
        for i, r in enumerate(self._readers):
            p = r.parser
            chans = []
            for c in p.channels:
                d = c.describe()
                values, why = p.stats.get(c.name, (0, {}))
                d["values"] = values
                d["rejected"] = dict(why)
                stale = self._stale.get(c.name, 0.0)
                if end is not None:
                    span = stale_span(self._last_ok.get(c.name), end, c.stale_s)
                    if span is not None:
                        stale += span[1] - span[0]
                d["stale_time_s"] = round(stale, 3)
                chans.append(d)
            out.append({"sensor": r.spec.decl.label, "source": r.spec.text, "format": p.shape, "lines": r.lines,
                        "readings": r.readings, "skipped": p.skipped, "rejected": r.rejected,
                        "fields": p.fields(), "ignored": list(p.ignored), "channels": chans,
                        "declared_in": r.spec.decl.file, "error": r.error})
        return out

    def close(self) -> None:
        """Stop the readers (a serial one is joined before its port closes) and freeze the
        summary at this moment of the session."""
        if self._closed:
            return
        if self._clock is not None:
            self._end = self._clock()
        self._closed = True
        self._stop.set()
        for r in self._readers:
            if r.is_alive() and r.spec.kind in ("serial", "file"):
                r.join(1.0)
        for r in self._readers:
            r.close()


def stale_span(last, t, stale_s):
    """The stale interval ``(a, b)`` before a valid value at ``t`` when the one before was at
    ``last`` (None: none since the session's start, t = 0), or None."""
    a = 0.0 if last is None else last + stale_s
    return (a, t) if t > a else None
