"""The zap console's baud change when it fails: the failure is a line of the console's log (not
only the page's error), the actuator's true state is found and said, and a stored rate that
would make it vanish at its next power-up is rolled back."""

from __future__ import annotations

import pytest

from zkzap import Bus
from zkzap.codec import zap
from zkzap.sim import start_zap
from zkzap.web.console import Request
from zkzap.web.zap_console import ZapConsole


class Hub:
    """What the console sends the pages."""

    def __init__(self):
        self.sent = []

    def send(self, cid, msg):
        self.sent.append(msg)

    def broadcast(self, msg):
        self.sent.append(msg)

    def sample(self, item):
        pass

    def traffic(self, item):
        pass


def _console(sim, bus):
    c = ZapConsole(bus, scan_ids=None)
    c.hub = Hub()
    for rec in bus.scan([1, 4]):
        c.actuators[rec["id"]] = dict(rec, polled=True, link=None)
    return c


def _write(console, ident, name, value):
    console.handle(Request(1, "page 1", {"op": "write", "req": 7, "id": ident, "register": name, "value": value,
                                         "grant": ["stored-write"]}))
    return console.hub.sent


def _deaf_to(sim, ident, code):
    """Actuator ``ident`` never hears instruction ``code`` (lost on a busy line)."""
    act = sim.device.actuator(ident)
    heard = act.handle
    act.handle = lambda pkt, now: None if pkt[5] == code else heard(pkt, now)


def test_a_restart_that_does_not_take_is_rolled_back_and_said_in_the_log():
    with start_zap(ids=[1, 4], virtual=True) as sim, Bus(sim, timeout=0.05) as bus:
        console = _console(sim, bus)
        _deaf_to(sim, 4, zap.RESTART)
        sent = _write(console, 4, "baud-rate", zap.BAUD_TO_CODE[115200])
        logs = [m["text"] for m in sent if m["type"] == "log"]
        assert any("ID 4 baud change 57600 -> 115200 failed" in t for t in logs), logs
        assert any(t == "ID 4 answers at 57600 baud and it stores baud-rate code 32 (57600): unchanged (rolled back)"
                   for t in logs), logs
        error = next(m for m in sent if m["type"] == "error")
        assert "unchanged (rolled back)" in error["text"] and error["req"] == 7
        act = sim.device.actuator(4)
        assert act.get("baud-rate") == 32 and act.baud == 57600          # as it was: it will not vanish
        assert console.actuators[4]["baud"] == 57600 and bus.baud == 57600
        assert bus.load(4, "baud-rate") == 32


def test_a_change_that_took_but_could_not_be_read_back_says_where_it_answers():
    with start_zap(ids=[1, 4], virtual=True) as sim, Bus(sim, timeout=0.05) as bus:
        console = _console(sim, bus)
        act = sim.device.actuator(4)
        heard = act.handle
        state = {"restarted": False, "reads": 0}

        def handle(pkt, now):                  # the first read after the restart is lost
            if pkt[5] == zap.RESTART:
                state["restarted"] = True
            elif pkt[5] == zap.LOAD_DATA and state["restarted"] and state["reads"] < 3:
                state["reads"] += 1
                return None
            return heard(pkt, now)

        act.handle = handle
        sent = _write(console, 4, "baud-rate", zap.BAUD_TO_CODE[115200])
        logs = [m["text"] for m in sent if m["type"] == "log"]
        assert any("failed" in t for t in logs), logs
        assert any("ID 4 answers at 115200 baud now and it stores baud-rate code 16 (115200)" in t
                   for t in logs), logs
        assert console.actuators[4]["baud"] == 115200 and act.baud == 115200
        assert bus.baud == 57600                                          # ID 1 is still polled there


def test_a_stored_rate_that_could_not_be_put_back_is_said_as_the_actuators_true_state():
    """The restart does not take and the rollback's write is lost too: the actuator answers at
    57600 but stores 115200's code (it would vanish at its next power-up): said, as an error."""
    with start_zap(ids=[1, 4], virtual=True) as sim, Bus(sim, timeout=0.05) as bus:
        console = _console(sim, bus)
        act = sim.device.actuator(4)
        heard = act.handle
        stores = []

        def handle(pkt, now):
            if pkt[5] == zap.RESTART:
                return None
            if pkt[5] == zap.STORE_DATA and pkt[6] == zap.REGISTER_BY_NAME["baud-rate"].address:
                stores.append(pkt)
                if len(stores) > 1:
                    return None                # the write back is lost
            return heard(pkt, now)

        act.handle = handle
        sent = _write(console, 4, "baud-rate", zap.BAUD_TO_CODE[115200])
        logs = [(m["level"], m["text"]) for m in sent if m["type"] == "log"]
        assert ("error", "ID 4 answers at 57600 baud, but it stores baud-rate code 16 (115200): it will answer at "
                         "115200 only after its next power-up") in logs, logs
        assert console.actuators[4]["baud"] == 57600 and act.get("baud-rate") == 16
