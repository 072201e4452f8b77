"""The console's web server (aiohttp): the page, its static files and one WebSocket per page.

Security: every page and WebSocket needs the console's token — in the URL the command prints
(``/?token=...``, traded at once for a cookie of this port and a redirect that drops it from
the address bar) or in that cookie. A WebSocket handshake must also come from the console's own
origin (``Origin`` equal to ``http://HOST:PORT`` of the request), so another site open in the
same browser cannot drive it; bound to a loopback address, the ``Host`` must be a loopback name
too (a DNS-rebinding page has neither the name nor the cookie). Every state-changing request is
a message on such an authenticated socket.

Who controls: the first page that connects controls; every other page watches (it sees
everything, can take control once nobody has it, and may press the ZK abort). The server pings
every page every :data:`PING_S`; a page answers at once. When the controlling page closes, it
loses control; when it sends nothing for :data:`DEADMAN_S` (a frozen tab, a dead network) while
the console runs something that needs a live hand (:meth:`Console.deadman`: a ZK console running
the engine), it loses control too. Either way the console is told
(:meth:`Console.control_lost`: a ZK console sends the engine to standby).

Live data goes out in batches at most :data:`BATCH_S` apart, the same encoded message to every
page; a page that cannot keep up loses its oldest batches first (counted), never the others'.
"""

from __future__ import annotations

import asyncio
import ipaddress
import json
import math
import os
import re
import secrets
import signal
import sys
import threading
import time

from . import STATIC

#: How often the server pings each page (seconds).
PING_S = 0.2
#: A controlling page silent for this long loses control (the dead-man rule).
DEADMAN_S = 1.0
#: Longest a live sample waits before it is sent (seconds).
BATCH_S = 0.02
#: Messages a page may have waiting before its oldest live batches are dropped.
BACKLOG = 400
#: Names a loopback-bound console answers to.
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1", "[::1]")
#: Requests a server handles itself (the consoles see the others).
OWN_OPS = ("pong", "hello", "take", "release")
#: Pages connected at once; one more is refused (HTTP 503) until one closes.
MAX_CLIENTS = 16
#: What a page's message may be (checked before anything else looks at it): its size in
#: characters, the nesting of its arrays and objects, the items of one array or object, the
#: magnitude of an integer (JSON's interoperable range), and an op's name.
MAX_MESSAGE = 4 * 1024 * 1024
MAX_DEPTH = 8
MAX_ITEMS = 4096
MAX_INT = 2 ** 53
OP_RE = re.compile(r"[a-z][a-z0-9]*(?:-[a-z0-9]+)*\Z")

CSP = ("default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; "
       "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'")


def is_loopback(host: str) -> bool:
    """True for an address only this machine reaches: a literal loopback address (127.0.0.0/8,
    ::1) or ``localhost``; never another name (``127.evil.example`` is a name anyone can point
    anywhere)."""
    h = host.strip("[]").lower()
    if h == "localhost":
        return True
    try:
        return ipaddress.ip_address(h).is_loopback
    except ValueError:
        return False


class BadMessage(ValueError):
    """A page's message that is not what a page sends (see :func:`parse_message`)."""


def _no_constant(name):
    raise BadMessage(f"{name} is not a JSON number")


def parse_message(text) -> dict:
    """A page's message, checked at the boundary before anything else sees it: a JSON object
    of at most :data:`MAX_MESSAGE` characters, arrays and objects nested at most
    :data:`MAX_DEPTH` deep with at most :data:`MAX_ITEMS` items each, finite numbers only (no
    NaN or Infinity), integers within ±2^53, string keys, and an ``op`` (when present) that is
    a lower-case name (``set``, ``sync-move``: never ``_lost`` or ``-lost``). Raises
    :class:`BadMessage` saying what is wrong."""
    if not isinstance(text, str) or len(text) > MAX_MESSAGE:
        raise BadMessage(f"a message of more than {MAX_MESSAGE} characters")
    try:
        msg = json.loads(text, parse_constant=_no_constant)
    except RecursionError:
        raise BadMessage(f"nested more than {MAX_DEPTH} deep") from None
    except BadMessage:
        raise
    except ValueError:
        raise BadMessage("not a JSON object") from None
    if not isinstance(msg, dict):
        raise BadMessage("not a JSON object")
    stack = [(msg, 1)]
    while stack:
        value, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise BadMessage(f"nested more than {MAX_DEPTH} deep")
        if len(value) > MAX_ITEMS:
            raise BadMessage(f"more than {MAX_ITEMS} items in one array or object")
        for item in (value.values() if isinstance(value, dict) else value):
            if isinstance(item, (dict, list)):
                stack.append((item, depth + 1))
            elif isinstance(item, int) and not isinstance(item, bool) and not -MAX_INT <= item <= MAX_INT:
                raise BadMessage("an integer beyond ±2^53")
            elif isinstance(item, float) and not math.isfinite(item):
                raise BadMessage("a number that is not finite")
    op = msg.get("op")
    if op is not None and not (isinstance(op, str) and OP_RE.match(op)):
        raise BadMessage(f"unknown request {op!r}"[:200])
    return msg


