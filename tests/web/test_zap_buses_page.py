"""The mightyZAP console of several buses, in a real browser: ``zkzap web zap -p A -p B`` (and
``--buses`` of a fleet file) shows every bus's actuators under its bus; an actuator is its bus
and ID (both buses have an ID 1): a move, the register table and a stored write reach that
bus's actuator only; a bus whose port dies is shown failed while the other keeps polling; the
IR protocol and Modbus RTU alike.

Each bus is a simulator served over TCP from this process (real ports for the consent rules),
so the tests see each bus's actuators.
"""

from __future__ import annotations

import json
import os
import subprocess

import pytest

from zkzap.sim import start_zap

from e2e.conftest import clean_env, executable
from webpage import WebConsole, click, console_errors, consent_dialog, css, js, open_console, set_value, text_of, until

SHOTS = os.environ.get("ZKZAP_SHOTS")          # a directory: the tests leave their screenshots there


@pytest.fixture(scope="session")
def bus_a():
    with start_zap(ids=[1, 2], transport="tcp") as sim:
        yield sim


@pytest.fixture(scope="session")
def bus_b():
    with start_zap(ids=[1, 3], transport="tcp") as sim:
        yield sim


@pytest.fixture(scope="session")
def two(bus_a, bus_b):
    c = WebConsole("zap", "-p", bus_a.url, "-p", bus_b.url, "--scan-ids", "0-5", "--timeout", "0.3")
    yield c
    c.close()


def ready(browser, console, rows, what):
    """The browser on ``console`` with ``rows`` actuator rows, in control, every bus free."""
    if not browser.current_url.startswith(console.base):
        open_console(browser, console.url)
    until(lambda: len(css(browser, "#actuators tbody tr[data-id]")) == rows, what)
    until(lambda: "You control" in text_of(browser, "#control") and not css(browser, "#busy.show")
          and not css(browser, "#buses .state.warn") and not css(browser, "#modal.show"),
          "the page in control with every bus free")
    return browser


@pytest.fixture
def page(browser, two):
    return ready(browser, two, 4, "both buses' actuators")


def reg(bus, ident, name):
    with bus.lock:
        return bus.device.actuator(ident).get(name)


def shown(page, row) -> int:
    text = text_of(page, f"#{row} td.pos .big").replace(",", "")
    return int(text) if text.isdigit() else -1


def shot(page, name):
    if SHOTS:
        page.save_screenshot(os.path.join(SHOTS, name))


def test_every_bus_is_listed_with_its_actuators_under_its_name(page, two, bus_a, bus_b):
    assert [r.get_attribute("id") for r in css(page, "#actuators tbody tr[data-id]")] == \
        ["act-0-1", "act-0-2", "act-1-1", "act-1-3"]
    assert [r.get_attribute("data-bus") for r in css(page, "#actuators tr.bushead")] == [bus_a.url, bus_b.url]
    heads = [r.text for r in css(page, "#actuators tr.bushead")]
    assert f"bus 1: {bus_a.url}" in heads[0] and "IR" in heads[0] and "2 found" in heads[0]
    assert [b.get_attribute("data-bus") for b in css(page, "#buses .busbtn")] == [bus_a.url, bus_b.url]
    assert "2 actuators" in text_of(page, "#bus-1") and "IR" in text_of(page, "#bus-1")
    assert "2 buses" in text_of(page, "#port")
    # each bus polled: both buses' actuators show a live position
    until(lambda: shown(page, "act-0-1") >= 0 and shown(page, "act-1-3") >= 0, "live positions on both buses")
    until(lambda: "4 polled" in text_of(page, "#link"), "the polls of both buses")
    # the live plots have a series a bus and ID
    keys = [k.text for k in css(page, "#plots .plot:first-child .key")]
    assert keys == ["bus 1 ID 1", "bus 1 ID 2", "bus 2 ID 1", "bus 2 ID 3"]     # a long port: bus N
    assert text_of(page, "#bushead-1 b") == f"bus 2: {bus_b.url}"
    assert f"scan: 2 actuators found (IDs 1,3)" in two.stderr() and f"bus {bus_b.url}: scan" in two.stderr()
    shot(page, "zap-buses.png")
    assert console_errors(page) == []


