"""The ZK console in a real browser: the live view, a start under consent with rpm rising, the
abort, a second page that watches (and may abort), the dead-man rule when the controlling tab
closes, and a clean browser console.

The ECU is the simulator (ten times faster than real time) served over TCP from this process:
``socket://`` is a real port for the consent rules, so a start asks for confirmation. The tests
share one console and browser, and hold in any order.
"""

from __future__ import annotations

import pytest

from zkzap.sim import start_zk

from webpage import (WebConsole, click, console_errors, consent_dialog, css, js, set_value, take_control, text_of,
                     open_console, until)



@pytest.fixture(scope="session")
def ecu():
    with start_zk(speed=10, transport="tcp") as sim:
        yield sim


@pytest.fixture(scope="session")
def console(ecu):
    c = WebConsole("zk", "-p", ecu.url, "--limit", "egt_c<=950,warn=900")
    yield c
    import sys
    print(f"console pid {c.proc.pid}:", c.stderr(), file=sys.stderr)
    c.close()


@pytest.fixture
def opened(browser, console):
    """The browser on this module's console (opened with its token when it is elsewhere)."""
    if not browser.current_url.startswith(console.base):
        open_console(browser, console.url)
    return browser


@pytest.fixture
def page(opened, console, ecu):
    """The page, in control, with the engine not running."""
    until(lambda: text_of(opened, "#control") not in ("", "not connected"), "the page's control banner")
    if "You control" not in text_of(opened, "#control"):
        opened.get(console.base + "/")
        take_control(opened)
    until(lambda: "frames/s" in text_of(opened, "#link"), "the status stream")
    if sw(ecu) == "run":
        click(opened, "#abort")
    until(lambda: sw(ecu) != "run" and text_of(opened, "#state") not in ("running", "ignition", "preheat", "fuel-ramp"),
          "the engine out of a run", timeout=60)
    clear_alarms(opened)
    return opened


def clear_alarms(page):
    """Acknowledge what an earlier test's abort latched, and wait until a start is allowed."""
    if css(page, "#ack")[0].is_enabled():
        click(page, "#ack")
        until(lambda: "LATCHED" not in text_of(page, "#alarms"), "the alarms acknowledged")
    until(lambda: "refused" not in text_of(page, "#interlock"), "the engine at rest and cool", timeout=60)


def sw(ecu):
    with ecu.lock:
        return ecu.device.effective_sw()


def rpm_shown(page):
    text = text_of(page, "#g-rpm .gv").replace(",", "")
    return int(text) if text.isdigit() else None


def start(page, throttle=30):
    """Start at ``throttle`` (after a trip: at setpoint 0, then the throttle raised)."""
    first = 0 if "setpoint 0" in text_of(page, "#interlock") else throttle
    set_value(page, "#throttle", first)
    click(page, "#start")
    assert "can start the engine" in consent_dialog(page)
    click(page, "#modal-ok")
    until(lambda: "Running under this console" in text_of(page, "#command") or text_of(page, ".toast:not(.info)"),
          "the run to start")
    assert "Running under this console" in text_of(page, "#command"), text_of(page, "#toasts")
    if first != throttle:
        set_value(page, "#throttle", throttle)
    return first


def test_the_page_shows_the_status_stream_and_the_limits(page):
    until(lambda: text_of(page, "#state") not in ("", "–"), "the engine state")
    assert text_of(page, "#state") in ("stop", "standby", "cooling")
    assert "egt_c<=950,warn=900" in text_of(page, "#limits")
    assert "You control" in text_of(page, "#control")


def test_a_start_asks_for_consent_the_rpm_rises_and_abort_sends_standby(page, ecu, console):
    first = start(page, 30)
    until(lambda: "Running under this console" in text_of(page, "#command"), "the page to show the run")
    assert sw(ecu) == "run"
    until(lambda: (rpm_shown(page) or 0) > 45000, lambda: "the rpm to rise above idle (page: " + str(js(page,
          "return [window.zkzapStats.longest, window.zkzapStats.pingGap, window.zkzapStats.samples, location.href]"))
          + f", ecu rpm {ecu.device.rpm}, console pid {console.proc.pid}: {console.stderr()[-600:]})", timeout=60)
    until(lambda: text_of(page, "#state") == "running", "the running state")
    assert f"starts the engine: state run, throttle {first} %" in console.stderr()

    set_value(page, "#throttle", 60)                      # the throttle follows the page

    def sent():
        with ecu.lock:
            return any(r.get("throttle_pct") == 60 for r in list(ecu.device.received)[-5:])

    until(sent, "throttle 60 % sent")
    click(page, "#abort")
    until(lambda: sw(ecu) == "standby", "standby at the ECU")
    until(lambda: "Monitoring" in text_of(page, "#command"), "the page to show the end")
    assert "abort from page" in text_of(page, "#ended") and "standby, throttle 0" in text_of(page, "#ended")


def test_a_second_page_watches_and_closing_the_controlling_tab_sends_standby(page, ecu, console):
    start(page, 25)
    until(lambda: sw(ecu) == "run", "the engine running again")
    first = page.current_window_handle
    page.switch_to.new_window("window")
    watcher = page.current_window_handle
    page.get(console.base + "/")
    until(lambda: "View only" in text_of(page, "#control"), "the second page's view-only banner")
    assert "page" in text_of(page, "#control") and "controls" in text_of(page, "#control")
    assert not css(page, "#start")[0].is_enabled() and css(page, "#abort")[0].is_enabled()
    err = js(page, "try { await Z.request('set', {mode: 'throttle', throttle: 90}); return null; }"
                   " catch (e) { return e.message; }")
    assert err.startswith("view only")
    page.switch_to.window(first)
    page.close()                                          # the controlling tab goes away
    page.switch_to.window(watcher)
    until(lambda: sw(ecu) == "standby", "the dead-man's standby")
    until(lambda: "Nobody controls" in text_of(page, "#control"), "the watcher to see nobody controls")
    until(lambda: "dead-man" in text_of(page, "#ended"), "the reason on the page")
    assert "the page closed" in console.stderr()
    assert console_errors(page) == []


def test_no_errors_in_the_browser_console(opened):
    page = opened
    assert console_errors(page) == []
    assert js(page, "return window.zkzapStats.errors") == 0
    assert js(page, "return window.zkzapStats.samples") > 0