def new_token() -> str:
    return secrets.token_urlsafe(18)


def dumps(msg) -> str:
    return json.dumps(msg, separators=(",", ":"), ensure_ascii=False, allow_nan=False, default=_plain)


def _plain(value):
    if isinstance(value, (set, frozenset, tuple)):
        return list(value)
    if isinstance(value, bytes):
        return value.hex(" ").upper()
    return str(value)


def _agent(ua: str) -> str:
    """A short name for a browser from its User-Agent."""
    for key, name in (("Edg/", "Edge"), ("Firefox/", "Firefox"), ("Chromium/", "Chromium"), ("HeadlessChrome", "Chromium"),
                      ("Chrome/", "Chrome"), ("Safari/", "Safari")):
        if key in ua:
            return name
    return "browser"


class Client:
    """One connected page."""

    __slots__ = ("id", "ws", "addr", "agent", "name", "since", "last_seen", "queue", "wake", "dropped",
                 "task", "ping_n", "rtt_ms", "pinged")

    def __init__(self, ident, ws, addr, agent, now):
        self.id = ident
        self.ws = ws
        self.addr = addr
        self.agent = agent
        self.name = ""
        self.since = time.time()
        self.last_seen = now
        self.queue = []
        self.wake = asyncio.Event()
        self.dropped = 0
        self.task = None
        self.ping_n = 0
        self.rtt_ms = None
        self.pinged = 0.0

    @property
    def label(self) -> str:
        who = self.name or f"page {self.id}"
        return f"{who} ({self.addr}, {self.agent})"

    def info(self) -> dict:
        return {"id": self.id, "label": self.label, "name": self.name or f"page {self.id}", "addr": self.addr,
                "agent": self.agent, "since": round(self.since, 3), "rtt_ms": self.rtt_ms}


class Hub:
    """Messages to the pages, from any thread: :meth:`broadcast`, :meth:`send` (one page),
    :meth:`sample` (live data, batched); and who controls."""

    def __init__(self, loop):
        self.loop = loop
        self.clients = {}
        self.controller = None
        self._samples = []
        self._traffic = []               # the bus's bytes both ways (a console that shows them)
        self._lock = threading.Lock()
        self._flush_due = False
        self.produced = 0
        self.delivered = 0

    # -- from any thread ------------------------------------------------------------------------

    def broadcast(self, msg: dict) -> None:
        self._call(self._broadcast, dumps(msg), False)

    def send(self, client_id, msg: dict) -> None:
        self._call(self._send, client_id, dumps(msg))

    def sample(self, item: dict) -> None:
        """A live sample (a status record, a poll row): batched, at most :data:`BATCH_S` late."""
        self._batch("_samples", item, 1)

    def traffic(self, item: dict) -> None:
        """A packet seen on the device's line: batched as the live samples are (and, like them,
        the first thing a page that cannot keep up loses)."""
        self._batch("_traffic", item, 0)

    def _batch(self, name, item, produced):
        with self._lock:                  # the list by name: a flush replaces it
            getattr(self, name).append(item)
            self.produced += produced
            if self._flush_due:
                return
            self._flush_due = True
        self._call(self._schedule_flush)

    def _call(self, fn, *args):
        try:
            self.loop.call_soon_threadsafe(fn, *args)
        except RuntimeError:          # the loop is closed: the server is going away
            pass

    # -- on the loop ----------------------------------------------------------------------------

    def _schedule_flush(self):
        self.loop.call_later(BATCH_S, self._flush)

    def _flush(self):
        with self._lock:
            items, self._samples = self._samples, []
            traffic, self._traffic = self._traffic, []
            self._flush_due = False
        if traffic:
            self._broadcast(dumps({"type": "traffic", "items": traffic}), True, 0)
        if items:
            self._broadcast(dumps({"type": "samples", "s": round(time.time() * 1000, 1), "items": items}), True,
                            len(items))

    def _broadcast(self, text, live=False, count=0):
        for c in list(self.clients.values()):
            self._put(c, text, live, count)

    def _send(self, client_id, text):
        c = self.clients.get(client_id)
        if c is not None:
            self._put(c, text, False, 0)

    def _put(self, c, text, live, count):
        q = c.queue
        if len(q) >= BACKLOG:
            # a page that cannot keep up loses its oldest live batches first
            for i, (_, was_live, n) in enumerate(q):
                if was_live:
                    del q[i]
                    c.dropped += n
                    break
            else:
                del q[0]
        q.append((text, live, count))
        c.wake.set()

    async def sender(self, c):
        """Send a page's messages in order, as fast as it takes them."""
        try:
            while True:
                await c.wake.wait()
                c.wake.clear()
                while c.queue:
                    text, live, count = c.queue.pop(0)
                    await c.ws.send_str(text)
                    if live:
                        self.delivered += count
        except (ConnectionError, RuntimeError, asyncio.CancelledError):
            pass

    def control_message(self) -> dict:
        ctl = self.clients.get(self.controller)
        return {"type": "control", "controller": ctl.info() if ctl else None,
                "clients": [c.info() for c in self.clients.values()]}


