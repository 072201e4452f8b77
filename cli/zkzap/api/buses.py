"""Several buses at once: the buses a fleet file names, each worked on its own thread.

A fleet file may name the buses of a machine and the actuators on each::

    "buses": {"left":  {"port": "/dev/ttyUSB0", "ids": [1, 2, 3]},
              "right": {"port": "/dev/ttyUSB1", "baud": 115200, "ids": [1, 2, 3]}}

(``baud`` defaults to 57600). An actuator ID is that bus's: two buses may both have an ID 1.
:func:`run` opens every bus, runs ``work(bus, spec, emit, cancel)`` for each on a thread of its
own, and yields what the workers ``emit`` in the order it comes (each record names its bus);
an error on one bus cancels the others (each ends safely: a play stops its actuators) and is
raised once every thread has ended; so is a Ctrl-C in the caller's thread.

Nothing here imports click or rich.
"""

from __future__ import annotations

import queue
import threading

from ..codec import zap
from ..errors import UsageError

BUS_KEYS = ("port", "baud", "ids", "actuators")


class BusSpec:
    """One named bus: ``name``, ``port``, ``baud``, ``ids``."""

    __slots__ = ("name", "port", "baud", "ids")

    def __init__(self, name, port, baud=57600, ids=()):
        self.name, self.port, self.baud, self.ids = name, port, baud, list(ids)

    def __repr__(self):
        return f"BusSpec({self.name!r}, {self.port!r}, {self.baud}, {self.ids})"


def check_buses(buses, fail) -> dict:
    """Check a fleet file's ``buses`` object (``fail(key, text)`` raises naming the key)."""
    if not isinstance(buses, dict) or not buses:
        fail("buses", "expected an object of buses by name, each with port and ids")
    ports = {}
    for name, spec in buses.items():
        where = f"buses.{name}"
        if not isinstance(spec, dict):
            fail(where, "expected an object with port, baud, ids (and a backup's actuators)")
        for k in spec:
            if k not in BUS_KEYS:
                fail(f"{where}.{k}", f"unknown key; allowed {', '.join(BUS_KEYS)}")
        port = spec.get("port")
        if not isinstance(port, str) or not port:
            fail(f"{where}.port", "missing; expected a device path or URL")
        if port in ports:
            fail(f"{where}.port", f"{port} is bus {ports[port]!r}'s port too")
        ports[port] = name
        baud = spec.get("baud", 57600)
        if baud not in zap.BAUD_TO_CODE or isinstance(baud, bool):
            fail(f"{where}.baud", f"{baud!r} is not an actuator baud rate; allowed "
                                  f"{', '.join(str(b) for b in sorted(zap.BAUD_TO_CODE))}")
        ids = spec.get("ids")
        if not isinstance(ids, list) or not ids:
            fail(f"{where}.ids", "missing; expected a list of actuator IDs")
        for i in ids:
            if not isinstance(i, int) or isinstance(i, bool) or not 0 <= i <= zap.MAX_ID:
                fail(f"{where}.ids", f"{i!r} is not an actuator ID 0..253")
        if len(set(ids)) != len(ids):
            fail(f"{where}.ids", "an ID is given twice")
    return buses


def buses_of(path, names=None) -> list:
    """The :class:`BusSpec` list of the fleet file at ``path`` (``names``: only those, in that
    order); UsageError when it names none or an unknown one."""
    from . import documents
    from .fleet import check_document, format_of

    doc, name = documents.read(path, "fleet", "json" if path == "-" else format_of(path))
    check_document(doc, name)
    buses = doc.get("buses")
    if not buses:
        raise UsageError(f"{name}: names no buses (a top-level buses object: name -> port, baud, ids)")
    chosen = list(names) if names else list(buses)
    for n in chosen:
        if n not in buses:
            from ..errors import did_you_mean

            raise UsageError(f"{name}: no bus {n!r}" + did_you_mean(n, list(buses)))
    return [BusSpec(n, buses[n]["port"], buses[n].get("baud", 57600), buses[n]["ids"]) for n in chosen]


_END = object()


def run(specs, work, *, open_bus=None):
    """Run ``work(bus, spec, emit, cancel)`` on every bus of ``specs``, each on its own thread
    (``bus``: the open :class:`~zkzap.link.zap_bus.ZapBus`; ``emit(record)`` hands a record to
    the caller; ``cancel``: a threading.Event set when another bus failed or the caller was
    interrupted). Yields the records as they come, each with ``bus`` (the spec's name) first."""
    if open_bus is None:
        from ..link.zap_bus import open_bus as _open

        def open_bus(spec):
            return _open(spec.port, spec.baud)
    q = queue.Queue(maxsize=1000)            # bounded: a slow consumer slows the workers, never memory
    cancel = threading.Event()
    errors = []

    def worker(spec):
        try:
            with open_bus(spec) as bus:
                def emit(rec):
                    out = {"bus": spec.name}
                    out.update(rec)
                    while not cancel.is_set():
                        try:
                            q.put(out, timeout=0.1)
                            return
                        except queue.Full:
                            continue
                    try:                 # after a cancel (the record of a run cut short): if there is room
                        q.put_nowait(out)
                    except queue.Full:
                        pass
                work(bus, spec, emit, cancel)
        except BaseException as e:  # noqa: BLE001 - raised again in the caller's thread
            errors.append((spec.name, e))
            cancel.set()
        finally:
            q.put((_END, spec.name))

    threads = [threading.Thread(target=worker, args=(s,), name=f"zap bus {s.name}", daemon=True) for s in specs]
    for t in threads:
        t.start()
    running = len(threads)
    try:
        while running:
            item = q.get()
            if isinstance(item, tuple) and item and item[0] is _END:
                running -= 1
                continue
            yield item
    except BaseException:
        cancel.set()
        for t in threads:
            while t.is_alive():
                t.join(0.1)
                while not q.empty():     # a worker blocked on a full queue goes on to its end
                    q.get_nowait()
        raise
    finally:
        cancel.set()
        for t in threads:
            t.join(5)
    if errors:
        name, e = errors[0]
        if isinstance(e, Exception) and hasattr(e, "facts"):
            e.facts.setdefault("bus", name)
        raise e
