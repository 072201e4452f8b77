"""The mightyZAP console in a real browser: scan, live table, moves, the register table's consent,
fleet backup/diff/apply, the self-check, a second page that watches, and a clean browser console.
The tests share one console and browser, and hold in any order.

The bus is the simulator served over TCP from this process: ``socket://`` is a real port for the
consent rules, so stored writes ask for confirmation as they would on hardware.
"""

from __future__ import annotations

import json

import pytest

from zkzap.sim import start_zap

from webpage import (WebConsole, click, console_errors, consent_dialog, css, js, open_console, set_value, text_of,
                     until)



@pytest.fixture(scope="session")
def bus():
    with start_zap(ids=[1, 2, 3], transport="tcp") as sim:
        yield sim


@pytest.fixture(scope="session")
def console(bus):
    # a reply timeout for a loaded test machine (the simulator runs in this process, beside the browser)
    c = WebConsole("zap", "-p", bus.url, "--scan-ids", "0-10", "--timeout", "0.3")
    yield c
    c.close()


@pytest.fixture
def opened(browser, console):
    """The browser on this module's console (opened with its token when it is elsewhere)."""
    if not browser.current_url.startswith(console.base):
        open_console(browser, console.url)
    until(lambda: len(css(browser, "#actuators tbody tr")) == 3, "the first scan's three actuators")
    return browser


@pytest.fixture
def page(opened):
    """The page, in control, with no job running on the bus."""
    until(lambda: "You control" in text_of(opened, "#control") and not css(opened, "#busy.show")
          and not css(opened, "#modal.show"),
          lambda: f"the page in control with the bus free (control: {text_of(opened, '#control')!r}, busy: "
                  f"{text_of(opened, '#busy')!r}, dialog: {text_of(opened, '#modal.show')!r})")
    return opened


def shown(page, ident) -> int:
    """The present position the page shows for ``ident`` (-1 while it shows none)."""
    text = text_of(page, f"#act-{ident} td.pos .big").replace(",", "")
    return int(text) if text.isdigit() else -1


def register(bus, ident, name):
    with bus.lock:
        return bus.device.actuator(ident).get(name)


def test_the_first_scan_lists_the_actuators_and_a_new_scan_shows_progress(page, console):
    assert [r.get_attribute("id") for r in css(page, "#actuators tbody tr")] == ["act-1", "act-2", "act-3"]
    assert "0xA112" in text_of(page, "#act-1") and "You control" in text_of(page, "#control")
    set_value(page, "#scan-ids", "0-20")
    click(page, "#scan")
    until(lambda: "probes" in text_of(page, "#scan-note"), "the scan's progress")
    until(lambda: "21 of 21 probes" in text_of(page, "#scan-note") and not css(page, "#busy.show"), "the scan to end")
    until(lambda: "3 found" in text_of(page, "#act-note"), "the table after the scan")
    assert "scan: 3 actuators found (IDs 1-3)" in console.stderr()


def test_the_live_view_follows_a_move_of_one_actuator(page, bus):
    set_value(page, "#act-2 td.goal input[type=range]", 3000, "input")
    others = register(bus, 1, "present-position")
    until(lambda: abs(register(bus, 2, "present-position") - 3000) <= 5, "the simulated actuator to reach 3000")
    until(lambda: abs(shown(page, 2) - 3000) <= 5, "the page to show it")
    assert register(bus, 1, "present-position") == others


def test_sync_move_moves_the_ticked_actuators_together(page, bus):
    before = register(bus, 2, "present-position")
    for ident in (1, 2, 3):
        box = css(page, f"#act-{ident} input.sync")[0]
        if box.is_selected() != (ident != 2):
            click(page, f"#act-{ident} input.sync")
    set_value(page, "#sync-pos", 1200)
    click(page, "#sync")
    until(lambda: all(abs(register(bus, i, "present-position") - 1200) <= 5 for i in (1, 3)), "both at 1200")
    assert register(bus, 2, "present-position") == before


def _registers(page, ident):
    js(page, "document.querySelector('#registers tbody').replaceChildren()")   # wait for the new table
    click(page, f"#act-{ident} button")                   # Registers
    until(lambda: f"of id {ident}" in text_of(page, "#reg-id").lower() and css(page, "#registers input[data-register=id]")
          and css(page, "#registers input[data-register=id]")[0].get_attribute("value") == str(ident),
          f"the register table of ID {ident}")


def _write(page, name, value):
    set_value(page, f"#registers [data-register={name}]:not(button)", value)
    click(page, f"#registers button[data-register={name}]")


def test_a_stored_write_asks_for_confirmation_and_a_refusal_writes_nothing(page, bus):
    _registers(page, 1)
    was = register(bus, 1, "long-stroke-limit")
    _write(page, "long-stroke-limit", 3500)
    assert "stored settings" in consent_dialog(page) and "long-stroke-limit" in text_of(page, "#modal-text")
    click(page, "#modal-cancel")
    until(lambda: "confirmation refused" in text_of(page, "#log"), "the refusal in the log")
    assert register(bus, 1, "long-stroke-limit") == was == 3686
    _registers(page, 1)
    _write(page, "long-stroke-limit", 3500)
    consent_dialog(page)
    click(page, "#modal-ok")
    until(lambda: register(bus, 1, "long-stroke-limit") == 3500, "the stored write")


