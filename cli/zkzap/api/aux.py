"""External sensors beside the ECU (``--aux SOURCE``): a load cell, a flowmeter, a barometer.

A source is a serial port or any pyserial URL (``/dev/ttyUSB1``, ``socket://host:port``; 9600
baud unless ``@BAUD`` follows: ``/dev/ttyUSB1@115200``), a FIFO, a file (read from its start,
then followed as it grows, like ``tail -f``) or ``-`` (standard input). It sends lines of text,
each one reading, in one of three shapes found from the first line:

- ``name=value`` pairs, separated by spaces, commas or semicolons (``thrust_n=123.4 t_c=21.5``);
- CSV with a header line (``thrust_n,flow_ml_min``, then ``123.4,250``; ``,`` ``;`` or tab);
- JSON objects, one per line (``{"thrust_n": 123.4}``).

Each reading is stamped when its line arrives (on the session's clock, so on a sped-up
simulator too), and its fields become fields of the records: every record carries each
field's latest value (None once it is older than :data:`STALE_S`). Names are lower-cased with
other characters than letters, digits and ``_`` turned into ``_``; a name that is already a
record key (``rpm``, ``thrust_kg``, ``t``) gets the prefix ``aux_``. Numbers are numbers,
anything else text.

:class:`AuxHub` runs one reader thread per source and hands the readings to the session's
thread in arrival order (:meth:`AuxHub.drain`); :meth:`AuxHub.start` waits for every source's
first line, so a sensor that is silent, unplugged or on the wrong port is found before the
engine is asked for anything (exit 3).
"""

from __future__ import annotations

import csv
import json
import math
import os
import queue
import re
import stat
import threading
import time

from ..errors import NoReply, PortError, UsageError

#: Baud rate of a serial aux source without ``@BAUD``.
DEFAULT_BAUD = 9600
#: A field older than this (real seconds; on a sped-up simulator that many of its seconds times
#: its speed) is no longer merged.
STALE_S = 2.0
#: Longest line read (a sensor that never sends a newline is not held in memory).
MAX_LINE = 4096
_SEP = re.compile(r"[,;\s]+")


def field_name(name, taken=frozenset()) -> str:
    """A sensor's field name as a record key: lower case, ``[a-z0-9_]``; ``aux_`` before a name
    that is a record key already."""
    key = re.sub(r"[^a-z0-9_]", "_", str(name).strip().lower()) or "field"
    if key[0].isdigit():
        key = "_" + key
    return f"aux_{key}" if key in taken else key


def _value(text):
    t = text.strip()
    try:
        v = float(t)
    except ValueError:
        return t
    if not math.isfinite(v):
        return None
    return int(v) if re.fullmatch(r"[+-]?\d+", t) else v


class LineParser:
    """Lines -> readings (dicts); the shape is decided by the first line (see the module)."""

    def __init__(self, taken):
        self.taken = taken
        self.shape = None
        self.header = None
        self.sep = ","
        self.names = {}

    def _key(self, name):
        key = self.names.get(name)
        if key is None:
            key = self.names[name] = field_name(name, self.taken)
        return key

    def feed(self, line):
        """The reading of one line (None for a header, a blank or a line that is not a reading)."""
        line = line.strip().lstrip("\ufeff")
        if not line:
            return None
        if self.shape is None:
            if line.startswith("{"):
                self.shape = "json"
            elif "=" in line:
                self.shape = "pairs"
            else:
                self.shape = "csv"
                self.sep = next((s for s in (";", "\t") if s in line), ",")
                try:
                    cells = next(csv.reader([line], delimiter=self.sep))
                except csv.Error as e:           # a stray carriage return, a field beyond csv's limit
                    raise UsageError(f"a first line that is not CSV ({line[:40]!r}): {e}") from None
                if any(isinstance(_value(c), (int, float)) for c in cells):
                    raise UsageError(f"a first line of numbers ({line[:40]!r}); a CSV source starts with its "
                                     f"header (the field names)")
                self.header = [self._key(c) for c in cells]
                return None
        if self.shape == "json":
            try:
                obj = json.loads(line)
            except (ValueError, RecursionError):       # not JSON, or nested beyond the parser's depth
                return None
            if not isinstance(obj, dict):
                return None
            return {self._key(k): (v if isinstance(v, (int, float, str, bool)) or v is None else str(v))
                    for k, v in obj.items()}
        if self.shape == "pairs":
            out = {}
            for part in _SEP.split(line):
                k, eq, v = part.partition("=")
                if eq and k:
                    out[self._key(k)] = _value(v)
            return out or None
        try:
            cells = next(csv.reader([line], delimiter=self.sep), [])
        except csv.Error:
            return None                          # not a reading (a damaged line)
        if len(cells) != len(self.header):
            return None
        return {k: _value(v) for k, v in zip(self.header, cells)}

    def fields(self):
        """The field keys known so far, in their order."""
        return list(self.header) if self.header is not None else list(self.names.values())


