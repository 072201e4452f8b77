"""Helpers of the browser console's tests (``from webpage import ...``): ``zkzap web ...`` as a
real subprocess (:class:`WebConsole`), waiting for a condition (:func:`until`: polled until it
holds, with a generous limit for a loaded machine, never a fixed time), and a page's elements.
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time

import pytest

from e2e.conftest import clean_env, executable, read_first_line, stop_sim

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
#: The longest a condition may take to hold on a loaded machine (not a speed target).
PATIENCE = 30.0
CHROMIUM_ARGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", "--window-size=1400,1000",
                 # every page a test opens is one a person looks at: none is slowed as a background page
                 "--disable-renderer-backgrounding", "--disable-background-timer-throttling",
                 "--disable-backgrounding-occluded-windows")


def _stale(e) -> bool:
    """Whether ``e`` says an element found a moment ago is gone (the page redrew it meanwhile)."""
    return type(e).__name__ == "StaleElementReferenceException"


def fresh(action, timeout=PATIENCE):
    """``action()`` (which finds the elements it uses), done again while an element it found was
    redrawn before it was used: a page that redraws a table on every update never fails a test
    that reaches for it at the wrong moment."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return action()
        except Exception as e:
            if not _stale(e) or time.monotonic() > deadline:
                raise
        time.sleep(0.02)


def until(condition, what, timeout=PATIENCE, interval=0.05):
    """Poll ``condition()`` until it returns something true (returned); fail naming ``what`` (a text,
    or a function giving it at the time). An element the condition found and the page redrew
    before it was read counts as not yet."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            got = condition()
        except Exception as e:
            if not _stale(e):
                raise
            got = None
        if got:
            return got
        if time.monotonic() > deadline:
            pytest.fail(f"timed out waiting for {what() if callable(what) else what}")
        time.sleep(interval)


class WebConsole:
    """``zkzap web ARGS...`` on a free loopback port: ``url`` (with its token), ``base``,
    ``token``, ``stderr()`` (what it said so far) and :meth:`stop` (its exit status)."""

    def __init__(self, *args, timeout=PATIENCE * 2):
        self.log = tempfile.NamedTemporaryFile(prefix="zkzap-web-", suffix=".log", delete=False)
        cmd = [executable("zkzap"), "web", *args]
        if "--listen" not in args:
            cmd += ["--listen", "127.0.0.1:0"]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=self.log,
                                     env=clean_env())
        self.url = self._first_line(timeout)
        self.base, _, query = self.url.partition("/?")
        self.token = query.partition("token=")[2]

    def _first_line(self, timeout) -> str:
        line = read_first_line(self.proc, timeout)
        if not line.endswith(b"\n"):
            self.stop()
            pytest.fail(f"zkzap web printed no URL within {timeout:g} s (exit {self.proc.returncode}): "
                        f"{self.stderr().strip()[-500:]}")
        return line.decode().strip()

    def stderr(self) -> str:
        with open(self.log.name, encoding="utf-8", errors="replace") as f:
            return f.read()

    def stop(self, sig=signal.SIGTERM) -> int:
        code = stop_sim(self.proc, sig, timeout=15.0)
        self.log.close()
        return code

    def close(self):
        self.stop()
        os.unlink(self.log.name)


def open_console(driver, url) -> None:
    """Open ``url`` afresh: the page before it (another test's, whose console may have ended, so
    that its reconnection attempts fail) is left first and the browser log it filled is dropped,
    so that :func:`console_errors` speaks of this page only."""
    driver.get("about:blank")
    driver.get_log("browser")
    driver.get(url)


def console_errors(driver) -> list:
    """The browser console's errors since the last call (and the page's own error count)."""
    return [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]


def css(driver, selector):
    from selenium.webdriver.common.by import By

    return driver.find_elements(By.CSS_SELECTOR, selector)


def text_of(driver, selector) -> str:
    def read():
        found = css(driver, selector)
        return found[0].text if found else ""

    return fresh(read)


def js(driver, script, *args):
    return driver.execute_script(script, *args)


def set_value(driver, selector, value, event="change"):
    """Set an input's value as a person would, then fire ``event``."""
    js(driver, "const e = document.querySelector(arguments[0]); e.value = arguments[1];"
               "e.dispatchEvent(new Event(arguments[2], {bubbles: true}));", selector, str(value), event)


def click(driver, selector):
    def shown():
        found = css(driver, selector)
        return found and found[0].is_enabled() and found[0].is_displayed()

    def press():
        element = css(driver, selector)[0]
        js(driver, "arguments[0].scrollIntoView({block: 'center'})", element)    # not under the sticky bar
        element.click()

    # shown too: a button a page reveals (the busy bar's Cancel) is clicked once a person could;
    # found again when the page redrew it between finding and clicking
    fresh(lambda: (until(shown, f"{selector} to be enabled and shown"), press()))


def take_control(driver):
    """The page just loaded: take control when another page had it, and wait until it controls."""
    until(lambda: "Take control" in text_of(driver, "#control") or "You control" in text_of(driver, "#control"),
          "the page's control banner")
    if "Take control" in text_of(driver, "#control"):
        click(driver, "#take")
    until(lambda: "You control" in text_of(driver, "#control"), "control")


def consent_dialog(driver):
    """The confirmation dialog's text once it is shown."""
    return until(lambda: text_of(driver, "#modal.show #modal-text"), "the confirmation dialog")


class Page:
    """A page without a browser, on a WebSocket of an aiohttp session: it answers the console's
    pings while ``alive``, keeps every message (:meth:`seen`) and sends requests
    (:meth:`request`: the reply)."""

    def __init__(self, ws):
        self.ws = ws
        self.alive = True
        self.messages = []
        self.n = 0
        self.task = asyncio.get_running_loop().create_task(self._read())

    async def _read(self):
        async for m in self.ws:
            msg = json.loads(m.data)
            self.messages.append(msg)
            if msg["type"] == "ping" and self.alive:
                await self.ws.send_str(json.dumps({"op": "pong", "n": msg["n"], "t": msg["t"]}))

    async def request(self, op, **fields):
        self.n += 1
        n = self.n
        await self.ws.send_str(json.dumps({"op": op, "req": n, **fields}))
        for _ in range(1200):
            for msg in self.messages:
                if msg.get("req") == n and msg["type"] in ("done", "error", "consent"):
                    return msg
            await asyncio.sleep(0.05)
        raise AssertionError(f"no reply to {op}")

    def seen(self, kind):
        return [m for m in self.messages if m["type"] == kind]


async def open_page(session, console):
    ws = await session.ws_connect(console.base + "/ws", params={"token": console.token},
                                  headers={"Origin": console.base})
    return Page(ws)


async def wait(cond, what, timeout=PATIENCE):
    for _ in range(int(timeout / 0.05)):
        if cond():
            return
        await asyncio.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")