class Server:
    """The aiohttp application of one console (``console``: a ZapConsole or ZkConsole)."""

    def __init__(self, console, *, host: str, port: int, token: str):
        self.console = console
        self.host = host
        self.port = port
        self.token = token
        self.loop = None
        self.hub = None
        self.runner = None
        self.url = None
        self._ids = 0
        self._tasks = []
        self._told = set()
        self.cookie = None
        self.stopping = False

    # -- start and stop -------------------------------------------------------------------------

    async def start(self) -> str:
        from aiohttp import web

        self.loop = asyncio.get_running_loop()
        self.hub = Hub(self.loop)
        app = web.Application()
        app.router.add_get("/", self.index)
        app.router.add_get("/ws", self.websocket)
        app.router.add_static("/static/", STATIC, follow_symlinks=False)
        app.on_response_prepare.append(self._headers)
        self.runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self.runner.setup()
        site = web.TCPSite(self.runner, self.host, self.port, shutdown_timeout=1.0)
        await site.start()
        bound = site._server.sockets[0].getsockname()
        self.port = bound[1]
        self.cookie = f"zkzap_token_{self.port}"
        self.url = f"http://{_url_host(self.host)}:{self.port}/?token={self.token}"
        self.console.start(self.hub)
        self._tasks = [self.loop.create_task(self._supervised(self._pinger, "the pings and the dead-man rule"))]
        return self.url

    def _internal(self, where, e) -> None:
        """An internal error the server goes on after: its traceback on stderr, once per kind."""
        import traceback

        key = (where.split(" from ")[0], type(e).__name__)
        if key not in self._told:
            self._told.add(key)
            print(f"zkzap web: internal error in {where}:", file=sys.stderr)
            traceback.print_exception(type(e), e, e.__traceback__, file=sys.stderr)

    async def _supervised(self, run, what):
        """Run ``run()`` for ever: when it fails, the console ends what needs a live hand (a ZK
        console: the engine session, with the abort) and says so, and it starts again."""
        while not self.stopping:
            try:
                await run()
                return
            except asyncio.CancelledError:
                raise
            except Exception as e:  # noqa: BLE001 - supervised: the failsafe, then on again
                self._internal(what, e)
                self.console.failsafe(f"{what} failed ({type(e).__name__}: {e})")
                await asyncio.sleep(PING_S)

    async def stop(self):
        """End the console first (a ZK console ends its engine run: 'the console is shutting
        down'), then tell the pages."""
        for t in self._tasks:
            t.cancel()
        self.stopping = True
        await self.loop.run_in_executor(None, self.console.close)
        for c in list(self.hub.clients.values()):
            try:
                await c.ws.close(code=1001, message=b"the console is shutting down")
            except Exception:  # noqa: BLE001 - a page already gone
                pass
        if self.runner is not None:
            await self.runner.cleanup()

    # -- HTTP -----------------------------------------------------------------------------------

    async def _headers(self, request, response):
        response.headers["Content-Security-Policy"] = CSP
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers["Referrer-Policy"] = "no-referrer"
        response.headers["X-Frame-Options"] = "DENY"
        if not request.path.startswith("/static/"):
            response.headers["Cache-Control"] = "no-store"

    def _authorised(self, request) -> bool:
        given = request.query.get("token") or request.cookies.get(self.cookie) or ""
        return secrets.compare_digest(given.encode(), self.token.encode())

    def _host_ok(self, request) -> bool:
        if not is_loopback(self.host):
            return True
        host = request.host.rsplit(":", 1)[0] if not request.host.endswith("]") else request.host
        return host.lower() in LOOPBACK_NAMES or is_loopback(host)

    async def index(self, request):
        from aiohttp import web

        if not self._host_ok(request):
            return web.Response(status=403, text="zkzap web: unknown host name\n")
        if not self._authorised(request):
            return web.Response(status=403, content_type="text/html", text=_FORBIDDEN)
        if "token" in request.query:
            # trade the token in the URL for a cookie, and drop it from the address bar
            resp = web.HTTPFound("/")
            resp.set_cookie(self.cookie, self.token, httponly=True, samesite="Strict", path="/")
            return resp
        with open(os.path.join(STATIC, f"{self.console.kind}.html"), encoding="utf-8") as f:
            return web.Response(text=f.read(), content_type="text/html")

    def _origin_ok(self, request) -> bool:
        origin = request.headers.get("Origin")
        if not origin:
            return False
        scheme = "https" if request.secure else "http"
        return origin.rstrip("/").lower() == f"{scheme}://{request.host}".lower()

    # -- the WebSocket --------------------------------------------------------------------------

    async def websocket(self, request):
        from aiohttp import WSMsgType, web

        if not self._host_ok(request) or not self._origin_ok(request):
            return web.Response(status=403, text="zkzap web: requests must come from the console's own page\n")
        if not self._authorised(request):
            return web.Response(status=403, text="zkzap web: the token is missing or wrong\n")
        if len(self.hub.clients) >= MAX_CLIENTS:
            return web.Response(status=503, text=f"zkzap web: {MAX_CLIENTS} pages are connected already; "
                                                 f"close one and open this page again\n")
        ws = web.WebSocketResponse(heartbeat=None, max_msg_size=MAX_MESSAGE * 4, compress=False)
        await ws.prepare(request)
        hub = self.hub
        self._ids += 1
        peer = request.remote or "?"
        c = Client(self._ids, ws, peer, _agent(request.headers.get("User-Agent", "")), self.loop.time())
        hub.clients[c.id] = c
        c.task = self.loop.create_task(hub.sender(c))
        if hub.controller is None:
            hub.controller = c.id
        hub._send(c.id, dumps({"type": "hello", "you": c.id, **self.console.hello()}))
        for msg in self.console.snapshot():
            hub._send(c.id, dumps(msg))
        hub._broadcast(dumps(hub.control_message()))
        self.console.joined(c.label, c.id == hub.controller)
        try:
            async for m in ws:
                if m.type != WSMsgType.TEXT:
                    continue
                c.last_seen = self.loop.time()
                try:
                    msg = parse_message(m.data)
                except BadMessage as e:
                    hub._send(c.id, dumps({"type": "error", "text": f"refused: {e}"}))
                    continue
                try:
                    self._message(c, msg)
                except Exception as e:  # noqa: BLE001 - no message may end a page's connection
                    self._internal(f"a message from {c.label}", e)
                    hub._send(c.id, dumps({"type": "error", "req": msg.get("req"),
                                           "text": f"internal error: {type(e).__name__}"}))
        finally:
            hub.clients.pop(c.id, None)
            c.task.cancel()
            if hub.controller == c.id:
                hub.controller = None
                if not self.stopping:
                    self.console.control_lost(c.label, "the page closed")
            hub._broadcast(dumps(hub.control_message()))
        return ws

    def _message(self, c, msg):
        hub = self.hub
        op = msg.get("op")
        req = msg.get("req")
        if not isinstance(req, (int, str)) or isinstance(req, bool) or isinstance(req, str) and len(req) > 64:
            req = None                    # an id the page can match a reply with, or none
            msg["req"] = None
        if not isinstance(op, str):       # parse_message let only a well-formed name through
            hub._send(c.id, dumps({"type": "error", "req": req, "text": f"unknown request {op!r}"}))
            return
        if op == "pong":
            t = msg.get("t")
            if msg.get("n") == c.ping_n and isinstance(t, (int, float)) and not isinstance(t, bool):
                rtt = time.time() * 1000 - t
                c.rtt_ms = round(rtt, 1) if 0 <= rtt < 3.6e6 else None   # a clock that says otherwise: unknown
            return
        if op == "hello":
            name = str(msg.get("name") or "")[:40].strip()
            if name != c.name:
                c.name = name
                hub._broadcast(dumps(hub.control_message()))
            return
        if op == "take":
            if hub.controller is None:
                hub.controller = c.id
                self.console.log(f"{c.label} takes control")
                hub._broadcast(dumps(hub.control_message()))
                hub._send(c.id, dumps({"type": "done", "req": req}))
            elif hub.controller != c.id:
                ctl = hub.clients[hub.controller]
                hub._send(c.id, dumps({"type": "error", "req": req,
                                       "text": f"{ctl.label} controls; it must release control first"}))
            else:
                hub._send(c.id, dumps({"type": "done", "req": req, "text": "this page controls already"}))
            return
        if op == "release":
            if hub.controller == c.id:
                hub.controller = None
                self.console.control_lost(c.label, "it released control")
                hub._broadcast(dumps(hub.control_message()))
            hub._send(c.id, dumps({"type": "done", "req": req}))
            return
        controlling = hub.controller == c.id
        if not controlling and op not in self.console.watch_ops:
            ctl = hub.clients.get(hub.controller)
            who = f"{ctl.label} controls" if ctl else "nobody controls: take control first"
            hub._send(c.id, dumps({"type": "error", "req": req, "text": f"view only: {who}"}))
            return
        self.console.request(c.id, c.label, msg)

    async def _pinger(self):
        """Ping every page; a controlling page silent for DEADMAN_S loses control."""
        hub = self.hub
        while True:
            await asyncio.sleep(PING_S / 2)
            now = self.loop.time()
            ctl = hub.clients.get(hub.controller)
            if ctl is not None and now - ctl.last_seen > DEADMAN_S and self.console.deadman():
                hub.controller = None
                self.console.control_lost(ctl.label, f"no heartbeat for {DEADMAN_S:g} s")
                hub._send(ctl.id, dumps({"type": "error", "text": f"you lost control: the server heard nothing "
                                                                  f"from this page for {DEADMAN_S:g} s"}))
                hub._broadcast(dumps(hub.control_message()))
            for c in list(hub.clients.values()):
                if now - c.pinged >= PING_S:
                    c.pinged = now
                    c.ping_n += 1
                    hub._put(c, dumps({"type": "ping", "n": c.ping_n, "t": round(time.time() * 1000, 1),
                                       "dropped": c.dropped, "produced": hub.produced}), False, 0)


