"""MCAP files of ZK telemetry, for Foxglove and PlotJuggler (the optional ``mcap`` extra).

One channel per status ID (``/zk/status/<id>``) and per control command
(``/zk/control/<command>``), JSON message encoding, and a JSON Schema per channel generated from
the protocol tables (:mod:`zkzap.codec.zk`): every key with its type, and its description and
unit from the table. A message's log time is the record's receive time (its ``time``), its
sequence the channel's message count. The file is chunked (zstd or lz4 when available) and
indexed, so large runs open quickly; :meth:`McapWriter.close` writes the summary and the
indexes, which a session does on every end it can see (count, duration, Ctrl-C, SIGTERM, a port
failure).

A chunk is closed by time as well as by size: every :data:`FLUSH_S` seconds the chunk in
progress is written out with its message indexes and the stream flushed (by a thread of the
writer's own, so a silent ECU does not hold the last records back), so a process killed
without a word (SIGKILL, a power cut) leaves a file whose records up to the last half second
are readable — it only lacks the summary and footer, which readers that scan the file
(``mcap.reader.NonSeekingReader``, ``mcap recover``) do without.
"""

from __future__ import annotations

import json
import threading

from ..codec import zk
from .writers import IsoNs
from .writers import dumps as _dumps

#: The extra that provides this module's library.
EXTRA = "mcap"
CHUNK_SIZE = 256 * 1024
#: The longest a record waits in memory before its chunk is written out (seconds).
FLUSH_S = 0.5


_COMMON = {
    "time": {"type": ["string", "null"], "format": "date-time",
             "description": "receive time, ISO 8601 UTC (null in a replay of a raw log, which holds no times)"},
    "t": {"type": "number", "description": "seconds since the start of the session (s)"},
    "kind": {"type": "string", "description": "status (ECU to host) or control (host to ECU)"},
    "frame": {"type": "string", "description": "the frame as hex bytes"},
}
_STALE = {
    "stale": {"type": "boolean", "description": "some status ID has not been seen for --stale-after periods"},
    "stale_ids": {"type": "array", "items": {"type": "integer"}, "description": "the stale status IDs"},
}


def _describe(field) -> str:
    text = field.help or field.key
    return f"{text} ({field.unit})" if field.unit else text


def _properties(layout) -> dict:
    props = {}
    by_name_key = {f.name_key: f for f in layout.fields if f.name_key}
    for key in layout.keys():
        f = layout.by_key.get(key)
        if f is not None:
            integral = not isinstance(f.scale, float) and f.scale == 1 or f.names is not None
            if f.values is not None:
                integral = all(isinstance(v, int) for v in f.values.values())
            props[key] = {"type": ["integer" if integral else "number", "null"], "description": _describe(f)}
        elif key in by_name_key:
            props[key] = {"type": ["string", "null"], "description": f"name of {by_name_key[key].key}"}
        else:
            props[key] = {"type": ["number", "string", "null"], "description": key.replace("_", " ")}
    return props


#: Records of a session's events (no status frame): a port's gap, a trip, the rundown after it;
#: each kind on its own channel, /zk/event/KIND.
EVENT_KINDS = ("gap", "trip", "rundown")


def status_schema(sid: int) -> dict:
    """The JSON Schema of status ID ``sid`` records as ``zk monitor`` writes them."""
    spec = zk.STATUS_BY_ID.get(sid)
    props = dict(_COMMON)
    props["id"] = {"type": "integer", "const": sid, "description": "status frame ID"}
    if spec is not None:
        props.update(_properties(spec.layout))
        title = f"ZK status ID {sid} ({spec.name})"
    else:
        props["rpm"] = {"type": ["integer", "null"], "description": "engine speed (rpm)"}
        props["payload"] = {"type": "string", "description": "undecoded bytes 3..5 of an undocumented ID"}
        title = f"ZK status ID {sid} (undocumented)"
    props.update(_STALE)
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title, "type": "object",
            "properties": props, "required": ["time", "t", "kind", "id"]}


def control_schema(name: str) -> dict:
    """The JSON Schema of control records of command ``name`` (``control``, ``action``, ...)."""
    spec = zk.CONTROL_BY_NAME[name]
    props = dict(_COMMON)
    props["id"] = {"type": "integer", "const": spec.id, "description": "control frame ID"}
    props["command"] = {"type": "string", "const": name, "description": spec.help}
    props.update(_properties(spec.layout))
    props["reserved"] = {"type": "string", "description": "reserved bits that are set"}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": f"ZK control ID {spec.id} ({name})", "type": "object", "properties": props,
            "required": ["time", "t", "kind", "id", "command"]}