def test_a_setting_that_changes_how_it_answers_needs_force_then_consent(page, bus):
    _registers(page, 2)
    _write(page, "protocol-type", 1)
    assert "changes how the actuator is reached" in consent_dialog(page)
    assert not css(page, "#modal-ok")[0].is_enabled()      # not before 'force' is ticked
    click(page, "#modal-force")
    click(page, "#modal-ok")
    until(lambda: "stored" in text_of(page, "#modal.show #modal-text"), "the stored-write confirmation next")
    click(page, "#modal-ok")
    until(lambda: "protocol-type = 1" in text_of(page, "#log"), "the write in the log")


def test_backup_diff_and_apply_of_a_fleet_file(page, bus, tmp_path):
    doc = json.loads(js(page, "return (await Z.request('backup', {format: 'json'})).text;"))
    assert sorted(doc["actuators"]) == ["1", "2", "3"]
    doc["actuators"]["2"]["stored"]["acceleration"] = 33
    del doc["actuators"]["3"]                         # ID 3 is then on the bus only: a row of the diff too
    path = tmp_path / "fleet.json"
    path.write_text(json.dumps(doc))
    css(page, "#fleet-file")[0].send_keys(str(path))
    click(page, "#diff")
    until(lambda: "acceleration" in text_of(page, "#fleet-out"), "the diff table")
    rows = [r.text.split() for r in css(page, "#fleet-out tbody tr")]
    assert ["3", "(actuator)", "absent", "present"] in [r[:2] + r[3:5] for r in rows], rows
    assert register(bus, 2, "acceleration") != 33
    click(page, "#apply")
    assert "survive power-off" in consent_dialog(page)
    click(page, "#modal-ok")
    until(lambda: register(bus, 2, "acceleration") == 33, "the apply's write")
    until(lambda: "1 writes made, 0 not verified" in text_of(page, "#fleet-out"), "the apply's result")


def test_the_self_check_moves_after_consent_and_shows_its_verdicts(page, bus):
    click(page, "#act-3 .btn:nth-child(2)")             # Check
    assert "full stroke" in consent_dialog(page)
    click(page, "#modal-ok")
    until(lambda: "verdict" in text_of(page, "#check-out"), "the check's verdicts", timeout=60)
    assert "ID 3: pass" in text_of(page, "#check-note")


def test_a_second_page_watches_and_cannot_move(page, bus, console):
    first = page.current_window_handle
    page.switch_to.new_window("window")
    try:
        page.get(console.base + "/")                        # the cookie carries the token
        until(lambda: "View only" in text_of(page, "#control"), "the second page's view-only banner")
        assert "page 1" in text_of(page, "#control")
        until(lambda: css(page, "#act-1"), "its table")
        assert not css(page, "#act-1 td.goal input[type=range]")[0].is_enabled()
        err = js(page, "try { await Z.request('move', {id: 1, position: 100}); return null; }"
                       " catch (e) { return e.message; }")
        assert err.startswith("view only: page 1")
        assert console_errors(page) == []
    finally:
        page.close()
        page.switch_to.window(first)
    assert abs(register(bus, 1, "present-position") - 100) > 50


def test_no_errors_in_the_browser_console(opened):
    page = opened
    assert console_errors(page) == []
    assert js(page, "return window.zkzapStats.errors") == 0
    assert js(page, "return window.zkzapStats.samples") > 0


def test_speed_and_current_goals_beside_the_slider(page, bus):
    until(lambda: js(page, "return document.querySelector('#act-3 input.goal-speed').value") != "",
          "the goal speed the actuator holds")
    assert js(page, "return document.querySelector('#act-3 input.goal-speed').value") == \
        str(register(bus, 3, "goal-speed"))
    set_value(page, "#act-3 input.goal-speed", 300)
    set_value(page, "#act-3 input.goal-current", 650)
    until(lambda: register(bus, 3, "goal-speed") == 300 and register(bus, 3, "goal-current") == 650,
          "the actuator's goal speed and current")
    until(lambda: js(page, "return document.querySelector('#act-3 input.goal-speed').value") == "300"
          and js(page, "return document.querySelector('#act-3 input.goal-current').value") == "650",
          "the page to show what the actuator holds now")


def test_the_ranges_and_the_voltage_are_the_ir_map_s(page, bus):
    """On the IR protocol the ranges are the 12Lf table's (positions 0..4095, goal speed 0..1023,
    goal current 0..1600 mA) and the voltage is in volts, as the table scales it (0.1 V)."""
    for sel in ("#act-1 td.goal input[type=range]", "#act-1 td.goal input[type=number]", "#sync-range", "#cycle-b"):
        e = css(page, sel)[0]
        assert (e.get_attribute("min"), e.get_attribute("max")) == ("0", "4095"), sel
    assert css(page, "#act-1 input.goal-speed")[0].get_attribute("max") == "1023"
    assert css(page, "#act-1 input.goal-current")[0].get_attribute("max") == "1600"
    raw = register(bus, 1, "present-voltage")
    until(lambda: text_of(page, "#act-1 td.volt") == f"{raw / 10:.1f} V", "the voltage in volts")
    titles = [t.get_attribute("textContent") for t in css(page, "#plots .plot .title b")]
    assert titles == ["Position", "Current (mA)", "Voltage (V)"], titles
    assert console_errors(page) == []
