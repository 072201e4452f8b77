"""The mightyZAP console's further panels in a real browser: a plot of any register (pause, zoom,
CSV and PNG export), the packet panel (the frame, the permissions the library's table asks, the
consent, the bytes on the bus both ways, decoded), and play, teach and cycle from the page.

The bus is the simulator served over TCP from this process (``socket://`` is a real port for the
consent rules); the console is its own ``zkzap web zap`` subprocess.
"""

from __future__ import annotations

import base64
import os

import pytest

from zkzap.sim import start_zap

from webpage import WebConsole, click, console_errors, consent_dialog, css, js, open_console, set_value, text_of, until

SHOTS = os.environ.get("ZKZAP_SHOTS")          # a directory: the tests leave their screenshots there


@pytest.fixture(scope="session")
def tools_bus():
    with start_zap(ids=[1, 2, 3], transport="tcp") as sim:
        yield sim


@pytest.fixture(scope="session")
def tools_console(tools_bus):
    c = WebConsole("zap", "-p", tools_bus.url, "--scan-ids", "0-5", "--timeout", "0.3")
    yield c
    c.close()


@pytest.fixture
def page(browser, tools_console):
    if not browser.current_url.startswith(tools_console.base):
        open_console(browser, tools_console.url)
    until(lambda: len(css(browser, "#actuators tbody tr")) == 3, "the first scan's three actuators")
    until(lambda: "You control" in text_of(browser, "#control") and not css(browser, "#busy.show")
          and not css(browser, "#modal.show"), "the page in control with the bus free")
    # what the page would have the browser save, kept for the test instead
    js(browser, "window.saved = []; Z.download = (name, content) => window.saved.push({name, content});")
    return browser


def reg(bus, ident, name):
    with bus.lock:
        return bus.device.actuator(ident).get(name)


def shot(page, name):
    if SHOTS:
        page.save_screenshot(os.path.join(SHOTS, name))


def saved(page, suffix):
    return until(lambda: js(page, "return window.saved.find(s => s.name.endsWith(arguments[0])) || null", suffix),
                 f"the {suffix} file")


def test_any_register_is_plotted_paused_zoomed_and_exported(page, tools_bus, tmp_path):
    set_value(page, "#rplot-window", 10)
    set_value(page, "#rplot-reg", "present-position")
    until(lambda: "present-position, polled" in text_of(page, "#rplot-note"), "the plot of present-position")
    set_value(page, "#act-1 td.goal input[type=number]", 2500)
    until(lambda: abs(reg(tools_bus, 1, "present-position") - 2500) <= 5, "ID 1 at 2500")
    until(lambda: js(page, "return document.querySelectorAll('#rplot .u-over').length") == 1, "the plot")
    click(page, "#rplot-csv")
    text = saved(page, ".csv")["content"]
    lines = text.strip().splitlines()
    assert lines[0] == "time,t,id1,id2,id3"
    ids1 = [float(v.split(",")[2]) for v in lines[1:] if v.split(",")[2]]
    assert ids1 and max(ids1) >= 2490                   # the move, as polled
    # a drag over the plot zooms in and pauses it: the view is the dragged span, no longer rolling
    from selenium.webdriver.common.action_chains import ActionChains

    over = css(page, "#rplot .u-over")[0]
    js(page, "arguments[0].scrollIntoView({block: 'center'})", over)
    w = over.size["width"]
    until(lambda: csv_span(page) >= 7, "the plot's window filled", timeout=20, interval=0.5)
    full = saved_csv_rows(page)
    ActionChains(page).move_to_element_with_offset(over, 0, 0).click_and_hold() \
        .move_by_offset(int(w * 0.4), 0).release().perform()
    until(lambda: text_of(page, "#rplot-pause") == "Live", "the plot paused by the zoom")
    zoomed = saved_csv_rows(page)
    assert 0 < zoomed < full                  # only what the zoomed view shows
    click(page, "#rplot-png")
    url = saved(page, ".png")["content"]
    assert url.startswith("data:image/png;base64,")
    png = base64.b64decode(url.split(",", 1)[1])
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 2000
    (tmp_path / "plot.png").write_bytes(png)
    if SHOTS:
        with open(os.path.join(SHOTS, "register-plot.png"), "wb") as f:
            f.write(png)
    click(page, "#rplot-pause")                         # live again
    assert text_of(page, "#rplot-pause") == "Pause"
    shot(page, "register-plot-page.png")
    assert console_errors(page) == []


def saved_csv(page) -> list:
    js(page, "window.saved = []")
    click(page, "#rplot-csv")
    return saved(page, ".csv")["content"].strip().splitlines()[1:]


def saved_csv_rows(page) -> int:
    return len(saved_csv(page))


