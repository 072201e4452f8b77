"""The ZK console's latched trips in a real browser: a start at full throttle trips a limit and
the engine gets standby; the alarm list shows it latched and the setpoint is back at 0; a
start is refused while the alarm is latched, and after it is acknowledged still refused while
the engine is hot; once the engine is at rest and cool, the start is allowed, at setpoint 0.
The run is recorded like the command line's: the console's -o file and its logbook entry.
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time

import pytest

from zkzap.sim.base import Clock
from zkzap.sim.launch import Simulator
from zkzap.sim.zk_ecu import ZkEcu

from webpage import WebConsole, click, consent_dialog, console_errors, open_console, js, set_value, take_control, text_of, until

LIMIT = "egt_c<=650,warn=620"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    d = tmp_path_factory.mktemp("alarms")
    return d / "run.jsonl", d / "engine.db"


class SteeredClock(Clock):
    """Model time whose speed the test sets as it goes (:meth:`steer`), without a jump: the
    steps that must happen while the engine runs down hot are taken with the engine's time
    nearly held, however long a loaded machine makes them, and its cooling then goes fast."""

    def __init__(self, speed):
        super().__init__(speed)
        self._lock = threading.Lock()
        self._base, self._since = 0.0, time.monotonic()

    def now(self):
        with self._lock:
            return self._base + (time.monotonic() - self._since) * self.speed

    def real_delay(self, model_seconds):
        with self._lock:
            return max(0.0, model_seconds / self.speed)

    def steer(self, speed):
        with self._lock:
            now = time.monotonic()
            self._base += (now - self._since) * self.speed
            self._since, self.speed = now, speed


@pytest.fixture(scope="module")
def ecu():
    """The ECU simulator, served over TCP from this process on a clock the test steers."""
    with Simulator("zk", ZkEcu(), SteeredClock(1.0), "tcp") as sim:
        yield sim


@pytest.fixture(scope="module")
def console(recorded, ecu):
    out, book = recorded
    # a start after a trip waits for EGT below 60 degC (not 150): the engine is "cool" only about
    # 26 s of model time after the trip, and the test holds the model's time back meanwhile
    c = WebConsole("zk", "-p", ecu.url, "--limit", LIMIT, "-o", str(out), "--logbook", str(book),
                   "--engine", "K100-1", "--restart-egt", "60")
    yield c
    c.close()


@pytest.fixture
def page(browser, console):
    open_console(browser, console.url)
    take_control(browser)
    until(lambda: "frames/s" in text_of(browser, "#link"), "the status stream")
    return browser


def toast_after(page, before):
    """The newest toast that came after :func:`toasts` marked those on the page (``before``).
    Toasts leave after 6 s, so a count would miss a new one that came as an old one left."""
    return until(lambda: js(page, "const t = [...document.querySelectorAll('#toasts .toast:not([data-seen])')]"
                                  ".map(e => e.innerText); return t.length ? t[t.length - 1] : null;"),
                 "a toast")


def toasts(page):
    """Mark the toasts on the page now (see :func:`toast_after`); returns how many there are."""
    return js(page, "const t = document.querySelectorAll('#toasts .toast');"
                    "t.forEach(e => { e.dataset.seen = '1'; }); return t.length;")


def start_refused(page, why):
    before = toasts(page)
    click(page, "#start")
    text = toast_after(page, before)
    assert why in text, text
    assert "Running under this console" not in text_of(page, "#command")
    return text


def test_a_limit_is_drawn_on_its_gauge_and_in_its_plot(page):
    # the gauge marks the limit (red) and where its warning band begins (amber)
    assert js(page, "return document.querySelector('#g-egt_c path.mark').getAttribute('d')").startswith("M")
    assert js(page, "return document.querySelector('#g-egt_c path.band').getAttribute('d')").startswith("M")
    assert js(page, "return document.querySelector('#g-rpm path.band').getAttribute('d')") == ""
    # the EGT plot has the limit's line and its warning band's
    egt = js(page, "return [...document.querySelectorAll('#plots .plot')].find(p => p.innerText.startsWith('EGT'))"
                   ".innerText")
    assert f"limit {LIMIT}" in egt and "warning" in egt


def test_a_trip_latches_and_a_start_waits_for_the_acknowledgement_and_a_cool_engine(page, console, recorded, ecu):
    ecu.clock.steer(1.0)
    set_value(page, "#throttle", 100)
    click(page, "#start")
    assert "can start the engine" in consent_dialog(page)      # a real port's start asks first
    click(page, "#modal-ok")
    until(lambda: "Running under this console" in text_of(page, "#command"), "the run")
    until(lambda: "LATCHED" in text_of(page, "#alarms"), "the trip in the alarm list", timeout=60)
    assert f"limit {LIMIT} violated: egt_c=" in text_of(page, "#alarms")
    until(lambda: "Monitoring" in text_of(page, "#command"), "the run's end")
    # the engine runs down and cools in model time: a tenth of real time now, so the steps
    # below happen while it is hot whatever the machine's load (a race with its cooling before)
    ecu.clock.steer(0.1)
    assert "limit violated" in text_of(page, "#ended") and "standby, throttle 0" in text_of(page, "#ended")
    # the setpoint is back at 0; a start at the old setpoint is refused while the alarm is latched
    assert js(page, "return document.querySelector('#throttle').value") == "0"
    set_value(page, "#throttle", 100)
    start_refused(page, "alarm latched")
    assert "start refused: alarm latched" in text_of(page, "#interlock")
    # acknowledged: still refused while the engine runs down hot
    set_value(page, "#throttle", 0)
    click(page, "#ack")
    until(lambda: "acknowledged by page" in text_of(page, "#alarms"), "the acknowledgement in the list")
    assert "LATCHED" not in text_of(page, "#alarms")
    assert "EGT below 60 °C" in start_refused(page, "not back at rest and cool after the trip")
    ecu.clock.steer(5.0)               # its cooling, at five times real time
    # once at rest and cool, a start at setpoint 0 is allowed; at any other setpoint it is refused
    until(lambda: "refused" not in text_of(page, "#interlock"), "the engine at rest and cool", timeout=60)
    assert "next start is at setpoint 0" in text_of(page, "#interlock")
    set_value(page, "#throttle", 30)
    start_refused(page, "after a trip the engine starts at setpoint 0")
    set_value(page, "#throttle", 0)
    ecu.clock.steer(1.0)
    click(page, "#start")
    consent_dialog(page)
    click(page, "#modal-ok")
    until(lambda: "Running under this console: throttle 0" in text_of(page, "#command"), "the start at 0")
    click(page, "#abort")
    until(lambda: "Monitoring" in text_of(page, "#command"), "the abort's end")
    until(lambda: "LATCHED" in text_of(page, "#alarms"), "the abort in the alarm list")
    assert "abort from page" in text_of(page, "#alarms .alarm.latched")
    click(page, "#ack")
    until(lambda: "LATCHED" not in text_of(page, "#alarms"), "the abort acknowledged")
    assert console_errors(page) == []
    # the log says who acknowledged what
    err = console.stderr()
    assert "acknowledged 1 alarm: limit egt_c<=650,warn=620 violated" in err

    # the browser run is recorded like the command line's: the file, with the trip marked
    out, book = recorded
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    trip = [r for r in recs if r["kind"] == "trip"]
    assert trip and trip[0]["limit"] == LIMIT and "sent standby, throttle 0" in trip[0]["trip"]
    assert any(r.get("limit") == [LIMIT] for r in recs if r["kind"] == "status")
    page.get("about:blank")            # the page leaves before its console ends (no reconnection attempts)
    console.stop()
    with sqlite3.connect(book) as db:
        rows = db.execute("select command, engine, starts, running_s, limits_violated, files from runs").fetchall()
    assert len(rows) == 1 and rows[0][:3] == ("zkzap web zk", "K100-1", 1) and rows[0][3] > 0, rows
    assert LIMIT in rows[0][4] and str(out) in rows[0][5]
