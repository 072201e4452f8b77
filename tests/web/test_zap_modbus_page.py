"""The mightyZAP console on a Modbus RTU bus (17Lf actuators), in a real browser: the page says
which protocol and model it speaks, scans Modbus IDs, plots the live view, and its register
table is the map's (decimal addresses, the 17Lf's registers), edited with the same consent rules.

The bus is the simulated 17Lf served over TCP from this process (a real port for consent)."""

from __future__ import annotations

import os

import pytest

from zkzap.sim import start_zap

from webpage import (WebConsole, click, consent_dialog, console_errors, css, js, open_console, set_value, text_of,
                     until)

SHOTS = os.environ.get("ZKZAP_SHOTS")          # a directory: the tests leave their screenshots there


@pytest.fixture(scope="module")
def bus():
    with start_zap(ids=[1, 2], transport="tcp", protocol="modbus") as sim:
        yield sim


@pytest.fixture(scope="module")
def console(bus):
    c = WebConsole("zap", "--protocol", "modbus", "-p", bus.url, "--scan-ids", "1-5", "--timeout", "0.3")
    yield c
    c.close()


@pytest.fixture
def page(browser, console):
    open_console(browser, console.url)
    until(lambda: len(css(browser, "#actuators tbody tr")) == 2, "the first scan's two 17Lf actuators")
    until(lambda: "You control" in text_of(browser, "#control") and not css(browser, "#busy.show"),
          "the page in control with the bus free")
    return browser


def register(bus, ident, name):
    with bus.lock:
        return bus.device.actuator(ident).get(name)


def _registers(page, ident):
    js(page, "document.querySelector('#registers tbody').replaceChildren()")   # wait for the new table
    click(page, f"#act-{ident} button")                   # Registers
    until(lambda: f"of id {ident}" in text_of(page, "#reg-id").lower()
          and css(page, "#registers input[data-register=goal-speed]"), f"the register table of ID {ident}")


def test_the_page_says_modbus_and_lists_the_17lf_map(page, console):
    assert text_of(page, "#protocol") == "Modbus RTU · 17Lf"
    assert [r.get_attribute("id") for r in css(page, "#actuators tbody tr")] == ["act-1", "act-2"]
    assert "scan: 2 actuators found (IDs 1-2)" in console.stderr()
    assert css(page, "#scan-ids")[0].get_attribute("value") == "1-247"
    _registers(page, 1)
    rows = {r.find_elements("css selector", "td")[1].text: r.find_elements("css selector", "td")[0].text
            for r in css(page, "#registers tbody tr")}
    assert rows["force-on-off"] == "200" and rows["goal-position"] == "205" and rows["present-position"] == "210"
    assert "protocol-type" not in rows and "feedback-return-mode" not in rows      # not the 12Lf's table
    until(lambda: text_of(page, "#act-1 td.pos .big") != "", "the live view's position")
    assert not console_errors(page)


def test_a_volatile_write_goes_and_a_stored_one_asks_first(page, bus):
    _registers(page, 2)
    set_value(page, "#registers [data-register=goal-speed]:not(button)", 444)
    click(page, "#registers button[data-register=goal-speed]")
    until(lambda: register(bus, 2, "goal-speed") == 444, "the volatile write on the 17Lf")
    _registers(page, 2)
    was = register(bus, 2, "speed-limit")
    set_value(page, "#registers [data-register=speed-limit]:not(button)", 700)
    click(page, "#registers button[data-register=speed-limit]")
    assert "stored settings" in consent_dialog(page) and "speed-limit" in text_of(page, "#modal-text")
    click(page, "#modal-cancel")
    until(lambda: "confirmation refused" in text_of(page, "#log"), "the refusal in the log")
    assert register(bus, 2, "speed-limit") == was
    _registers(page, 2)
    set_value(page, "#registers [data-register=speed-limit]:not(button)", 700)
    click(page, "#registers button[data-register=speed-limit]")
    consent_dialog(page)
    click(page, "#modal-ok")
    until(lambda: register(bus, 2, "speed-limit") == 700, "the stored write after consent")


def test_every_range_and_the_voltage_are_the_map_s(page, bus, console):
    """The position slider, its number, the bar, the goal speed and current, the sync move and
    the cycle's ends span the 17Lf map's ranges (positions 0..10000, never the IR 0..4095), and
    present-voltage, which the map gives no unit, is shown raw and said to be raw: never volts."""
    regs = {r["name"]: r for r in console_hello(page)}
    lo, hi = regs["goal-position"]["lo"], regs["goal-position"]["hi"]
    assert (lo, hi) == (0, 10000)
    for sel in ("#act-1 td.goal input[type=range]", "#act-1 td.goal input[type=number]", "#sync-range", "#sync-pos",
                "#cycle-a", "#cycle-b"):
        e = css(page, sel)[0]
        assert (e.get_attribute("min"), e.get_attribute("max")) == (str(lo), str(hi)), sel
    for name in ("goal-speed", "goal-current"):
        e = css(page, f"#act-1 input.{name}")[0]
        assert (e.get_attribute("min"), e.get_attribute("max")) == (str(regs[name]["lo"]), str(regs[name]["hi"]))
    set_value(page, "#act-1 td.goal input[type=range]", 7500, "input")
    until(lambda: register(bus, 1, "present-position") == 7500, "the 17Lf to reach 7500 (beyond the IR range)")
    until(lambda: text_of(page, "#act-1 td.pos .big") == "7,500", "the live view at 7500")
    bar = css(page, "#act-1 .posbar i")[0].get_attribute("style")
    assert "calc(75% - 1px)" in bar, bar                          # 7500 of 0..10000
    raw = register(bus, 1, "present-voltage")
    until(lambda: text_of(page, "#act-1 td.volt") == f"{raw} (raw)", "the raw voltage, said to be raw")
    assert " V" not in text_of(page, "#act-1 td.volt")
    titles = [t.get_attribute("textContent") for t in css(page, "#plots .plot .title b")]
    assert titles == ["Position", "Current (mA)", "Voltage (raw: the map gives no unit)"], titles
    set_value(page, "#cycle-id", 1)
    set_value(page, "#cycle-a", 6000)
    set_value(page, "#cycle-b", 9000)
    set_value(page, "#cycle-n", 1)
    set_value(page, "#cycle-dwell", 0)
    click(page, "#cycle-go")
    until(lambda: "1 cycles in" in text_of(page, "#cycle-sum"), "the cycle beyond the IR range", timeout=60)
    head = [th.get_attribute("textContent") for th in css(page, "#cycle-table thead th")]
    assert "min voltage (raw)" in head and "min V" not in head, head
    cell = css(page, "#cycle-table tbody tr td")[head.index("min voltage (raw)")].text
    assert cell == f"{raw} (raw)", cell
    if SHOTS:
        page.save_screenshot(os.path.join(SHOTS, "zap-modbus.png"))
    assert not console_errors(page)


def console_hello(page):
    """The register map the console sent the page (its hello)."""
    return js(page, "return Z.hello && Z.hello.registers")