def csv_span(page) -> float:
    """Seconds between the first and the last point the plot's CSV holds."""
    rows = saved_csv(page)
    return float(rows[-1].split(",")[1]) - float(rows[0].split(",")[1]) if rows else 0.0


def test_a_composed_packet_shows_its_frame_and_what_the_table_asks_then_goes_out(page, tools_bus):
    set_value(page, "#pkt-ins", "store")
    set_value(page, "#pkt-id", 2)
    set_value(page, "#pkt-reg", "goal-position")
    set_value(page, "#pkt-value", 1000)
    until(lambda: text_of(page, "#pkt-frame") == "FF FF FF 02 05 F3 86 E8 03 94", "the goal-position frame")
    assert "store goal-position=1000 to ID 2" in text_of(page, "#pkt-describe")
    assert "needs no permission" in text_of(page, "#pkt-needs")
    assert "no reply expected" in text_of(page, "#pkt-describe")       # feedback-return-mode 1
    click(page, "#pkt-send")
    until(lambda: "no reply expected (feedback-return-mode 1)" in text_of(page, "#pkt-reply"), "the packet sent")
    until(lambda: reg(tools_bus, 2, "goal-position") == 1000, "the goal written")
    set_value(page, "#pkt-ins", "load")
    set_value(page, "#pkt-value", "")
    until(lambda: text_of(page, "#pkt-frame").startswith("FF FF FF 02 04 F2 86 02"), "the Load Data frame")
    assert "a reply is expected" in text_of(page, "#pkt-describe")
    click(page, "#pkt-send")
    until(lambda: "reply FF FF FF 02 04 00 E8 03" in text_of(page, "#pkt-reply"), "the reply, with the goal")
    # both ways in the bytes on the bus, decoded
    until(lambda: "store goal-position=1000 to ID 2" in text_of(page, "#traffic"), "the packet sent, in the log")
    until(lambda: "reply of ID 2: goal-position=1000" in text_of(page, "#traffic"), "the reply, decoded")
    set_value(page, "#pkt-ins", "store")
    # a stored setting: the library's table says so, and the bus asks for consent before it goes out
    set_value(page, "#pkt-reg", "long-stroke-limit")
    set_value(page, "#pkt-value", 3600)
    until(lambda: "stored" in text_of(page, "#pkt-needs"), "the permission the table asks")
    assert text_of(page, "#pkt-asks") == "asks for consent"
    click(page, "#pkt-send")
    assert "long-stroke-limit" in consent_dialog(page)
    click(page, "#modal-cancel")
    until(lambda: "not sent" in text_of(page, "#pkt-reply"), "the refusal")
    assert reg(tools_bus, 2, "long-stroke-limit") != 3600
    click(page, "#pkt-send")
    consent_dialog(page)
    click(page, "#modal-ok")
    until(lambda: reg(tools_bus, 2, "long-stroke-limit") == 3600, "the stored write after consent")
    # an ID change by hand needs force as well, on every port
    set_value(page, "#pkt-reg", "id")
    set_value(page, "#pkt-value", 9)
    until(lambda: "identity" in text_of(page, "#pkt-needs"), "the identity permission")
    assert text_of(page, "#pkt-asks") == "asks for force and consent"
    click(page, "#pkt-send")
    assert "changes how the actuator is reached" in consent_dialog(page)
    click(page, "#modal-cancel")
    assert reg(tools_bus, 2, "id") == 2
    # a raw packet, and the polls in the log when asked for
    set_value(page, "#pkt-ins", "echo")
    until(lambda: text_of(page, "#pkt-frame") == "FF FF FF 02 02 F1 0A", "the echo frame")
    click(page, "#traffic-polls")
    until(lambda: "load present-position" in text_of(page, "#traffic") or "load goal-position" in text_of(page, "#traffic"),
          "the live view's polls in the log")
    click(page, "#traffic-polls")
    shot(page, "packet-panel.png")
    assert console_errors(page) == []


PATH = "t,id,position\n0,\"1,2,3\",600\n0.6,\"1,2,3\",1800\n1.2,1,900\n"


def test_play_a_path_from_the_page_plan_first(page, tools_bus, tmp_path):
    path = tmp_path / "wave.csv"
    path.write_text(PATH)
    css(page, "#play-file")[0].send_keys(str(path))
    click(page, "#play-plan")
    until(lambda: "3 steps" in text_of(page, "#play-out"), "the plan")
    assert "FF FF FF FE" in text_of(page, "#play-out")          # a sync move: broadcast Symmetric Store
    click(page, "#play-interp")
    set_value(page, "#play-rate", 20)
    click(page, "#play-go")
    until(lambda: "lateness p99" in text_of(page, "#play-out"), "the play's summary", timeout=60)
    assert "play" in text_of(page, "#log")
    assert "played" in text_of(page, "#play-note")
    assert reg(tools_bus, 1, "goal-position") == 900 and reg(tools_bus, 3, "goal-position") == 1800
    shot(page, "play.png")