_FORBIDDEN = """<!doctype html><meta charset="utf-8"><title>zkzap web</title>
<body style="font:16px system-ui,sans-serif;margin:3em;max-width:40em">
<h1>zkzap web: the token is missing</h1>
<p>Open the URL that <code>zkzap web</code> printed when it started: it carries the console's token
(<code>/?token=...</code>). The token then stays in a cookie of this browser for this console.</p>
</body>
"""


def _url_host(host: str) -> str:
    if host in ("0.0.0.0", "::", ""):
        import socket

        return socket.gethostname()
    return f"[{host}]" if ":" in host else host


def serve(console, *, host: str, port: int, token: str, announce, fallback_ports: int = 0) -> None:
    """Run the console's server until SIGINT, SIGTERM or another stop signal (raised afterwards as KeyboardInterrupt /
    :class:`~zkzap.signals.Terminated`, after the console closed safely). ``announce(url)`` is
    called once it listens. With ``fallback_ports``, a busy ``port`` is followed by the next ones."""
    from .. import signals as _signals

    loop = asyncio.new_event_loop()
    stop = asyncio.Event()
    got = {}

    def on_signal(signum):
        if "signum" not in got:
            got["signum"] = signum
            _signals.received(signum)
            loop.call_soon(stop.set)

    installed = []
    old = {}
    for s in _signals.STOP_SIGNALS:
        try:
            old[s] = signal.getsignal(s)
            loop.add_signal_handler(s, on_signal, s)
            installed.append(s)
        except (NotImplementedError, RuntimeError, ValueError, OSError):   # Windows, not the main thread
            old.pop(s, None)

    async def main():
        server = None
        last = None
        for p in range(port, port + 1 + fallback_ports) if port else [0]:
            server = Server(console, host=host, port=p, token=token)
            try:
                url = await server.start()
                break
            except OSError as e:
                if server.runner is not None:
                    await server.runner.cleanup()
                last = e
                server = None
        if server is None:
            from ..errors import PortError

            console.close()
            raise PortError(f"listen: cannot listen on {host}:{port}: {last.strerror or last}")
        try:
            announce(url)
            await stop.wait()
        finally:
            await server.stop()

    try:
        loop.run_until_complete(main())
    finally:
        for s in installed:
            loop.remove_signal_handler(s)
            signal.signal(s, old[s])
        loop.close()
    if "signum" in got:
        raise _signals.interruption(got["signum"])


def stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)
