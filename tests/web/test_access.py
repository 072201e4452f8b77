"""Who may use a console, and the engine's safe ends, without a browser: the token and the origin
on every page and socket, a non-loopback address refused without a token, one page controls and
the others watch, the dead-man rule when a controlling page stops answering its heartbeat, and
standby when the console itself is ended while it runs the engine."""

from __future__ import annotations

import asyncio
import json
import signal

import pytest

from zkzap.sim import start_zk

from webpage import Page, WebConsole, open_page, until, wait

aiohttp = pytest.importorskip("aiohttp")


# -- before anything opens -------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["zap", "zk"])
@pytest.mark.parametrize("listen", ["0.0.0.0:8470", "[::]:0", "192.0.2.7:8470"])
def test_an_address_other_machines_reach_needs_a_token(cli, kind, listen):
    r = cli("web", kind, "--sim", "--listen", listen)
    assert r.exit_code == 2 and r.stdout == ""
    assert "reachable from other machines: give --token SECRET" in r.stderr and "--token auto" in r.stderr


@pytest.mark.parametrize("args,message", [
    (["--listen", "localhost"], "listen: 'localhost' is not HOST:PORT"),
    (["--listen", "127.0.0.1:70000"], "listen: '127.0.0.1:70000' is not HOST:PORT"),
    (["--token", "short"], "token: 8 to 200 characters"),
    (["--token", "spaces are not url safe"], "token: 8 to 200 characters"),
])
def test_bad_listen_and_token_values_are_refused(cli, args, message):
    r = cli("web", "zk", "--sim", *args)
    assert r.exit_code == 2 and r.stdout == "" and message in r.stderr


def test_without_the_extra_it_names_the_extra(cli, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "aiohttp" else real(name, *a))
    r = cli("web", "zap", "--sim")
    assert r.exit_code == 2 and "pip install 'zkzap[web]'" in r.stderr


# -- a running console -----------------------------------------------------------------------

@pytest.fixture(scope="session")
def ecu():
    with start_zk(speed=10, transport="tcp") as sim:
        yield sim


@pytest.fixture(scope="session")
def console(ecu):
    c = WebConsole("zk", "-p", ecu.url)
    yield c
    c.close()


def sw(ecu):
    with ecu.lock:
        return ecu.device.effective_sw()


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, 60))


async def _get(console, path, **kw):
    async with aiohttp.ClientSession() as s:
        async with s.get(console.base + path, allow_redirects=False, **kw) as r:
            return r.status, dict(r.headers), await r.text()


def test_the_first_line_is_the_url_with_its_token(console):
    assert console.url.startswith("http://127.0.0.1:") and len(console.token) >= 16
    until(lambda: "is served on 127.0.0.1; open the URL above" in console.stderr(), "the note on stderr")


def test_the_page_needs_the_token_which_is_traded_for_a_cookie(console):
    assert run(_get(console, "/"))[0] == 403
    assert run(_get(console, "/?token=wrong-token"))[0] == 403
    status, headers, _ = run(_get(console, f"/?token={console.token}"))
    assert status == 302 and headers["Location"] == "/"
    assert f"={console.token}" in headers["Set-Cookie"] and "HttpOnly" in headers["Set-Cookie"]
    assert "SameSite=Strict" in headers["Set-Cookie"]
    status, headers, body = run(_get(console, "/", headers={"Cookie": headers["Set-Cookie"].split(";")[0]}))
    assert status == 200 and "ABORT" in body and "frame-ancestors 'none'" in headers["Content-Security-Policy"]
    assert run(_get(console, "/", headers={"Host": "evil.example"}))[0] == 403     # DNS rebinding


async def _socket_status(console, **kw):
    async with aiohttp.ClientSession() as s:
        try:
            async with s.ws_connect(console.base + "/ws", **kw):
                return 101
        except aiohttp.WSServerHandshakeError as e:
            return e.status


@pytest.mark.parametrize("case", ["no origin", "another origin", "no token", "wrong token"])
def test_a_socket_needs_the_consoles_origin_and_token(console, case):
    params = {} if case == "no token" else {"token": "x" * 24 if case == "wrong token" else console.token}
    headers = {} if case == "no origin" else {"Origin": "http://evil.example" if case == "another origin"
                                              else console.base}
    assert run(_socket_status(console, params=params, headers=headers)) == 403
    assert run(_socket_status(console, params={"token": console.token}, headers={"Origin": console.base})) == 101


