"""The packet panel and the bytes on the bus in a real browser, the same test on both protocol
families: a request composed by register (the frame the library makes, what its permission table
asks), sent and answered, both ways in the log decoded; a stored write asked for before it goes
out; a reply with a bad checksum or CRC shown as bytes that make no frame, never as a value. On a
Modbus RTU bus also an exception reply, named.

Each bus is the simulator served over TCP from this process (``socket://`` is a real port for
the consent rules); each console its own ``zkzap web zap`` subprocess.
"""

from __future__ import annotations

import pytest

from zkzap.codec import modbus, zap
from zkzap.sim import start_zap

from webpage import (WebConsole, click, console_errors, consent_dialog, css, js, open_console, set_value, text_of,
                     until)

#: What differs between the two families: the read instruction, its frame, the words of a bad reply.
FAMILY = {
    "ir": {"read": "load", "frame": zap.packet(2, zap.LOAD_DATA, bytes((zap.register("goal-position").address, 2))),
           "bad": "not a packet: mightyZAP packet: checksum mismatch", "args": ()},
    "modbus": {"read": "read", "frame": modbus.read(2, "goal-position"),
               "bad": "not a frame: Modbus RTU frame: CRC mismatch", "args": ("--protocol", "modbus")},
}


@pytest.fixture(scope="session", params=sorted(FAMILY))
def rig(request):
    protocol = request.param
    with start_zap(ids=[1, 2], transport="tcp", protocol=protocol) as sim:
        c = WebConsole("zap", *FAMILY[protocol]["args"], "-p", sim.url, "--scan-ids", "1-3", "--timeout", "0.3")
        try:
            yield protocol, sim, c
        finally:
            c.close()


@pytest.fixture
def page(browser, rig):
    protocol, sim, console = rig
    if not browser.current_url.startswith(console.base):
        open_console(browser, console.url)
    until(lambda: len(css(browser, "#actuators tbody tr")) == 2, "the first scan's two actuators")
    until(lambda: "You control" in text_of(browser, "#control") and not css(browser, "#busy.show")
          and not css(browser, "#modal.show"), "the page in control with the bus free")
    return browser


def reg(sim, ident, name):
    with sim.lock:
        return sim.device.actuator(ident).get(name)


def compose(page, instruction, ident, register, value=""):
    set_value(page, "#pkt-ins", instruction)
    set_value(page, "#pkt-id", ident)
    set_value(page, "#pkt-reg", register)
    set_value(page, "#pkt-value", value)


def test_a_request_composed_by_register_goes_out_and_both_ways_are_decoded(page, rig):
    protocol, sim, _ = rig
    fam = FAMILY[protocol]
    with sim.lock:
        sim.device.actuator(2).set("goal-position", 1500)
    compose(page, fam["read"], 2, "goal-position")
    frame = fam["frame"].hex(" ").upper()
    until(lambda: text_of(page, "#pkt-frame") == frame, "the library's frame")
    assert "needs no permission" in text_of(page, "#pkt-needs")
    assert "a reply is expected" in text_of(page, "#pkt-describe")
    words = text_of(page, "#pkt-describe").split(" · ")[0]
    click(page, "#pkt-send")
    until(lambda: text_of(page, "#pkt-reply").startswith("reply "), "the reply")
    until(lambda: "reply of ID 2: goal-position=1500" in text_of(page, "#traffic"), "the reply in the log, decoded")
    assert words in text_of(page, "#traffic")                    # the request as it went out, in words
    assert console_errors(page) == []


def test_a_stored_write_is_asked_for_before_it_goes_out(page, rig):
    protocol, sim, _ = rig
    write = "store" if protocol == "ir" else "write"
    compose(page, write, 2, "speed-limit", 700)
    until(lambda: "stored" in text_of(page, "#pkt-needs"), "the permission the table asks")
    assert text_of(page, "#pkt-asks") == "asks for consent"
    was = reg(sim, 2, "speed-limit")
    click(page, "#pkt-send")
    assert "speed-limit" in consent_dialog(page)
    click(page, "#modal-cancel")
    until(lambda: "not sent" in text_of(page, "#pkt-reply"), "the refusal")
    assert reg(sim, 2, "speed-limit") == was != 700
    click(page, "#pkt-send")
    consent_dialog(page)
    click(page, "#modal-ok")
    until(lambda: reg(sim, 2, "speed-limit") == 700, "the stored write after consent")
    assert console_errors(page) == []


def test_a_reply_with_a_bad_check_is_shown_as_such_never_as_a_value(page, rig):
    protocol, sim, _ = rig
    fam = FAMILY[protocol]
    click(page, "#traffic-clear")
    # every bad row the log shows, kept as it comes (the polls soon push it out of the rows kept)
    js(page, "window.badRows = []; new MutationObserver((ms) => { for (const m of ms) for (const n of m.addedNodes)"
             " if (n.classList && n.classList.contains('bad')) window.badRows.push(n.textContent); })"
             ".observe(document.querySelector('#traffic'), {childList: true});")
    click(page, "#traffic-polls")            # every reply in the log: the bad one may answer a poll
    until(lambda: css(page, "#traffic .poll"), "the polls in the log")
    with sim.lock:
        sim.device.inject(2, "corrupt", count=1)
    compose(page, fam["read"], 2, "goal-position")
    click(page, "#pkt-send")
    until(lambda: text_of(page, "#pkt-reply").startswith("reply "), "the good reply (a retry's)")
    bad = until(lambda: js(page, "return window.badRows.length ? window.badRows : null"),
                "the bad reply, as bytes that make no frame")
    assert len(bad) == 1 and fam["bad"] in bad[0], bad
    assert "reply of" not in bad[0] and "goal" not in bad[0], bad        # never a value
    click(page, "#traffic-polls")
    assert console_errors(page) == []


def test_an_exception_reply_is_named(page, rig):
    protocol, sim, _ = rig
    if protocol != "modbus":
        pytest.skip("exception replies are Modbus RTU's")
    compose(page, "read", 2, "")
    set_value(page, "#pkt-params", "01 2C 00 01")           # register 300: not in the 17Lf's table
    until(lambda: text_of(page, "#pkt-frame") == modbus.read_registers(2, 300).hex(" ").upper(), "the raw frame")
    click(page, "#pkt-send")
    until(lambda: "exception 2 (illegal-data-address)" in text_of(page, "#pkt-reply"), "the exception, named")
    until(lambda: "exception reply of ID 2 to read: 2 illegal-data-address" in text_of(page, "#traffic"),
          "the exception in the log")
    assert console_errors(page) == []
