"""Make the screenshots of docs/web.md: the consoles on the simulators, in headless Chromium.

    python docs/img/make.py            # writes docs/img/web-*.png (or: make.py zap-tools zap-buses zk alarms)

Needs the extra 'web', selenium, and Debian's chromium and chromium-driver (the test suite's
setup). Each picture is a console after a few real actions (a scan and moves, a start).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "cli"))

from zkzap.sim import start_zap, start_zk  # noqa: E402


def console(*args):
    exe = os.path.join(os.path.dirname(sys.executable), "zkzap")
    p = subprocess.Popen([exe, "web", *args, "--listen", "127.0.0.1:0"], stdout=subprocess.PIPE,
                         stderr=subprocess.DEVNULL, text=True)
    return p, p.stdout.readline().strip()


def browser(width, height):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    o = webdriver.ChromeOptions()
    o.binary_location = "/usr/bin/chromium"
    for a in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
              "--disable-background-networking", "--disable-component-update", "--disable-sync",
              "--hide-scrollbars", f"--user-data-dir={tempfile.mkdtemp(prefix='zkzap-shots-')}",
              f"--window-size={width},{height}"):
        o.add_argument(a)
    return webdriver.Chrome(service=Service(executable_path="/usr/bin/chromedriver"), options=o)


def wait(d, script, timeout=30):
    end = time.monotonic() + timeout
    while not d.execute_script(script):
        if time.monotonic() > end:
            raise SystemExit(f"timed out: {script}")
        time.sleep(0.1)


def move(d, ident, position):
    d.execute_script("const r = document.querySelector(`#act-${arguments[0]} input[type=range]`);"
                     "r.value = arguments[1]; r.dispatchEvent(new Event('input'));", ident, position)


def shoot(d, name):
    path = os.path.join(HERE, name)
    d.save_screenshot(path)
    print(path)


def zap_shots():
    with start_zap(ids=[1, 2, 3, 4], transport="tcp") as sim:
        p, url = console("zap", "-p", sim.url, "--scan-ids", "0-10")
        d = browser(1440, 1350)
        try:
            d.get(url)
            wait(d, "return document.querySelectorAll('#actuators tbody tr').length === 4")
            for ident, pos in ((1, 3000), (2, 1200), (3, 2500), (4, 600)):
                move(d, ident, pos)
            time.sleep(1.5)
            for ident, pos in ((1, 900), (3, 3600), (4, 2000)):
                move(d, ident, pos)
            time.sleep(1.0)
            d.execute_script("document.querySelector('#act-2 .btn').click();"
                             "for (const i of [3, 4]) document.querySelector(`#act-${i} input.sync`).click();")
            wait(d, "return document.querySelector('#registers') && !document.querySelector('#registers').hidden")
            time.sleep(1.0)
            shoot(d, "web-zap.png")
        finally:
            d.quit()
            p.terminate()
            p.wait()


def zap_tools_shots():
    """The register plot, the packet panel with the bytes on the bus, and a cycle run."""
    with start_zap(ids=[1, 2, 3], transport="tcp") as sim:
        p, url = console("zap", "-p", sim.url, "--scan-ids", "0-10")
        d = browser(1440, 1750)
        try:
            d.get(url)
            wait(d, "return document.querySelectorAll('#actuators tbody tr').length === 3")
            wait(d, "return document.querySelectorAll('#rplot-reg option').length > 10")
            d.execute_script("const s = document.querySelector('#rplot-reg'); s.value = 'present-current';"
                             "s.dispatchEvent(new Event('change'));")
            for ident, pos in ((1, 3000), (2, 1200), (3, 2500)):
                move(d, ident, pos)
            time.sleep(2.0)
            for ident, pos in ((1, 900), (2, 3400), (3, 600)):
                move(d, ident, pos)
            time.sleep(2.5)
            d.execute_script(
                "const set = (s, v) => { const e = document.querySelector(s); e.value = v;"
                " e.dispatchEvent(new Event('change', {bubbles: true})); };"
                "set('#pkt-ins', 'load'); set('#pkt-id', 2); set('#pkt-reg', 'present-position');"
                "document.querySelector('#pkt-send').click();"
                "set('#cycle-id', 3); set('#cycle-a', 800); set('#cycle-b', 3200); set('#cycle-n', 8);"
                "set('#cycle-dwell', 0.2);")
            time.sleep(1.0)
            d.execute_script("document.querySelector('#cycle-go').click();")
            wait(d, "return /8 cycles in/.test(document.querySelector('#cycle-sum').textContent)", timeout=90)
            d.execute_script("document.querySelector('#rplot-card').scrollIntoView({block: 'start'});"
                             "window.scrollBy(0, -60);")
            time.sleep(1.5)                   # the live view polls again
            shoot(d, "web-zap-tools.png")
        finally:
            d.quit()
            p.terminate()
            p.wait()


def zap_buses_shots():
    """Two buses of a fleet file at once, both with an ID 1: each bus's actuators under its name."""
    import json

    with start_zap(ids=[1, 2, 3], transport="tcp") as left, start_zap(ids=[1, 2], transport="tcp") as right:
        with tempfile.TemporaryDirectory() as tmp:
            fleet = os.path.join(tmp, "machine.json")
            with open(fleet, "w") as f:
                json.dump({"format": "zkzap-fleet/1", "actuators": {"1": {}}, "buses": {
                    "left": {"port": left.url, "ids": [1, 2, 3]}, "right": {"port": right.url, "ids": [1, 2]}}}, f)
            p, url = console("zap", "--fleet", fleet, "--buses", "all")
            d = browser(1440, 1350)
            try:
                d.get(url)
                wait(d, "return document.querySelectorAll('#actuators tbody tr[data-id]').length === 5")
                for row, pos in (("0-1", 3000), ("0-2", 1200), ("0-3", 2500), ("1-1", 600), ("1-2", 3400)):
                    move(d, row, pos)
                time.sleep(2.0)
                d.execute_script("document.querySelector('#act-1-1 .btn').click();")
                wait(d, "return document.querySelector('#registers') && !document.querySelector('#registers').hidden")
                time.sleep(1.0)
                shoot(d, "web-zap-buses.png")
            finally:
                d.quit()
                p.terminate()
                p.wait()


