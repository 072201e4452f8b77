"""The mightyZAP console on a Modbus RTU bus (17Lf actuators), in a real browser: the page says
which protocol and model it speaks, scans Modbus IDs, plots the live view, and its register
table is the map's (decimal addresses, the 17Lf's registers), edited with the same consent rules.

The bus is the simulated 17Lf served over TCP from this process (a real port for consent)."""

from __future__ import annotations

import pytest

from zkzap.sim import start_zap

from webpage import (WebConsole, click, consent_dialog, console_errors, css, js, open_console, set_value, text_of,
                     until)


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
