"""The pings and the dead-man rule are supervised: when the task that runs them fails, the
engine run ends with the abort and the log says so, and the task runs again (the dead-man rule
works afterwards). In-process: the console's server on a loop of the test, a failure injected
into the pinger."""

from __future__ import annotations

import asyncio

import pytest

from zkzap.api.zk import Ecu
from zkzap.sim import start_zk

from webpage import Page, wait

aiohttp = pytest.importorskip("aiohttp")


def _sw(ecu):
    with ecu.lock:
        return ecu.device.effective_sw()


def test_a_failing_pinger_ends_the_engine_run_and_runs_again():
    from zkzap.web import server
    from zkzap.web.zk_console import ZkConsole

    async def main(sim):
        console = ZkConsole(Ecu(sim.url, silence=2.0))
        logs = []
        console.on_log = logs.append
        srv = server.Server(console, host="127.0.0.1", port=0, token="supervised-token")
        url = await srv.start()
        base = url.split("/?")[0]
        try:
            async with aiohttp.ClientSession() as s:
                page = Page(await s.ws_connect(base + "/ws", params={"token": srv.token}, headers={"Origin": base}))
                await wait(lambda: page.seen("samples"), "status frames")
                assert (await page.request("start", mode="throttle", throttle=20, grant=["engine"]))["type"] == "done"
                await wait(lambda: _sw(sim) == "run", "the engine running")
                put = srv.hub._put

                def failing(c, text, live, count):
                    if '"type":"ping"' in text:
                        srv.hub._put = put                       # once
                        raise RuntimeError("injected")
                    put(c, text, live, count)

                srv.hub._put = failing
                await wait(lambda: _sw(sim) == "standby", "the failsafe's standby")
                assert any("the pings and the dead-man rule failed (RuntimeError: injected)" in e["text"]
                           for e in logs)
                # the pinger runs again: the dead-man rule still ends a run whose page froze
                await wait(lambda: not page.seen("engine")[-1]["controlling"], "the run ended")
                await asyncio.sleep(0.5)
                assert (await page.request("start", mode="throttle", throttle=20, grant=["engine"]))["type"] == "done"
                await wait(lambda: _sw(sim) == "run", "the engine running again")
                page.alive = False
                await wait(lambda: _sw(sim) == "standby", "the dead-man's standby")
                await page.ws.close()
        finally:
            await srv.stop()

    with start_zk(speed=10, transport="tcp") as sim:
        asyncio.run(asyncio.wait_for(main(sim), 90))