def zk_shots():
    with start_zk(speed=1, transport="tcp") as sim:
        p, url = console("zk", "-p", sim.url, "--limit", "egt_c<=900,warn=700", "--limit", "power_voltage_v>=11")
        d = browser(1440, 900)
        tablet = None
        try:
            d.get(url)
            wait(d, "return window.zkzapStats.samples > 20")
            time.sleep(2)
            d.execute_script("const t = document.querySelector('#throttle'); t.value = 55;"
                             "t.dispatchEvent(new Event('change')); document.querySelector('#start').click();")
            wait(d, "return document.querySelector('#modal.show') !== null")
            d.execute_script("document.querySelector('#modal-ok').click()")
            wait(d, "return document.querySelector('#state').textContent === 'running'", 60)
            time.sleep(6)
            tablet = browser(820, 1180)
            tablet.get(url.split("/?")[0] + "/?" + url.split("/?")[1])
            wait(tablet, "return window.zkzapStats.samples > 20")
            time.sleep(3)
            shoot(d, "web-zk.png")
            shoot(tablet, "web-zk-tablet.png")
        finally:
            if tablet is not None:
                tablet.quit()
            d.execute_script("document.querySelector('#abort').click()")
            time.sleep(0.5)
            d.quit()
            p.terminate()
            p.wait()


def alarm_shots():
    """A trip: the engine at full throttle over its EGT limit, the alarm latched, the start refused."""
    with start_zk(speed=2, transport="tcp") as sim:
        p, url = console("zk", "-p", sim.url, "--limit", "egt_c<=650,warn=620", "--limit", "power_voltage_v>=11")
        d = browser(1440, 1000)
        try:
            d.get(url)
            wait(d, "return window.zkzapStats.samples > 20")
            d.execute_script("const t = document.querySelector('#throttle'); t.value = 100;"
                             "t.dispatchEvent(new Event('change')); document.querySelector('#start').click();")
            wait(d, "return document.querySelector('#modal.show') !== null")
            d.execute_script("document.querySelector('#modal-ok').click()")
            wait(d, "return document.querySelector('#alarms .alarm.latched') !== null", 90)
            wait(d, "return document.querySelector('#command').textContent.startsWith('Monitoring')")
            d.execute_script("const t = document.querySelector('#throttle'); t.value = 100;"
                             "t.dispatchEvent(new Event('change')); document.querySelector('#start').click();")
            time.sleep(1.5)
            shoot(d, "web-zk-alarms.png")
        finally:
            d.quit()
            p.terminate()
            p.wait()


SHOTS = {"zap": zap_shots, "zap-tools": zap_tools_shots, "zap-buses": zap_buses_shots, "zk": zk_shots, "alarms": alarm_shots}

if __name__ == "__main__":
    for name in sys.argv[1:] or SHOTS:     # python docs/img/make.py [zap] [zk] [alarms]
        SHOTS[name]()