def test_a_move_of_id_1_on_bus_b_moves_bus_b_actuator_only(page, bus_a, bus_b):
    target = 3000 if abs(reg(bus_b, 1, "present-position") - 3000) > 50 else 1000
    was = reg(bus_a, 1, "present-position")
    set_value(page, "#act-1-1 td.goal input[type=range]", target, "input")
    until(lambda: abs(reg(bus_b, 1, "present-position") - target) <= 5, "bus B's ID 1 to reach the goal")
    until(lambda: abs(shown(page, "act-1-1") - target) <= 5, "the page to show bus B's ID 1 there")
    assert reg(bus_a, 1, "goal-position") != target and reg(bus_a, 1, "present-position") == was
    assert abs(shown(page, "act-0-1") - was) <= 5


def test_the_register_table_of_an_actuator_reads_its_own_bus(page, bus_a, bus_b):
    with bus_a.lock:
        bus_a.device.actuator(1).set("short-stroke-limit", 111)
    with bus_b.lock:
        bus_b.device.actuator(1).set("short-stroke-limit", 222)

    def table(row, bus, value):
        js(page, "document.querySelector('#registers tbody').replaceChildren()")
        click(page, f"#{row} button")                  # Registers
        until(lambda: f"on bus {bus.url}" in text_of(page, "#reg-id").lower()
              and css(page, "#registers input[data-register=short-stroke-limit]")
              and css(page, "#registers input[data-register=short-stroke-limit]")[0].get_attribute("value")
              == str(value), lambda: f"the register table of ID 1 on {bus.url} (shown: {text_of(page, '#reg-id')!r}, "
              f"{[e.get_attribute('value') for e in css(page, '#registers input[data-register=short-stroke-limit]')]})")

    table("act-0-1", bus_a, 111)
    assert "chosen" in css(page, "#bus-0")[0].get_attribute("class")
    assert f"bus {bus_a.url}" in text_of(page, "#scan-bus").lower()
    table("act-1-1", bus_b, 222)
    assert "chosen" in css(page, "#bus-1")[0].get_attribute("class")
    assert "chosen" not in css(page, "#bus-0")[0].get_attribute("class")


def test_a_stored_write_asks_consent_and_writes_the_chosen_bus_only(page, bus_a, bus_b):
    js(page, "document.querySelector('#registers tbody').replaceChildren()")   # wait for the new table
    click(page, "#act-1-1 button")                     # bus B's ID 1: Registers
    until(lambda: f"on bus {bus_b.url}" in text_of(page, "#reg-id").lower()
          and css(page, "#registers input[data-register=long-stroke-limit]"), "bus B's register table")
    a_was = reg(bus_a, 1, "long-stroke-limit")
    new = 3500 if reg(bus_b, 1, "long-stroke-limit") != 3500 else 3400
    set_value(page, "#registers [data-register=long-stroke-limit]:not(button)", new)
    click(page, "#registers button[data-register=long-stroke-limit]")
    assert "stored settings" in consent_dialog(page)
    click(page, "#modal-ok")
    until(lambda: reg(bus_b, 1, "long-stroke-limit") == new, "bus B's ID 1 to store the new limit")
    assert reg(bus_a, 1, "long-stroke-limit") == a_was


def test_stop_all_stops_every_bus(page, bus_a, bus_b):
    for sim, row in ((bus_a, "act-0-2"), (bus_b, "act-1-3")):
        with sim.lock:
            sim.device.actuator(int(row[-1])).set("goal-speed", 40)   # slow: still moving when stopped
    set_value(page, "#act-0-2 td.goal input[type=number]", 4000 if reg(bus_a, 2, "present-position") < 2000 else 100)
    set_value(page, "#act-1-3 td.goal input[type=number]", 4000 if reg(bus_b, 3, "present-position") < 2000 else 100)
    until(lambda: reg(bus_a, 2, "moving") and reg(bus_b, 3, "moving"), "both actuators moving")
    click(page, "#stopall")
    until(lambda: not reg(bus_a, 2, "moving") and not reg(bus_b, 3, "moving"), "both buses' actuators stopped")
    for sim, ident in ((bus_a, 2), (bus_b, 3)):
        with sim.lock:
            sim.device.actuator(ident).set("goal-speed", 1023)