class Spec:
    """One ``--aux SOURCE`` as given: ``kind`` (stdin, fifo, file, serial), ``path``, ``baud``."""

    def __init__(self, text):
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


def parse_specs(texts) -> list:
    """``--aux`` values -> :class:`Spec` (UsageError first); at most one ``-``."""
    specs = [Spec(t) for t in texts]
    if sum(s.kind == "stdin" for s in specs) > 1:
        raise UsageError("aux: '-' given twice; standard input is one source")
    return specs


class _Reader(threading.Thread):
    """Reads one source's lines, stamps them (monotonic) and queues the readings."""

    def __init__(self, spec, index, out, taken, stop):
        super().__init__(name=f"zkzap-aux-{index}", daemon=True)
        self.spec, self.index, self.out, self.stop = spec, index, out, stop
        self.parser = LineParser(taken)
        self.ready = threading.Event()     # the field names are known (or the source failed)
        self.error = None
        self.lines = 0
        self.readings = 0
        self._port = None
        self._file = None

    def run(self):
        try:
            for line in self._lines():
                if self.stop.is_set():
                    return
                self.lines += 1
                try:
                    reading = self.parser.feed(line)
                except UsageError as e:
                    self.error = f"{self.spec.text}: {e}"
                    self.ready.set()
                    return
                if self.parser.header is not None:
                    self.ready.set()
                if reading:
                    self.readings += 1
                    self.out.put((time.monotonic(), self.index, reading))
                    self.ready.set()
        except (OSError, PortError, UsageError) as e:
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
            stream = self._file = open(self.spec.path, "rb")      # a FIFO: blocks until a writer opens
        buf = b""
        while not self.stop.is_set():
            chunk = stream.readline(MAX_LINE)
            if not chunk:
                if kind == "file":
                    time.sleep(0.05)                              # followed as it grows
                    continue
                return                                            # a FIFO's writer or stdin closed
            buf += chunk
            if buf.endswith(b"\n") or len(buf) >= MAX_LINE:
                yield buf.decode("utf-8", "replace")
                buf = b""

    def _serial(self):
        from ..link.port import open_port

        # never into the session's --capture: that file is the ECU's line
        self._port = port = open_port(self.spec.path, self.spec.baud, timeout=0.1, capture=())
        buf = b""
        while not self.stop.is_set():
            try:
                data = port.read(256)
            except Exception as e:          # pyserial's SerialException: the port went away
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


