"""The mightyZAP console of several buses at once: one :class:`~.zap_console.ZapConsole` a bus,
each with its worker thread of its own, behind one page.

Every bus keeps what one bus's console has: its scan, live poll, moves, register table, packet
panel, fleet file, self-check, play, teach and cycle, and its consent (each on its own port). A
bus's worker polls its actuators whatever the others do, so a slow or dead bus holds up no
other: a bus whose port fails is shown failed on the page (its requests refused, saying so)
while the others go on. An actuator is known by its bus and ID (two buses may both have an
ID 1): every message a bus's console sends, and every live sample and byte on its line, names
its bus; every request of the page names the bus it is for. A STOP ALL (a stop without a bus
or ID) stops the actuators of every bus.
"""

from __future__ import annotations

import threading

from .console import Console


class BusHub:
    """The server's hub as one bus's console sees it: what the console sends names its bus."""

    def __init__(self, hub, name):
        self.hub = hub
        self.name = name

    def broadcast(self, msg: dict) -> None:
        self.hub.broadcast({**msg, "bus": self.name})

    def send(self, client_id, msg: dict) -> None:
        self.hub.send(client_id, {**msg, "bus": self.name})

    def sample(self, item: dict) -> None:
        item["bus"] = self.name
        self.hub.sample(item)

    def traffic(self, item: dict) -> None:
        item["bus"] = self.name
        self.hub.traffic(item)


class BusesConsole(Console):
    """The console of ``consoles`` (``{bus name: ZapConsole}``, in the order the page lists
    them); ``ports``: each bus's port as the person named it (``{bus name: port}``)."""

    kind = "zap"

    def __init__(self, consoles: dict, ports: dict):
        self.consoles = dict(consoles)
        self.ports = dict(ports)
        super().__init__(", ".join(self.ports[n] for n in self.consoles),
                         simulated=all(not c.policy.real for c in self.consoles.values()))
        self.watch_ops = frozenset().union(*(c.watch_ops for c in self.consoles.values()))
        for name, c in self.consoles.items():
            c.on_log = self._log_of(name)

    def _log_of(self, name):
        def told(entry):
            if self.on_log is not None:
                self.on_log({**entry, "text": f"bus {name}: {entry['text']}"})
        return told

    # -- life: a worker a bus -------------------------------------------------------------------

    @property
    def failure(self):
        """The first bus's failure (the command's exit status once the console ends), or None."""
        for c in self.consoles.values():
            if c.failure is not None:
                return c.failure
        return None

    @failure.setter
    def failure(self, value):
        if value is not None:           # this console has no worker of its own that could fail
            raise AttributeError("a bus's console fails, not the console of several")

    def failed(self) -> dict:
        """``{bus name: error}`` of the buses whose worker stopped."""
        return {n: c.failure for n, c in self.consoles.items() if c.failure is not None}

    def start(self, hub) -> None:
        self.hub = hub
        for name, c in self.consoles.items():
            c.start(BusHub(hub, name))

    def close(self) -> None:
        """End every bus's worker at once (each leaves its actuators as one bus's console does),
        and wait for them all."""
        with self._wake:
            self._closing = True
        threads = [threading.Thread(target=c.close, name=f"zkzap-web-close {n}", daemon=True)
                   for n, c in self.consoles.items()]
        for t in threads:
            t.start()
        for t in threads:
            t.join()

    # -- to the pages ---------------------------------------------------------------------------

    def hello(self) -> dict:
        from .. import __version__

        return {"kind": self.kind, "port": f"{len(self.consoles)} buses", "simulated": not self.policy.real,
                "version": __version__,
                "buses": [{"name": n, "port": self.ports[n], "protocol": c.protocol, "simulated": not c.policy.real}
                          for n, c in self.consoles.items()]}

    def snapshot(self) -> list:
        logs = list(self.logs)
        for name, c in self.consoles.items():
            logs += [{**e, "bus": name} for e in list(c.logs)]
        logs.sort(key=lambda e: e["t"])
        out = [{"type": "logs", "items": logs}]
        for name, c in self.consoles.items():
            out.append({"type": "bushello", "bus": name, **c.hello()})
            out += [{**m, "bus": name} for m in c.snapshot() if m.get("type") != "logs"]
            if c.failure is not None:
                out.append({"type": "failed", "bus": name, "text": str(c.failure)})
        return out

    # -- requests: each to its bus --------------------------------------------------------------

    def request(self, cid, label, msg) -> None:
        name = msg.get("bus")
        if name is None and msg.get("op") == "stop" and msg.get("id") is None:
            alive = [(n, c) for n, c in self.consoles.items() if c.failure is None]
            for _, c in alive:             # STOP ALL: every bus that still works
                c.request(cid, label, msg)
            if not alive:
                self._refuse(cid, msg, "every bus has failed")
            return
        c = self.consoles.get(name) if isinstance(name, str) else None
        if c is None:
            given = "none given" if name is None else f"no bus {name!r}"
            self._refuse(cid, msg, f"bus: {given}; the buses: {', '.join(self.consoles)}")
            return
        if c.failure is not None:
            self._refuse(cid, msg, f"bus {name} failed: {c.failure}", name)
            return
        c.request(cid, label, msg)

    def _refuse(self, cid, msg, text, name=None) -> None:
        if self.hub is not None:
            out = {"type": "error", "req": msg.get("req"), "text": text}
            if name is not None:
                out["bus"] = name
            self.hub.send(cid, out)

    def run(self) -> None:              # pragma: no cover - the buses' consoles have the workers
        raise RuntimeError("the console of several buses has no worker of its own")
