"""A page may send anything: thousands of hostile messages — wrong types, NaN and infinities,
huge numbers, deep nesting, huge strings, unknown and private ops, text that is not JSON —
from a page that controls and from pages that watch, some answering their pings with garbage.
Afterwards the console still serves (a new page is greeted, requests are answered), nothing
put a traceback in its log, and the dead-man rule still sends the engine to standby when the
controlling page falls silent. The boundary itself (``parse_message``, ``number``, the
loopback names) is checked example by example."""

from __future__ import annotations

import asyncio
import json
import math
import random

import pytest

from zkzap.sim import start_zk
from zkzap.web import server
from zkzap.web.console import number

from webpage import Page, WebConsole, open_page, wait

aiohttp = pytest.importorskip("aiohttp")

#: Messages sent in all (by three pages).
MESSAGES = 3000
OPS = ["start", "set", "stop", "abort", "take", "release", "hello", "pong", "move", "sync", "write", "scan",
       "registers", "check", "backup", "diff", "apply", "cancel"]
HOSTILE_OPS = ["_lost", "-lost", "_failsafe", "__class__", "op__lost", "", "LOST", "set\x00", "_", "-", "a" * 5000,
               "handle", "run", "close", "shutdown", 7, None, True, ["set"], {"op": "set"}]
HUGE = 10 ** 400


def _value(rng, depth=0):
    kind = rng.randrange(16)
    if kind == 0:
        return float("nan")
    if kind == 1:
        return rng.choice([float("inf"), float("-inf")])
    if kind == 2:
        return rng.choice([HUGE, -HUGE, 2 ** 64, 2 ** 53 + 1])
    if kind == 3:
        return rng.choice([1e308, -1e308, 5e-324, -0.0])
    if kind == 4:
        return rng.choice([None, True, False])
    if kind == 5:
        return "x" * rng.choice([0, 1, 100, 100_000])
    if kind == 6 and depth < 3:
        return [_value(rng, depth + 1) for _ in range(rng.randrange(4))]
    if kind == 7 and depth < 3:
        return {rng.choice(["id", "throttle", "rpm", "value", "x"]): _value(rng, depth + 1) for _ in range(rng.randrange(4))}
    if kind == 8:
        return rng.choice(["20", "1e400", "nan", "0x10", " 5 ", "-1"])
    return rng.choice([0, 1, -1, 20, 50, 100, 101, 3.5, 65535, 253, 254])


def _message(rng) -> str:
    """One hostile message, as the text a page would send."""
    kind = rng.randrange(20)
    if kind == 0:
        return "[" * rng.choice([50, 1000, 100_000]) + "]" * rng.choice([0, 50])
    if kind == 1:
        return rng.choice(["not json", "{", "", "null", "[1,2]", "42", '"op"', "{}", '{"op":NaN}',
                           '{"op":"set","throttle":1e400}'])
    if kind == 2:
        return json.dumps({"op": rng.choice(OPS), "deep": json.loads("[" * 9 + "]" * 9)})
    op = rng.choice(HOSTILE_OPS) if kind < 5 else rng.choice(OPS)
    msg = {"op": op, "req": rng.choice([rng.randrange(10 ** 6), "r", None, HUGE, [1], float("nan")])}
    for key in rng.sample(["mode", "throttle", "rpm", "id", "position", "targets", "register", "value", "ids",
                           "bauds", "grant", "name", "n", "t", "format", "text", "compare", "plan", "move"],
                          rng.randrange(5)):
        msg[key] = _value(rng)
    if rng.random() < 0.2:
        msg["mode"] = rng.choice(["throttle", "rpm", "x"])
        msg["throttle"] = rng.choice([HUGE, float("nan"), 1e308, 20, "20"])
    if rng.random() < 0.1:
        msg["grant"] = rng.choice([["engine"], "engine", [HUGE], [[["engine"]]]])
    return json.dumps(msg)                      # allow_nan: NaN and Infinity go out as they are


class Hostile(Page):
    """A page that answers its pings with a ``t`` that is not a time (NaN, an infinity, a huge
    number, text), and floods the console with what it is given."""

    def __init__(self, ws, rng):
        super().__init__(ws)
        self.alive = False                      # the base class's pongs: off; these instead
        self.rng = rng

    async def _read(self):
        async for m in self.ws:
            msg = json.loads(m.data)
            self.messages.append(msg)
            if msg["type"] == "ping":
                t = self.rng.choice(["NaN", "Infinity", "-Infinity", "1e999", str(HUGE), '"x"', "null", "[]"])
                await self.ws.send_str(f'{{"op":"pong","n":{msg["n"]},"t":{t}}}')


def _sw(ecu):
    with ecu.lock:
        return ecu.device.effective_sw()


def test_hostile_messages_from_every_page_neither_stop_the_console_nor_its_dead_man():
    rng = random.Random(34)
    with start_zk(speed=10, transport="tcp") as ecu:
        c = WebConsole("zk", "-p", ecu.url)
        try:
            asyncio.run(asyncio.wait_for(_scenario(c, ecu, rng), 90))
            assert c.proc.poll() is None, c.stderr()
            c.stop()
            log = c.stderr()
        finally:
            c.close()
        assert "Traceback" not in log and "RecursionError" not in log and "internal error" not in log, log[-3000:]