def test_the_packet_panel_and_a_cycle_act_on_the_chosen_bus_while_the_other_bus_moves(page, bus_a, bus_b):
    click(page, "#bus-1")                              # bus B for the panels
    until(lambda: "chosen" in css(page, "#bus-1")[0].get_attribute("class"), "bus B chosen")
    goal = 1500 if reg(bus_a, 1, "goal-position") != 1500 else 1600
    a_goal = reg(bus_a, 1, "goal-position")
    set_value(page, "#pkt-ins", "store")
    set_value(page, "#pkt-id", 1)
    set_value(page, "#pkt-reg", "goal-position")
    set_value(page, "#pkt-value", goal)
    until(lambda: f"store goal-position={goal} to ID 1" in text_of(page, "#pkt-describe"), "the packet composed")
    click(page, "#pkt-send")
    until(lambda: reg(bus_b, 1, "goal-position") == goal, "bus B's ID 1 to take the packet's goal")
    assert reg(bus_a, 1, "goal-position") == a_goal
    until(lambda: "goal-position" in text_of(page, "#traffic"), "the packet among bus B's bytes")
    # a cycle of bus B's ID 1; meanwhile bus A is free and moves
    set_value(page, "#cycle-id", 1)
    set_value(page, "#cycle-a", 1000)
    set_value(page, "#cycle-b", 2000)
    set_value(page, "#cycle-n", 3)
    set_value(page, "#cycle-dwell", 0.3)
    click(page, "#cycle-go")
    until(lambda: "cycle" in text_of(page, "#bus-1 .state"), "bus B shown running the cycle")
    assert "cycle" not in text_of(page, "#bus-0 .state")
    target = 3500 if reg(bus_a, 2, "present-position") < 2000 else 500
    set_value(page, "#act-0-2 td.goal input[type=number]", target)
    until(lambda: abs(reg(bus_a, 2, "present-position") - target) <= 5, "bus A's ID 2 to move during bus B's cycle")
    until(lambda: "3 cycles in" in text_of(page, "#cycle-sum"), "the cycle's summary", timeout=60)
    assert len(css(page, "#cycle-table tbody tr")) == 3
    assert reg(bus_a, 1, "goal-position") == a_goal and reg(bus_b, 1, "goal-position") in (1000, 2000)
    # bus A's panels start empty; bus B's run is shown again when it is chosen again
    click(page, "#bus-0")
    until(lambda: not css(page, "#cycle-table tbody tr") and text_of(page, "#cycle-sum") == "", "bus A's cycle panel")
    click(page, "#bus-1")
    until(lambda: len(css(page, "#cycle-table tbody tr")) == 3 and "3 cycles in" in text_of(page, "#cycle-sum"),
          "bus B's cycle run shown again")
    assert console_errors(page) == []


def test_every_request_goes_to_the_bus_it_names_and_one_naming_none_is_refused(browser, two, bus_a, bus_b):
    """Over the WebSocket, as a page sends them: a backup of bus B is bus B's document; a request
    naming no bus, or an unknown one, is refused saying which buses there are."""
    import asyncio

    aiohttp = pytest.importorskip("aiohttp")
    from webpage import open_page, wait

    browser.get("about:blank")                         # the browser's page no longer controls

    async def main():
        async with aiohttp.ClientSession() as s:
            p = await open_page(s, two)
            await wait(lambda: p.seen("hello") and len(p.seen("bushello")) == 2, "the buses' hellos")
            assert [b["name"] for b in p.seen("hello")[0]["buses"]] == [bus_a.url, bus_b.url]
            assert [m["bus"] for m in p.seen("bushello")] == [bus_a.url, bus_b.url]
            for _ in range(100):
                if (await p.request("take"))["type"] == "done":
                    break
                await asyncio.sleep(0.1)
            got = await p.request("backup", bus=bus_b.url, format="json")
            assert got["type"] == "done" and got["bus"] == bus_b.url, got
            doc = json.loads(got["text"])
            assert doc["port"] == bus_b.url and sorted(doc["actuators"]) == ["1", "3"]
            none = await p.request("registers", id=1)
            assert none["type"] == "error" and none["text"] == f"bus: none given; the buses: {bus_a.url}, {bus_b.url}"
            unknown = await p.request("registers", id=1, bus="nope")
            assert unknown["type"] == "error" and unknown["text"].startswith("bus: no bus 'nope'")
            mine = await p.request("registers", id=3, bus=bus_a.url)      # ID 3 is bus B's only
            assert mine["type"] == "error" and "no actuator 3 was found" in mine["text"] and mine["bus"] == bus_a.url
            await p.ws.close()

    asyncio.run(asyncio.wait_for(main(), 60))


@pytest.fixture(scope="session")
def mixed():
    # bus 1 the in-process simulator (consent waived there), bus 2 a real port
    with start_zap(ids=[1], transport="tcp") as real:
        c = WebConsole("zap", "-p", "sim://zap?ids=1", "-p", real.url, "--scan-ids", "0-2", "--timeout", "0.3")
        yield c, real
        c.close()