def test_teach_waypoints_download_them_and_play_them_back(page, tools_bus):
    set_value(page, "#teach-ids", "1,2")
    click(page, "#teach-start")
    until(lambda: "IDs 1, 2" in text_of(page, "#teach-note"), "teaching")
    for pos in (700, 2100):
        set_value(page, "#act-1 td.goal input[type=number]", pos)
        until(lambda: abs(reg(tools_bus, 1, "present-position") - pos) <= 5, f"ID 1 at {pos}")
        n = len(css(page, "#teach-out tbody tr"))
        click(page, "#teach-take")
        until(lambda: len(css(page, "#teach-out tbody tr")) == n + 1, "the waypoint")
    assert "2 waypoints" in text_of(page, "#teach-note")
    click(page, "#teach-save")
    text = saved(page, ".csv")["content"]
    lines = text.strip().splitlines()
    assert lines[0] == "t,id,position" and len(lines) == 5
    firsts = [line for line in lines[1:] if line.split(",")[1] == "1"]
    assert abs(int(firsts[0].split(",")[2]) - 700) <= 5 and abs(int(firsts[1].split(",")[2]) - 2100) <= 5
    set_value(page, "#act-1 td.goal input[type=number]", 3000)
    until(lambda: abs(reg(tools_bus, 1, "present-position") - 3000) <= 5, "ID 1 away at 3000")
    click(page, "#teach-stop")
    if css(page, "#play-interp")[0].is_selected():
        click(page, "#play-interp")
    click(page, "#teach-play")
    until(lambda: "the taught path: played" in text_of(page, "#play-note"), "the taught path played", timeout=60)
    assert abs(reg(tools_bus, 1, "goal-position") - 2100) <= 5
    shot(page, "teach.png")


def test_cycle_from_the_page_with_its_records_and_a_cancel_that_holds_the_rod(page, tools_bus):
    set_value(page, "#cycle-id", 3)
    set_value(page, "#cycle-a", 1000)
    set_value(page, "#cycle-b", 2000)
    set_value(page, "#cycle-n", 2)
    set_value(page, "#cycle-dwell", 0.1)
    click(page, "#cycle-go")
    until(lambda: "2 cycles in" in text_of(page, "#cycle-sum"), "the run's summary", timeout=60)
    assert len(css(page, "#cycle-table tbody tr")) == 2
    assert "the wire limit" in text_of(page, "#cycle-sum")
    shot(page, "cycle.png")
    set_value(page, "#cycle-n", 1000)
    click(page, "#cycle-go")
    until(lambda: css(page, "#busy.show") and len(css(page, "#cycle-table tbody tr")) >= 1, "the long run under way",
          timeout=60)
    click(page, "#cancel")
    until(lambda: "stopped: cancelled" in text_of(page, "#cycle-note"), "the cancel", timeout=30)
    assert "held at" in text_of(page, "#log")
    until(lambda: not css(page, "#busy.show"), "the bus free again")
    held = reg(tools_bus, 3, "goal-position")
    assert abs(reg(tools_bus, 3, "present-position") - held) <= 10
    assert console_errors(page) == []


def test_a_play_cancelled_from_the_page_stops_every_actuator_where_it_is(page, tools_bus, tmp_path):
    path = tmp_path / "long.csv"
    # a second step long after the first: on a loaded machine the play must not end by itself
    # before the page cancels it (it was 30 s, and ended as the test reached for Cancel)
    path.write_text('t,id,position\n0,"1,2",3500\n600,"1,2",200\n')
    css(page, "#play-file")[0].send_keys(str(path))
    if css(page, "#play-interp")[0].is_selected():
        click(page, "#play-interp")
    click(page, "#play-go")
    until(lambda: css(page, "#busy.show") and "play" in text_of(page, "#busy"), "the play under way")
    until(lambda: reg(tools_bus, 1, "present-position") > 1000, "ID 1 on its way")
    click(page, "#cancel")
    until(lambda: "stopped: cancelled" in text_of(page, "#play-note"), "the cancel", timeout=30)
    assert "cancelled from the page" in text_of(page, "#play-out")
    until(lambda: not css(page, "#busy.show"), "the bus free again")
    for i in (1, 2):
        held = reg(tools_bus, i, "goal-position")
        assert held != 200 and abs(reg(tools_bus, i, "present-position") - held) <= 10
    assert console_errors(page) == []