def test_one_page_controls_and_a_silent_controller_sends_the_engine_to_standby(console, ecu):
    async def scenario():
        async with aiohttp.ClientSession() as s:
            a = await open_page(s, console)
            await wait(lambda: a.seen("hello"), "hello")
            b = await open_page(s, console)
            await wait(lambda: b.seen("control") and b.seen("control")[-1]["controller"], "the control message")
            me = a.seen("hello")[0]["you"]
            assert b.seen("control")[-1]["controller"]["id"] == me
            refused = await b.request("start", mode="throttle", throttle=20)
            assert refused["type"] == "error" and refused["text"].startswith("view only")
            await wait(lambda: a.seen("samples"), "status frames")
            asked = await a.request("start", mode="throttle", throttle=20)
            assert asked["type"] == "consent" and asked["permission"] == "engine"      # socket://: a real port
            started = await a.request("start", mode="throttle", throttle=20, grant=["engine"])
            assert started["type"] == "done"
            await wait(lambda: sw(ecu) == "run", "the engine running")
            await asyncio.sleep(2.0)                       # answering its pings, the page keeps control
            assert sw(ecu) == "run"
            a.alive = False                                # the page freezes: no more answers
            await wait(lambda: sw(ecu) == "standby", "the dead-man's standby")
            await wait(lambda: any("lost control" in m.get("text", "") for m in a.seen("error")), "a's notice")
            await wait(lambda: b.seen("control")[-1]["controller"] is None, "control released")
            taken = await b.request("take")
            assert taken["type"] == "done"
            engine = [m for m in b.seen("engine")][-1]
            assert engine["controlling"] is False and "no heartbeat" in engine["ended"]["why"]
            await a.ws.close()
            await b.ws.close()

    run(scenario())
    assert "no heartbeat for 1 s" in console.stderr()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1],
                         ids=["SIGTERM", "SIGHUP", "SIGQUIT", "SIGUSR1"])
def test_ending_the_console_while_it_runs_the_engine_sends_standby(sig):
    with start_zk(speed=10, transport="tcp") as ecu:
        _end_while_running(ecu, sig)


def _end_while_running(ecu, sig=signal.SIGTERM):
    c = WebConsole("zk", "-p", ecu.url)

    async def scenario():
        async with aiohttp.ClientSession() as s:
            a = await open_page(s, c)
            await wait(lambda: a.seen("samples"), "status frames")
            await wait(lambda: (a.seen("health") and a.seen("health")[-1].get("silent_s") is not None), "health")
            r = await a.request("start", mode="throttle", throttle=15, grant=["engine"])
            assert r["type"] == "done", r
            await wait(lambda: sw(ecu) == "run", "the engine running")
            assert c.stop(sig) == 128 + sig

    try:
        run(scenario())
        assert sw(ecu) == "standby"
        assert "the console is shutting down: sent standby, throttle 0" in c.stderr()
    finally:
        c.close()


def test_a_silent_ecu_is_shown_as_silent_and_never_started():
    """The console serves until it is stopped, so the command tree's silent-device walk leaves
    it out; here is its side of that promise: no frame is no telemetry, and no start."""
    c = WebConsole("zk", "-p", "sim://zk?silent_after=0&speed=10")

    async def scenario():
        async with aiohttp.ClientSession() as s:
            a = await open_page(s, c)
            await wait(lambda: [h for h in a.seen("health") if "frames" in h], "the link's health")
            health = [h for h in a.seen("health") if "frames" in h][-1]
            assert health["frames"] == 0 and health["silent_s"] is None
            r = await a.request("start", mode="throttle", throttle=20, grant=["engine"])
            assert r["type"] == "error" and "no status frame from the ECU yet" in r["text"]
            await a.ws.close()

    try:
        run(scenario())
        assert c.stop(signal.SIGTERM) == 143
        assert "stopped: no status frame from the ECU" in c.stderr()
    finally:
        c.close()


def test_the_token_can_come_from_a_file_and_never_from_both(cli, tmp_path):
    f = tmp_path / "token"
    f.write_text("from-a-file-123\n")
    c = WebConsole("zk", "--sim", "--token-file", str(f))
    try:
        assert c.token == "from-a-file-123"
    finally:
        c.close()
    both = cli("web", "zk", "--sim", "--token-file", str(f), "--token", "abcdefghijk")
    assert both.exit_code == 2 and "give --token or --token-file, not both" in both.stderr
    f.write_text("\n")
    empty = cli("web", "zk", "--sim", "--token-file", str(f))
    assert empty.exit_code == 2 and "has no token on its first line" in empty.stderr
    r = cli("web", "zk", "--help")
    assert "visible to every user of the machine (ps)" in " ".join(r.stdout.split())


def test_connections_are_capped_with_a_clear_refusal(console):
    from zkzap.web.server import MAX_CLIENTS

    async def scenario():
        async with aiohttp.ClientSession() as s:
            kw = {"params": {"token": console.token}, "headers": {"Origin": console.base}}
            open_ = []
            refused = None
            for _ in range(MAX_CLIENTS + 1):
                try:
                    open_.append(await s.ws_connect(console.base + "/ws", **kw))
                except aiohttp.WSServerHandshakeError as e:
                    refused = e.status
                    break
            assert refused == 503 and len(open_) <= MAX_CLIENTS
            async with s.get(console.base + "/ws", **kw) as r:
                assert "pages are connected already" in await r.text()
            for ws in open_:
                await ws.close()
            await asyncio.sleep(0.2)
            again = await s.ws_connect(console.base + "/ws", **kw)          # room again
            await again.close()

    run(scenario())
