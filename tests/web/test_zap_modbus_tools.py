"""The zap console's plot, packet panel and byte log on a Modbus RTU bus (the 17Lf): a plotted
register is the map's (never the 12Lf IR register of that name, at another address), the packet
panel, which composes IR packets, is refused with its reason, and the bytes on the bus are
framed and decoded as Modbus RTU."""

from __future__ import annotations

import pytest

from zkzap import Bus
from zkzap.sim import start_zap
from zkzap.web.console import Request
from zkzap.web.zap_console import ZapConsole


class Hub:
    def __init__(self):
        self.sent, self.items, self.bytes = [], [], []

    def send(self, cid, msg):
        self.sent.append(msg)

    def broadcast(self, msg):
        self.sent.append(msg)

    def sample(self, item):
        self.items.append(item)

    def traffic(self, item):
        self.bytes.append(item)


@pytest.fixture
def rig():
    with start_zap(ids=[1], virtual=True, protocol="modbus") as sim, \
            Bus(sim, protocol="modbus", timeout=0.05) as bus:
        console = ZapConsole(bus, scan_ids=None)
        console.hub = Hub()
        for rec in bus.scan([1]):
            console.actuators[rec["id"]] = dict(rec, polled=True, link=None)
        yield sim, bus, console


def _ask(console, op, **fields):
    console.hub.sent.clear()
    console.handle(Request(1, "page 1", {"op": op, "req": 3, **fields}))
    return console.hub.sent


def test_a_plotted_register_is_the_maps(rig):
    sim, bus, console = rig
    _ask(console, "plot", register="goal-speed")
    assert console.plotted is bus.map.by_name["goal-speed"]
    with sim.lock:
        sim.device.actuator(1).set("goal-speed", 321)
    assert bus.read(1, console.plotted) == 321      # what the live view polls for the plot


@pytest.mark.parametrize("op", ["compose", "packet"])
def test_the_packet_panel_is_refused_with_its_reason(rig, op):
    sim, _, console = rig
    before = len(sim.device.received)
    sent = _ask(console, op, instruction="store", id=1, register="goal-position", value=100)
    error = next(m for m in sent if m["type"] == "error")
    assert "speaks Modbus RTU" in error["text"] and "zap raw --protocol modbus" in error["text"]
    assert len(sim.device.received) == before


def test_the_bytes_on_the_bus_are_modbus_frames_decoded(rig):
    _, bus, console = rig
    console.hub.bytes.clear()
    assert bus.read(1, "goal-speed") is not None
    items = console.hub.bytes
    assert [i["dir"] for i in items] == ["tx", "rx"], items
    assert all(not i.get("bad") for i in items), items
    assert "register=goal-speed" in items[0]["text"] and "kind=reply" in items[1]["text"], items


def test_the_page_plans_a_path_with_the_bus_s_own_frames(rig):
    """A path planned from the page on a Modbus bus is the library's Modbus plan: one answered Write
    Multiple Registers per actuator, the 17Lf's range (never IR Symmetric Store packets)."""
    _, _, console = rig
    sent = _ask(console, "plan", text='t,id,position\n0,1,9000\n0.5,1,100\n', name="wave.csv")
    reply = next(m for m in sent if m.get("req") == 3)
    assert [s["frames"] for s in reply["steps"]] == [["01 10 00 CD 00 01 02 23 28 AF 63"],
                                                     ["01 10 00 CD 00 01 02 00 64 B7 A6"]], reply
    sent = _ask(console, "plan", text='t,id,position\n0,248,5\n', name="bad.csv")
    assert any(m.get("type") == "error" and "1..247" in m.get("text", "") for m in sent), sent
