"""zkzap web: do the live views keep up? A 100 Hz ECU status stream and the polling of six
actuators, through the console to a real (headless) browser.

    python benchmarks/web.py                   # 15 s per case
    python benchmarks/web.py --seconds 30
    python benchmarks/web.py --quick           # 2 s per case, targets not checked (the test suite)

Each case runs the simulator as its own process on a pty (``zkzap sim ... --pty``), the console
as its own process (``zkzap web ...``) and Debian's Chromium on the console's page, then reads
the page's own counters (``window.zkzapStats``): the updates it received, the latency of each
(its arrival in the page minus the moment the console read it from the port, one clock) and of
the frame that drew it, and the updates the console produced (sent to it with each ping).

- ZK: the ECU simulator at 100 Hz (``--rate 100``). Produced vs the ECU's 100 frames/s, delivered
  vs produced, latency p50/p99. Targets: delivered/produced >= 0.99, produced >= 0.99 x 100/s,
  browser-side latency p99 < 100 ms.
- mightyZAP: six actuators. First ``zap watch`` alone on the same pty (the command's poll rate:
  goal and present position, current, voltage, moving, as fast as the line allows), then the
  console polling the same registers (``--rate 1000``: as fast as the line allows).
  Targets: the console's poll rate >= 0.9 x zap watch's, delivered/produced >= 0.99, p99 < 100 ms.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))
sys.path.insert(0, HERE)

from common import add_quick  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
WARMUP = 3.0


def tool(name):
    exe = os.path.join(os.path.dirname(sys.executable), name)
    return [exe] if os.path.exists(exe) else [sys.executable, "-m", "zkzap"]


def first_line(args, what):
    p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                         env=dict(os.environ, NO_COLOR="1"))
    line = p.stdout.readline().strip()
    if not line:
        p.kill()
        raise SystemExit(f"{what} did not start")
    return p, line


def stop(p):
    p.terminate()
    try:
        p.wait(10)
    except subprocess.TimeoutExpired:
        p.kill()


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    o = webdriver.ChromeOptions()
    o.binary_location = CHROMIUM
    for a in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
              "--disable-background-networking", "--disable-component-update", "--disable-sync",
              f"--user-data-dir={tempfile.mkdtemp(prefix='zkzap-bench-')}", "--window-size=1400,1000"):
        o.add_argument(a)
    return webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=o)


def pct(values, p):
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, int(p * len(s)))]


def measure(driver, url, seconds):
    """(received/s, produced/s, delivery latencies, render latencies, dropped) over ``seconds``."""
    driver.get(url)
    deadline = time.monotonic() + 30
    while not driver.execute_script("return window.zkzapStats && window.zkzapStats.samples > 0"):
        if time.monotonic() > deadline:
            raise SystemExit("no live update reached the page")
        time.sleep(0.1)
    time.sleep(WARMUP)
    get = ("const s = window.zkzapStats; return [s.samples, s.produced, s.latencies.length, s.renderLatencies.length,"
           " s.producedAt, Date.now()];")
    a = driver.execute_script(get)
    time.sleep(seconds)
    b = driver.execute_script(get)
    dt = (b[5] - a[5]) / 1000
    made_dt = (b[4] - a[4]) / 1000
    lat = driver.execute_script("return window.zkzapStats.latencies.slice(arguments[0]);", a[2])
    ren = driver.execute_script("return window.zkzapStats.renderLatencies.slice(arguments[0]);", a[3])
    dropped = driver.execute_script("return window.zkzapStats.dropped;")
    # 'produced' arrives with each ping (every 0.2 s), stamped with the console's clock
    return (b[0] - a[0]) / dt, (b[1] - a[1]) / made_dt, lat, ren, dropped


def zk_case(driver, seconds):
    sim, port = first_line(tool("zkzap") + ["sim", "zk", "--rate", "100", "--pty"], "the ECU simulator")
    try:
        console, url = first_line(tool("zkzap") + ["web", "zk", "-p", port, "--listen", "127.0.0.1:0"], "the console")
        try:
            got, made, lat, ren, dropped = measure(driver, url, seconds)
        finally:
            stop(console)
    finally:
        stop(sim)
    return {"case": "ZK status stream, 100 Hz", "source_per_s": 100.0, "produced_per_s": made,
            "delivered_per_s": got, "lat": lat, "render": ren, "dropped": dropped}


LIVE = ["goal-position", "goal-speed", "goal-current", "present-position", "present-current", "present-voltage", "moving"]


def watch_rate(port, seconds):
    """Polls per second of ``zap watch`` alone (rows / 6 / s)."""
    p = subprocess.run(tool("zap") + ["watch", *LIVE, "--ids", "1-6", "-p", port, "-d", str(seconds), "-f", "jsonl"],
                       capture_output=True, text=True, timeout=seconds + 30)
    rows = [json.loads(ln) for ln in p.stdout.splitlines() if ln.strip()]
    if len(rows) < 12:
        raise SystemExit(f"zap watch gave {len(rows)} rows: {p.stderr[-300:]}")
    return (len(rows) / 6) / (rows[-1]["t"] - rows[0]["t"])


def zap_case(driver, seconds):
    sim, port = first_line(tool("zkzap") + ["sim", "zap", "--ids", "1-6", "--pty"], "the bus simulator")
    try:
        alone = watch_rate(port, seconds)
        console, url = first_line(tool("zkzap") + ["web", "zap", "-p", port, "--scan-ids", "1-6", "--rate", "1000",
                                                   "--listen", "127.0.0.1:0"], "the console")
        try:
            got, made, lat, ren, dropped = measure(driver, url, seconds)
        finally:
            stop(console)
    finally:
        stop(sim)
    return {"case": "mightyZAP, 6 actuators polled", "source_per_s": alone * 6, "produced_per_s": made,
            "delivered_per_s": got, "lat": lat, "render": ren, "dropped": dropped, "watch_polls": alone,
            "web_polls": made / 6}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=15.0)
    add_quick(ap, seconds=2.0)
    args = ap.parse_args(argv)
    if not (os.path.exists(CHROMIUM) and os.path.exists(CHROMEDRIVER) and shutil.which("true")):
        raise SystemExit("needs chromium and chromium-driver (apt-get install chromium chromium-driver)")
    driver = browser()
    try:
        results = [zk_case(driver, args.seconds), zap_case(driver, args.seconds)]
    finally:
        driver.quit()
    ok = True
    for r in results:
        ratio = r["delivered_per_s"] / r["produced_per_s"] if r["produced_per_s"] else 0.0
        keep = r["produced_per_s"] / r["source_per_s"] if r["source_per_s"] else 0.0
        p50, p99, r99 = pct(r["lat"], 0.5), pct(r["lat"], 0.99), pct(r["render"], 0.99)
        print(f"{r['case']}:")
        if "watch_polls" in r:
            print(f"  polls/s per actuator: console {r['web_polls']:.1f}, zap watch alone {r['watch_polls']:.1f} "
                  f"-> {r['web_polls'] / r['watch_polls']:.2f}x (target >= 0.9x)")
            ok &= r["web_polls"] / r["watch_polls"] >= 0.9
        else:
            print(f"  produced {r['produced_per_s']:.1f} updates/s of the ECU's {r['source_per_s']:.0f} -> {keep:.3f}x "
                  f"(target >= 0.99x)")
            ok &= keep >= 0.99
        print(f"  delivered {r['delivered_per_s']:.1f} updates/s of {r['produced_per_s']:.1f} produced -> {ratio:.3f}x "
              f"(target >= 0.99x), {r['dropped']} dropped")
        print(f"  browser-side latency p50 {p50:.1f} ms, p99 {p99:.1f} ms (target < 100 ms); drawn within "
              f"p99 {r99:.1f} ms of the newest update")
        ok &= ratio >= 0.99 and p99 < 100
    if args.quick:
        print("quick run: the figures mean nothing, targets not checked")
        return 0
    print("all targets met" if ok else "a target was missed")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
