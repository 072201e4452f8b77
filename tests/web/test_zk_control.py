"""The ZK console's engine control, through its WebSocket (no browser): RPM mode and its
interlocks, stop, a violated limit ending the run with the abort, and the consent rule of the
in-process simulator (sim:// never asks)."""

from __future__ import annotations

import asyncio

import pytest

from zkzap.sim import start_zk

from webpage import WebConsole, open_page, wait

aiohttp = pytest.importorskip("aiohttp")


@pytest.fixture(scope="session")
def ecu():
    with start_zk(speed=10, transport="tcp") as sim:
        yield sim


@pytest.fixture(scope="session")
def console(ecu):
    c = WebConsole("zk", "-p", ecu.url, "--limit", "rpm<=120000")
    yield c
    c.close()


def device(ecu, fn):
    with ecu.lock:
        return fn(ecu.device)


def scenario(console, steps):
    async def run():
        async with aiohttp.ClientSession() as s:
            page = await open_page(s, console)
            await wait(lambda: any(m.get("max_rpm") for m in page.seen("samples") for m in m["items"]),
                       "status ID 6 (max rpm)")
            try:
                await steps(page)
            finally:
                await page.ws.close()

    asyncio.run(asyncio.wait_for(run(), 120))


async def idle(page, ecu):
    """Nothing runs and a start is allowed: abort anything left, wait for the engine to leave run,
    acknowledge what an earlier test latched, wait until the engine is at rest and cool; after a
    trip the first start is at setpoint 0: one is made (and stopped) so that a test starts where
    it wants."""
    await page.request("abort")
    await wait(lambda: device(ecu, lambda d: d.effective_sw()) != "run", "the engine out of run")
    await wait(lambda: not page.seen("engine") or not page.seen("engine")[-1]["controlling"], "no run")
    await page.request("ack")
    await wait(lambda: page.seen("health") and page.seen("health")[-1].get("interlock") is None,
               "the engine at rest and cool", timeout=60)
    if page.seen("alarms") and page.seen("alarms")[-1]["zero_setpoint"]:
        r = await page.request("start", mode="throttle", throttle=0, grant=["engine"])
        assert r["type"] == "done", r
        await page.request("stop")
        await wait(lambda: not page.seen("engine")[-1]["controlling"], "the start at 0 stopped")


def test_rpm_mode_and_its_interlocks(console, ecu):
    async def steps(page):
        await idle(page, ecu)
        over = await page.request("start", mode="rpm", rpm=200000, grant=["engine"])
        assert over["type"] == "error" and "above the ECU's max rpm 160000" in over["text"]
        started = await page.request("start", mode="rpm", rpm=90005, grant=["engine"])
        assert started["type"] == "done" and started["command"]["rpm"] == 90000       # steps of 40 rpm (RPM_X 4)
        assert started["command"]["rpm_factor"] == 4
        await wait(lambda: device(ecu, lambda d: d.rpm_mode and d.effective_sw() == "run"), "RPM mode at the ECU")
        assert device(ecu, lambda d: d.rpm_value * 10 * d.rpm_factor) == 90000
        again = await page.request("start", mode="throttle", throttle=10, grant=["engine"])
        assert again["type"] == "error" and "already running" in again["text"]
        back = await page.request("set", mode="throttle", throttle=20)
        assert back["type"] == "done"
        await wait(lambda: device(ecu, lambda d: not d.rpm_mode and d.throttle == 20), "back to throttle at the ECU")
        stop = await page.request("stop")
        assert stop["type"] == "done"
        await wait(lambda: device(ecu, lambda d: d.effective_sw()) == "stop", "stop at the ECU")
        await wait(lambda: not page.seen("engine")[-1]["controlling"], "the run's end on the page")
        engine = page.seen("engine")[-1]
        assert not engine["controlling"] and "stop from page" in engine["ended"]["why"]
        assert engine["ended"]["sent"] == "stop, throttle 0"
        # the status rate's window goes on over the console's sessions: frames/s stays the ECU's rate
        # (it counted up by the frames of every session before, its clock restarted per session)
        import time

        first, t0 = page.seen("health")[-1], time.monotonic()
        await wait(lambda: page.seen("health")[-1]["frames"] > first["frames"] + 200, "frames after the run")
        last, t1 = page.seen("health")[-1], time.monotonic()
        measured = (last["frames"] - first["frames"]) / (t1 - t0)        # frames a second, as they came
        assert 0 < last["frames_per_s"] <= measured * 1.5, (last, measured)

    scenario(console, steps)


def test_a_violated_limit_ends_the_run_with_the_abort(console, ecu):
    async def steps(page):
        await idle(page, ecu)
        await wait(lambda: device(ecu, lambda d: d.rpm) < 100000, "a slow engine")
        r = await page.request("start", mode="throttle", throttle=100, grant=["engine"])
        assert r["type"] == "done", r
        await wait(lambda: page.seen("engine")[-1]["controlling"], "the run")
        await wait(lambda: not page.seen("engine")[-1]["controlling"], "the run's end", timeout=60)
        ended = page.seen("engine")[-1]["ended"]
        assert ended["reason"] == "limit" and "rpm<=120000" in ended["why"] and ended["sent"] == "standby, throttle 0"
        assert device(ecu, lambda d: d.effective_sw()) == "standby"
        await wait(lambda: any(m.get("limits") and m["limits"][0]["verdict"] == "violated" for m in page.seen("health")),
                   "the limit's verdict on the page")
        refused = await page.request("start", mode="throttle", throttle=10, grant=["engine"])
        assert refused["type"] == "error" and "alarm latched: limit rpm<=120000 violated" in refused["text"]
        alarms = page.seen("alarms")[-1]
        assert alarms["latched"] == 1 and alarms["zero_setpoint"] and alarms["items"][0]["limit"] == "rpm<=120000"
        done = await page.request("ack")
        assert done["type"] == "done" and done["acknowledged"] == [alarms["items"][0]["id"]]
        refused = await page.request("start", mode="throttle", throttle=0, grant=["engine"])
        assert refused["type"] == "error" and "not back at rest and cool" in refused["text"]

    scenario(console, steps)


def test_the_in_process_simulator_never_asks():
    c = WebConsole("zk", "-p", "sim://zk?speed=10")

    async def steps(page):
        r = await page.request("start", mode="throttle", throttle=10)
        assert r["type"] == "done", r
        await wait(lambda: page.seen("engine") and page.seen("engine")[-1]["controlling"], "the run")
        await page.request("abort")

    try:
        scenario(c, steps)
    finally:
        c.close()