class AuxHub:
    """The ``--aux`` sources of a session (see the module's text).

    ``taken``: the record keys a sensor field must not shadow. After :meth:`start`,
    :attr:`fields` lists the field keys; :meth:`bind` gives the session's clock; the session's
    thread calls :meth:`drain` (readings with session times) and :meth:`merge`.
    """

    def __init__(self, specs, taken=frozenset(), notify=None):
        self.specs = list(specs)
        self.taken = frozenset(taken)
        self.notify = notify or (lambda message: None)
        self._queue = queue.Queue()
        self._stop = threading.Event()
        self._readers = [_Reader(s, i, self._queue, self.taken, self._stop) for i, s in enumerate(self.specs)]
        self.fields = []
        self.latest = {}               # key -> (session t, value)
        self.readings = 0
        self._clock = None
        self._speed = 1.0
        self._silent = set()
        self._source_t = {}

    def __bool__(self):
        return bool(self.specs)

    def start(self, timeout) -> None:
        """Start the readers and wait up to ``timeout`` real seconds for each source's first
        line (its field names). A source that stays silent is :class:`NoReply` (exit 3); one
        that cannot be opened or read is :class:`PortError` (exit 4)."""
        for r in self._readers:
            r.start()
        deadline = time.monotonic() + timeout
        for r in self._readers:
            r.ready.wait(max(0.0, deadline - time.monotonic()))
            if r.error is not None:
                self.close()
                raise (UsageError if "first line of numbers" in r.error else PortError)(f"aux: {r.error}")
            if not r.ready.is_set():
                self.close()
                raise NoReply(f"aux: no line from {r.spec.text} within {timeout:g} s (check the sensor, its port "
                              f"and baud rate{'' if r.spec.kind != 'serial' else f' ({r.spec.baud})'})")
        seen = []
        for r in self._readers:
            for k in r.parser.fields():
                if k not in seen:
                    seen.append(k)
        self.fields = seen

    def bind(self, clock, speed=1.0) -> None:
        """Stamp readings on the session's clock (``clock()``: session seconds; ``speed``: session
        seconds per real second)."""
        self._clock, self._speed = clock, speed

    def drain(self) -> list:
        """The readings that arrived since the last call, as ``[(t, fields)]`` in arrival order,
        ``t`` on the session's clock."""
        out = []
        if self._clock is None:
            return out
        now_mono, now = time.monotonic(), self._clock()
        while True:
            try:
                mono, index, reading = self._queue.get_nowait()
            except queue.Empty:
                break
            t = max(0.0, now - (now_mono - mono) * self._speed)
            for k, v in reading.items():
                if k not in self.fields:
                    self.fields.append(k)
                    self.notify(f"aux: field {k} from {self.specs[index].text} appeared after the start: "
                                f"in JSON records, not in a CSV's columns")
                self.latest[k] = (t, v)
            self._source_t[index] = t
            if index in self._silent:
                self._silent.discard(index)
                self.notify(f"aux: {self.specs[index].text} sends again at t={t:.2f} s")
            self.readings += 1
            out.append((t, reading))
        for i, r in enumerate(self._readers):
            last = self._source_t.get(i)
            if i not in self._silent and last is not None and now - last > STALE_S * self._speed:
                self._silent.add(i)
                why = f" ({r.error})" if r.error else ""
                self.notify(f"aux: nothing from {r.spec.text} since t={last:.2f} s{why}; its fields are empty "
                            f"until it sends again")
        return out

    def value(self, key, now):
        """The latest value of ``key`` if it is fresh at session time ``now``, else None."""
        got = self.latest.get(key)
        if got is None or now - got[0] > STALE_S * self._speed:
            return None
        return got[1]

    def merge(self, now) -> dict:
        """Every field's latest fresh value at session time ``now`` (None when stale)."""
        return {k: self.value(k, now) for k in self.fields}

    def summary(self) -> list:
        return [{"source": r.spec.text, "lines": r.lines, "readings": r.readings,
                 "fields": [k for k in r.parser.fields()], "error": r.error} for r in self._readers]

    def close(self) -> None:
        self._stop.set()
        for r in self._readers:
            r.close()
        for r in self._readers:
            if r.is_alive() and r.spec.kind not in ("stdin", "fifo"):
                r.join(1.0)
