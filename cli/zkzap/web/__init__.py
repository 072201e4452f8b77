"""The browser console: ``zkzap web zap|zk`` serves a single-page console for an actuator bus or
an ECU over HTTP, with live data on a WebSocket.

Layers: the consoles (:mod:`.zap_console`, :mod:`.zk_console`) drive the public API
(:class:`zkzap.api.zap.Bus`, :class:`zkzap.api.zk.Ecu` with :class:`zkzap.api.session.Session`)
on a worker thread of their own, one device transaction at a time; :mod:`.server` is the
aiohttp application (pages, static files, the WebSocket, the token and origin checks, who
controls, the heartbeat); :mod:`.consent` is the one place that decides which requests need a
person's confirmation. The pages are plain HTML, CSS and JavaScript under ``static/``, with uPlot
(MIT licence, ``static/vendor/``) for the plots: no build step, nothing fetched at run time.

aiohttp comes with the optional extra ``web`` (``pip install 'zkzap[web]'``); it is imported
only here, when a console starts.
"""

from __future__ import annotations

import os

#: Where the pages and their assets are.
STATIC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "static")
#: The optional extra that brings the server's library.
EXTRA = "web"


def require() -> None:
    """Refuse (exit 2) when aiohttp is missing, naming the extra to install."""
    import importlib.util

    from ..errors import UsageError

    try:
        found = importlib.util.find_spec("aiohttp") is not None
    except (ImportError, ValueError):
        found = False
    if not found:
        raise UsageError(f"web: needs the aiohttp library; install it with pip install 'zkzap[{EXTRA}]'")