def test_consent_is_each_bus_s_own(browser, mixed):
    console, real = mixed
    page = ready(browser, console, 2, "both buses' actuators")
    assert "simulated" in text_of(page, "#bus-0") and "simulated" not in text_of(page, "#bus-1")
    assert "(simulated)" not in text_of(page, "#port")

    def write(row, value):
        js(page, "document.querySelector('#registers tbody').replaceChildren()")
        click(page, f"#{row} button")                  # Registers
        until(lambda: css(page, "#registers input[data-register=long-stroke-limit]"), f"the register table of {row}")
        set_value(page, "#registers [data-register=long-stroke-limit]:not(button)", value)
        click(page, "#registers button[data-register=long-stroke-limit]")

    write("act-0-1", 3500)                            # the simulator: written at once, nothing asked
    until(lambda: "long-stroke-limit = 3500 (stored, reads back 3500)" in text_of(page, "#log"), "the simulated write")
    assert not css(page, "#modal.show")
    write("act-1-1", 3400)                            # the real port: asked first
    assert "stored settings" in consent_dialog(page)
    click(page, "#modal-ok")
    until(lambda: reg(real, 1, "long-stroke-limit") == 3400, "the real port's write once confirmed")


# -- a bus that dies ---------------------------------------------------------------------------


@pytest.fixture(scope="session")
def dying():
    with start_zap(ids=[1, 2], transport="tcp") as a, start_zap(ids=[1], transport="tcp") as b:
        c = WebConsole("zap", "-p", a.url, "-p", b.url, "--scan-ids", "0-3", "--timeout", "0.3")
        yield c, a, b
        c.close()


def test_a_bus_whose_port_dies_is_shown_failed_and_the_other_goes_on(browser, dying):
    console, a, b = dying
    page = ready(browser, console, 3, "both buses' actuators")
    until(lambda: shown(page, "act-0-1") >= 0 and shown(page, "act-1-1") >= 0, "live positions on both buses")
    a.close()                                          # bus A's port goes away
    until(lambda: "failed" in text_of(page, "#bus-0 .state"), "bus A shown failed")
    until(lambda: "bus failed" in text_of(page, "#act-0-1") and "bus failed" in text_of(page, "#act-0-2"),
          "bus A's actuators shown on a failed bus")
    assert "failed" not in text_of(page, "#bus-1 .state")
    until(lambda: "1 polled" in text_of(page, "#link"), "the failed bus's actuators no longer counted as polled")
    assert f"Bus {a.url} stopped" in text_of(page, "#banner")
    # bus B keeps polling and moving
    target = 3000 if abs(reg(b, 1, "present-position") - 3000) > 50 else 1000
    set_value(page, "#act-1-1 td.goal input[type=number]", target)
    until(lambda: abs(reg(b, 1, "present-position") - target) <= 5, "bus B's ID 1 to move")
    until(lambda: abs(shown(page, "act-1-1") - target) <= 5, "the page to show bus B still polled")
    # a request to the failed bus is refused, saying so
    click(page, "#act-0-1 button")                     # Registers of bus A's ID 1
    until(lambda: f"bus {a.url} failed" in text_of(page, "#toasts"), "the refusal of the failed bus")
    assert f"bus {a.url}: stopped" in console.stderr()
    shot(page, "zap-buses-failed.png")


@pytest.fixture(scope="session")
def slow_and_fast():
    # bus A's actuator answers after 120 ms (a slow adapter or line), bus B's at once
    with start_zap(ids=[1], transport="tcp", turnaround=120) as a, start_zap(ids=[1], transport="tcp") as b:
        c = WebConsole("zap", "-p", a.url, "-p", b.url, "--scan-ids", "1", "--timeout", "0.3", "--rate", "30")
        yield c, a, b
        c.close()


def test_a_slow_bus_does_not_slow_the_other(browser, slow_and_fast):
    console, a, b = slow_and_fast
    page = ready(browser, console, 2, "both buses' actuators")
    until(lambda: shown(page, "act-0-1") >= 0 and shown(page, "act-1-1") >= 0, "live positions on both buses")
    js(page, "window.per = {}; Z.every('samples', (m) => { for (const s of m.items) if (s.status === 'ok')"
             " window.per[s.bus] = (window.per[s.bus] || 0) + 1; });")
    t0 = js(page, "return performance.now()")
    until(lambda: js(page, "return performance.now()") - t0 > 4000, "4 s of samples", interval=0.2)
    per = js(page, "return window.per")
    seconds = (js(page, "return performance.now()") - t0) / 1000
    slow, fast = per.get(a.url, 0) / seconds, per.get(b.url, 0) / seconds
    # the slow bus is polled at most 1/0.12 s; the fast one at its --rate, whatever the slow one does
    assert slow <= 9 and fast >= 15 and fast >= 2.5 * slow, (slow, fast)