class McapWriter:
    """Records (status and control, as dicts) into an MCAP file on a binary ``stream``."""

    def __init__(self, stream, *, library="zkzap", flush_s=FLUSH_S):
        from mcap.writer import CompressionType, IndexType, Writer

        compression = CompressionType.NONE
        for name, kind in (("zstandard", CompressionType.ZSTD), ("lz4", CompressionType.LZ4)):
            try:
                __import__(name)
            except ImportError:
                continue
            compression = kind
            break
        self.stream = stream
        self._make = lambda: Writer(stream, chunk_size=CHUNK_SIZE, compression=compression,
                                    index_types=IndexType.ALL, use_chunking=True, use_statistics=True,
                                    use_summary_offsets=True)
        self._library = library
        self._w = None                     # started by the first record (a header is not a record)
        self._channels = {}
        self._seq = {}
        self._last_ns = 0
        self._ch_ns = {}                   # channel -> its last log time (ns)
        self.count = 0
        self._closed = False
        self._ns = IsoNs()
        self._lock = threading.Lock()
        self._pending = False             # messages not yet written out
        self._error = None                # an OSError of the flushing thread, raised by the next write
        self._stop = threading.Event()
        self._thread = None
        if flush_s:
            self._thread = threading.Thread(target=self._flusher, args=(flush_s,), name="zkzap-mcap-flush",
                                            daemon=True)
            self._thread.start()

    def _flusher(self, period):
        while not self._stop.wait(period):
            with self._lock:
                if self._closed or not self._pending or self._w is None:
                    continue
                try:
                    self._w.flush()       # the chunk in progress, its message indexes, then the stream
                except (OSError, ValueError) as e:
                    self._error = e
                    return
                self._pending = False

    def _start(self):
        from .. import __version__

        self._w = self._make()
        try:
            self._w.start(profile="", library=f"{self._library} {__version__}")
            self.stream.flush()           # the header is on disk before the first record
        except OSError as e:
            self._fail(e)

    def _channel(self, rec):
        if self._w is None:
            self._start()
        kind = rec.get("kind") or "status"
        if kind == "control":
            key = ("control", rec.get("command") or f"id-{rec.get('id')}")
        elif kind in EVENT_KINDS:
            key = ("event", kind)
        else:
            key = ("status", rec.get("id"))
        ch = self._channels.get(key)
        if ch is None:
            if key[0] == "event":
                schema, topic, sname = {"type": "object"}, f"/zk/event/{key[1]}", f"zk.event.{key[1]}"
            elif key[0] == "control":
                name = key[1]
                schema = control_schema(name) if name in zk.CONTROL_BY_NAME else {"type": "object"}
                topic, sname = f"/zk/control/{name}", f"zk.control.{name}"
            else:
                schema = status_schema(key[1])
                topic, sname = f"/zk/status/{key[1]}", f"zk.status.{key[1]}"
            sid = self._w.register_schema(name=sname, encoding="jsonschema",
                                          data=json.dumps(schema, ensure_ascii=False).encode("utf-8"))
            ch = self._channels[key] = self._w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
            self._seq[ch] = 0
        return ch

    def _time_ns(self, rec):
        ns = self._ns(rec.get("time"))
        if ns is None and rec.get("time") is None and isinstance(rec.get("t"), (int, float)):
            ns = round(rec["t"] * 1e9)     # no wall-clock time (a raw log's replay): time since its start
        if ns is not None:
            if not 0 <= ns < 1 << 64:
                from ..errors import UsageError

                when = rec.get("time") if rec.get("time") is not None else f"t = {rec.get('t')} s"
                raise UsageError(f"mcap: a record at {when}: MCAP's log time is nanoseconds since 1970 in "
                                 "64 bits (1970-01-01 to 2554-07-21)")
            self._last_ns = ns
        return self._last_ns

    def write(self, rec):
        if self._closed:
            return
        if self._error is not None:
            self._fail(self._error)
        data = _dumps({k: v for k, v in rec.items() if k[:1] != "_"}).encode("utf-8")
        with self._lock:
            try:
                ns = self._time_ns(rec)       # before the channel: a time MCAP cannot hold starts no file
                ch = self._channel(rec)
                last = self._ch_ns.get(ch)
                if last is not None and ns <= last:
                    ns = last + 1             # each message of a channel its own time (within the ms of `time`)
                self._ch_ns[ch] = ns
                seq = self._seq[ch]
                self._seq[ch] = seq + 1
                self._w.add_message(channel_id=ch, log_time=ns, data=data, publish_time=ns, sequence=seq)
            except OSError as e:
                self._fail(e)
            self._pending = True
        self.count += 1

    def _fail(self, e):
        from ..errors import OutputError

        self._closed = True
        self._stop.set()
        name = getattr(self.stream, "name", None)
        name = "stdout" if not isinstance(name, str) or name == "<stdout>" else name
        raise OutputError(f"output: cannot write {name}: {getattr(e, 'strerror', None) or e}") from None

    def write_many(self, recs):
        for rec in recs:
            self.write(rec)

    def close(self):
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()
        if self._closed:
            return
        if self._error is not None:
            self._fail(self._error)
        with self._lock:
            if self._w is None:
                if getattr(self.stream, "lazy", False):
                    self._closed = True
                    return                 # a file no record opened: left as it was
                self._start()              # stdout: an empty, valid MCAP stream
            try:
                self._w.finish()
                self.stream.flush()
            except BrokenPipeError:
                self._closed = True
            except OSError as e:
                self._fail(e)
            self._closed = True