async def _scenario(c, ecu, rng):
    async with aiohttp.ClientSession() as s:
        a = await open_page(s, c)                                   # the first page controls
        await wait(lambda: a.seen("hello") and a.seen("samples"), "a's hello and status frames")
        b = Hostile(await s.ws_connect(c.base + "/ws", params={"token": c.token}, headers={"Origin": c.base}), rng)
        v = await open_page(s, c)                                   # a viewer that answers its pings well
        await wait(lambda: b.seen("hello") and v.seen("hello"), "the other pages' hello")
        pages = [a, b, v]
        for i in range(MESSAGES):
            await pages[i % 3].ws.send_str(_message(rng))
            if i % 200 == 0:
                await asyncio.sleep(0.01)                           # let the pings through now and then
        # it still serves: a new page is greeted with everything a page needs
        d = await open_page(s, c)
        await wait(lambda: d.seen("hello") and d.seen("control") and d.seen("engine"), "d's greeting")
        # whoever controls now releases; d takes control and runs the engine
        # (a hostile page's take still in the console's queue may come after a release: then the
        # take is refused because that page controls again, and the pages release once more)
        for _ in range(5):
            for p in pages:
                await p.ws.send_str(json.dumps({"op": "abort"}))
                await p.ws.send_str(json.dumps({"op": "release", "req": -1}))
            await wait(lambda: d.seen("control")[-1]["controller"] is None, "control released")
            took = await d.request("take")
            if took["type"] == "done":
                break
        assert took["type"] == "done", took
        again = await d.request("take")                              # the page that controls: a reply too
        assert again["type"] == "done" and "controls already" in again["text"]
        await wait(lambda: _sw(ecu) in ("standby", "stop"), "the engine at rest")
        # a hostile start that ran and the aborts above are trips: acknowledged, the engine cool,
        # and the first start after one at setpoint 0
        assert (await d.request("ack"))["type"] == "done"
        await wait(lambda: d.seen("health") and d.seen("health")[-1].get("interlock") is None, "a start allowed",
                   timeout=60)
        zero = d.seen("alarms") and d.seen("alarms")[-1]["zero_setpoint"]
        started = await d.request("start", mode="throttle", throttle=0 if zero else 20, grant=["engine"])
        assert started["type"] == "done", started
        await wait(lambda: _sw(ecu) == "run", "the engine running")
        d.alive = False                                              # d freezes: the dead-man rule
        await wait(lambda: _sw(ecu) == "standby", "the dead-man's standby", timeout=10)
        await wait(lambda: any("lost control" in m.get("text", "") for m in d.seen("error")), "d's notice")
        refusals = [m["text"] for p in pages for m in p.seen("error") if m.get("text", "").startswith("refused: ")]
        for why in ("is not a JSON number", "not finite", "2^53"):
            assert any(why in t for t in refusals), why
        assert any("nested more than" in t for t in refusals) and any("unknown request" in t for t in refusals)
        for p in (*pages, d):
            await p.ws.close()


@pytest.mark.parametrize("text,why", [
    ('{"op":"pong","t":NaN}', "NaN is not a JSON number"),
    ('{"op":"set","throttle":1e400}', "not finite"),
    ('{"op":"set","throttle":' + "9" * 400 + "}", "2^53"),
    ("[" * 100_000 + "]" * 100_000, "nested more than"),
    ('{"a":' * 9 + "1" + "}" * 9, "nested more than"),
    ('{"op":"-lost"}', "unknown request '-lost'"),
    ('{"op":"_lost"}', "unknown request '_lost'"),
    ('{"op":"Set"}', "unknown request"),
    ("[1]", "not a JSON object"),
    ("{", "not a JSON object"),
])
def test_the_boundary_refuses_what_no_page_sends(text, why):
    with pytest.raises(server.BadMessage, match=why.replace("^", r"\^").replace("(", r"\(")):
        server.parse_message(text)


def test_the_boundary_passes_what_pages_send():
    msg = server.parse_message('{"op":"sync-move","req":3,"targets":{"1":2047,"2":0.5},"grant":["engine"]}')
    assert msg["targets"]["1"] == 2047
    assert server.parse_message('{"op":"pong","n":1,"t":1733230000000.5}')["t"] > 0


@pytest.mark.parametrize("value,message", [
    (HUGE, "a 401-digit number is out of range"), (float("nan"), "not a finite number"),
    (1e308, r"1e\+308 is out of range"), ("x" * 100, "is not a number"), ([1], "is not a number"),
    (True, "is not a number"), ("1e400", "not a finite number"),
])
def test_a_number_is_checked_before_it_is_converted(value, message):
    with pytest.raises(ValueError, match=message):
        number({"throttle": value}, "throttle", float, 0, 100)
    assert number({"p": "20"}, "p", int, 0, 100) == 20 and number({"p": 20.0}, "p", float, 0, 100) == 20.0
    assert not math.isnan(number({"p": 5}, "p", float, 0, 100))


@pytest.mark.parametrize("host,ok", [
    ("127.0.0.1", True), ("127.1.2.3", True), ("localhost", True), ("::1", True), ("[::1]", True),
    ("127.evil.example", False), ("127.0.0.1.nip.io", False), ("localhost.evil", False), ("0.0.0.0", False),
    ("10.0.0.1", False),
])
def test_only_literal_loopback_addresses_and_localhost_are_loopback(host, ok):
    assert server.is_loopback(host) is ok