# -- a fleet file's buses, and Modbus RTU ------------------------------------------------------


@pytest.fixture(scope="session")
def modbus_buses(tmp_path_factory):
    with start_zap(ids=[1, 2], transport="tcp", protocol="modbus") as a, \
            start_zap(ids=[1], transport="tcp", protocol="modbus") as b:
        fleet = tmp_path_factory.mktemp("buses") / "machine.json"
        fleet.write_text(json.dumps({"format": "zkzap-fleet/2", "protocol": "modbus", "actuators": {"1": {}}, "buses": {"left": {"port": a.url, "ids": [1, 2]},
                                                                     "right": {"port": b.url, "ids": [1]}}}))
        c = WebConsole("zap", "--protocol", "modbus", "--fleet", str(fleet), "--buses", "all", "--timeout", "0.3")
        yield c, a, b
        c.close()


def test_a_fleet_file_s_modbus_buses_are_shown_by_name_and_a_move_reaches_its_bus(browser, modbus_buses):
    console, a, b = modbus_buses
    page = ready(browser, console, 3, "the fleet file's buses' 17Lf actuators")
    assert [x.get_attribute("data-bus") for x in css(page, "#buses .busbtn")] == ["left", "right"]
    assert "Modbus RTU" in text_of(page, "#bus-0") and "Modbus RTU" in text_of(page, "#bushead-1")
    assert "Modbus RTU" in text_of(page, "#protocol")
    keys = [k.text for k in css(page, "#plots .plot:first-child .key")]
    assert keys == ["left ID 1", "left ID 2", "right ID 1"]
    assert [r.get_attribute("id") for r in css(page, "#actuators tbody tr[data-id]")] == ["act-0-1", "act-0-2", "act-1-1"]
    was = reg(a, 1, "present-position")
    target = 8000 if abs(reg(b, 1, "present-position") - 8000) > 100 else 2000
    set_value(page, "#act-1-1 td.goal input[type=number]", target)
    until(lambda: abs(reg(b, 1, "present-position") - target) <= 10, "bus right's ID 1 to move")
    assert reg(a, 1, "present-position") == was
    js(page, "document.querySelector('#registers tbody').replaceChildren()")
    click(page, "#act-0-1 button")                     # left's ID 1: its register table
    until(lambda: "on bus left" in text_of(page, "#reg-id").lower() and css(page, "#registers input[data-register=goal-speed]"),
          "the register table of left's ID 1")
    assert "bus left:" in console.stderr() and "bus right:" in console.stderr()
    shot(page, "zap-buses-modbus.png")
    assert console_errors(page) == []


def _web_zap(*args):
    return subprocess.run([executable("zkzap"), "web", "zap", *args, "--listen", "127.0.0.1:0"],
                          capture_output=True, text=True, env=clean_env(), timeout=60, stdin=subprocess.DEVNULL)


@pytest.mark.parametrize("args, said", [
    (("--sim", "-p", "sim://zap?ids=1", "-p", "sim://zap?ids=2"), "not with --sim"),
    (("-p", "sim://zap?ids=1", "-p", "sim://zap?ids=1"), "is given twice"),
    (("--buses", "all"), "--buses: needs --fleet FILE"),
])
def test_several_buses_are_refused_as_the_other_commands_refuse_them(args, said):
    r = _web_zap(*args)
    assert r.returncode == 2 and r.stdout == "" and said in r.stderr, r.stderr


def test_a_fleet_file_of_another_protocol_is_refused(tmp_path):
    fleet = tmp_path / "machine.json"
    fleet.write_text(json.dumps({"format": "zkzap-fleet/2", "protocol": "modbus", "actuators": {"1": {}}, "buses": {"left": {"port": "sim://zap?ids=1", "ids": [1]}}}))
    r = _web_zap("--fleet", str(fleet), "--buses", "all")
    assert r.returncode == 2 and r.stdout == "" and "speak the modbus protocol; give --protocol modbus" in r.stderr
