"""Telemetry bridges: extra record sinks that publish a session's records elsewhere (MAVLink,
MQTT) without ever blocking the serial loop.

A :class:`Bridge` takes records through :meth:`Bridge.submit`, which never blocks: the record
goes into a bounded queue that the bridge's own thread empties; when the queue is full the
record is dropped and counted. Each bridge is imported only when its option is given, and its
library (an optional extra) only by :meth:`Bridge.start`. :class:`Bridges` fans records out to
several and gathers their figures for the health view and the end-of-run summary.
"""

from __future__ import annotations

import importlib.util
import queue
import threading

from ...errors import MissingExtra

#: Records a bridge holds while its peer is slow or away (10 s at the ECU's fastest 100 Hz).
QUEUE_SIZE = 1000
#: Longest a bridge takes at the end to hand over what it still holds.
DRAIN_S = 5.0

_STOP = object()


def require_extra(module: str, extra: str, option: str) -> None:
    """Refuse (exit 2) an option whose library is not installed, naming the extra to install."""
    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        found = False
    if not found:
        raise MissingExtra(option, module, extra)


class Bridge:
    """A record sink with its own thread and a bounded queue (see the module's description)."""

    name = "bridge"

    def __init__(self, queue_size=QUEUE_SIZE):
        self.queue = queue.Queue(queue_size)
        self.submitted = 0
        self.dropped = 0
        self.error = None
        self._thread = None
        self._closing = threading.Event()

    # the serial loop's side
    def submit(self, rec) -> None:
        try:
            self.queue.put_nowait(rec)
            self.submitted += 1
        except queue.Full:
            self.dropped += 1

    def start(self) -> None:
        """Connect (raising :class:`~zkzap.errors.PortError` when the peer cannot be reached) and
        start the thread."""
        self.connect()
        self._thread = threading.Thread(target=self._run, name=f"zkzap-{self.name}", daemon=True)
        self._thread.start()

    def close(self, timeout=DRAIN_S) -> None:
        """Hand over what is queued (at most ``timeout`` s), then disconnect."""
        self._closing.set()
        if self._thread is not None:
            try:
                self.queue.put(_STOP, timeout=timeout)
            except queue.Full:
                pass
            self._thread.join(timeout + 1.0)
            self._thread = None
        self.disconnect()

    def stats(self) -> dict:
        return {"submitted": self.submitted, "dropped": self.dropped, "queued": self.queue.qsize()}

    def describe(self) -> str:
        s = self.stats()
        return f"{s['submitted']} records, {s['dropped']} dropped"

    # the bridge's side
    def drain(self, q, stop) -> tuple:
        """(records waiting, stop seen) without blocking."""
        out = []
        while True:
            try:
                rec = q.get_nowait()
            except queue.Empty:
                return out, False
            if rec is stop:
                return out, True
            out.append(rec)

    def _run(self):
        try:
            self.run(self.queue, _STOP)
        except Exception as e:          # a bridge failing must not take the session down
            self.error = f"{type(e).__name__}: {e}"

    def connect(self):  # pragma: no cover - abstract
        raise NotImplementedError

    def run(self, q, stop):  # pragma: no cover - abstract
        raise NotImplementedError

    def disconnect(self):
        pass


class Bridges:
    """Several bridges as one sink."""

    def __init__(self, bridges=()):
        self.bridges = list(bridges)

    def __bool__(self):
        return bool(self.bridges)

    def start(self):
        started = []
        try:
            for b in self.bridges:
                b.start()
                started.append(b)
        except BaseException:
            for b in started:
                b.close(timeout=0.5)
            raise

    def submit(self, rec):
        for b in self.bridges:
            b.submit(rec)

    def close(self):
        for b in self.bridges:
            b.close()

    def stats(self) -> dict:
        return {b.name: b.stats() for b in self.bridges}

    def lines(self) -> list:
        """One line per bridge for the end-of-run summary."""
        out = []
        for b in self.bridges:
            line = f"{b.name}: {b.describe()}"
            if b.error:
                line += f"; failed: {b.error}"
            out.append(line)
        return out
