"""The interactive report (``zk report ... -o report.html --interactive``) as a reader sees it: the
page opened from its file in headless Chromium renders its plots with no console error, a drag
zooms every time history at once, and the cursor gets a readout of every line at its time."""

from __future__ import annotations

import re

import pytest

pytest.importorskip("plotly")

from webpage import console_errors, css, js, until  # noqa: E402

SIM = "sim://zk?speed=20"


@pytest.fixture(scope="module")
def page_file(tmp_path_factory):
    from click.testing import CliRunner

    from zkzap.commands import root, run as run_cli

    d = tmp_path_factory.mktemp("interactive")
    sched = d / "stand.csv"
    sched.write_text("0,0,run\n20,40\n28,80\n36,0,standby\n40,0,standby\n")       # model seconds
    tel, steps, summary, out = (str(d / n) for n in ("tel.csv", "steps.csv", "summary.json", "report.html"))
    with CliRunner().isolation():
        assert run_cli(root, "zkzap", ["zk", "profile", str(sched), "-p", SIM, "-o", tel, "--settle", "4",
                                       "--steps-csv", steps, "--summary-json", summary]) == 0
        assert run_cli(root, "zkzap", ["zk", "report", tel, "--steps", steps, "--summary", summary,
                                       "--limit", "egt_c<=700,warn=650", "-o", out, "--interactive",
                                       "--title", "K-100 #1234"]) == 0
    return out


def test_the_page_renders_zooms_and_reads_out(browser, page_file):
    text = open(page_file, encoding="utf-8").read()
    assert "<script src=" not in text                    # self-contained: plotly.js inlined, nothing fetched
    size = browser.get_window_size()                     # the session's browser: given back as it was
    browser.set_window_size(1400, 1600)
    try:
        _check_page(browser, page_file)
    finally:
        browser.set_window_size(size["width"], size["height"])


def _check_page(browser, page_file):
    from selenium.webdriver.common.action_chains import ActionChains

    browser.get("file://" + page_file)
    console_errors(browser)
    until(lambda: js(browser, "const g = document.getElementById('histories-plot');"
                              "return !!(g && g._fullLayout && g.querySelector('.main-svg'))"),
          "the time histories drawn")
    assert js(browser, "return document.title") == "K-100 #1234"
    titles = js(browser, "return [...document.querySelectorAll('#histories-plot .annotation-text')]"
                         ".map(e => e.textContent)")
    assert {"Engine speed", "Exhaust gas temperature", "Thrust", "Throttle", "limit <= 700"} <= set(titles), titles
    names = js(browser, "return document.getElementById('histories-plot').data.map(t => t.name)")
    assert {"rpm", "EGT", "thrust (ECU)", "target", "state: running"} <= set(names), names
    # every line drew points: a path with a real 'd' per drawn trace
    drawn = js(browser, "return [...document.querySelectorAll('#histories-plot .scatterlayer .js-line')]"
                        ".filter(p => (p.getAttribute('d') || '').length > 20).length")
    assert drawn >= 8, drawn
    assert "warn <= 650" in titles
    assert js(browser, "return document.getElementById('steady-plot').data.length") >= 3
    assert css(browser, "table#summary") and css(browser, "table#steps")

    # a drag across the first panel zooms that time span on every panel (one shared axis)
    drag = css(browser, "#histories-plot .nsewdrag")[0]
    w = drag.size["width"]
    ActionChains(browser).move_to_element_with_offset(drag, int(-w * 0.2), 0).click_and_hold() \
        .move_by_offset(int(w * 0.3), 0).release().perform()
    until(lambda: js(browser, "return document.getElementById('histories-plot').layout.xaxis.autorange === false"
                              " && !!document.getElementById('histories-plot')._fullLayout.xaxis.range"),
          "the zoom")
    ranges = js(browser, "const L = document.getElementById('histories-plot')._fullLayout;"
                         "return Object.keys(L).filter(k => /^xaxis\\d*$/.test(k)).map(k => L[k].range)")
    lo, hi = ranges[0]
    assert 0 < hi - lo < 20, ranges                   # about 12 of the run's 40 s
    assert all(abs(r[0] - lo) < 1e-6 and abs(r[1] - hi) < 1e-6 for r in ranges), ranges

    # the cursor on a panel: the unified readout names each line's value at that time
    ActionChains(browser).move_to_element_with_offset(drag, 0, 0).perform()
    readout = until(lambda: js(browser, "const h = document.querySelector('#histories-plot .hoverlayer');"
                                        "return h && h.textContent"), "the readout at the cursor")
    assert re.search(r"rpm\s*:\s*\d+ rpm", readout) and re.search(r"EGT\s*:\s*[\d.]+ °C", readout), readout
    browser.save_screenshot(str(page_file) + ".png")
    assert console_errors(browser) == []
