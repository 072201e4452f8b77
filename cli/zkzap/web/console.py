"""What the two consoles share: a worker thread that owns the device (one transaction at a
time), the requests the pages send it, the activity log, and the replies.

A request is a message ``{"op": NAME, "req": N, "grant": [PERMISSION, ...], ...}``; the worker
calls the console's ``op_NAME(ctx, msg)``. A reply is ``{"type": "done", "req": N, ...}``,
``{"type": "error", "req": N, "text": ...}`` or, when a person must confirm first,
``{"type": "consent", "req": N, "permission": ..., "text": ...}``: the page asks and sends the
same request again with the permission in ``grant``.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
import traceback
from collections import deque

from ..errors import PermissionNeeded, ZkzapError
from .consent import Needed, Policy

#: Log lines a page that connects is shown.
LOG_KEPT = 200


class Request:
    """One request being handled: who sent it (``cid``, ``label``), ``req``, ``granted``."""

    __slots__ = ("cid", "label", "req", "granted", "msg")

    def __init__(self, cid, label, msg):
        self.cid = cid
        self.label = label
        self.msg = msg
        self.req = msg.get("req")
        grant = msg.get("grant") or ()
        self.granted = frozenset(g for g in grant if isinstance(g, str)) if isinstance(grant, list) else frozenset()


class Console:
    """The base of :class:`~.zap_console.ZapConsole` and :class:`~.zk_console.ZkConsole`."""

    kind = ""
    #: Requests a page that watches may send too.
    watch_ops = frozenset()

    def __init__(self, url: str, simulated=None):
        self.url = url
        self.policy = Policy(url, simulated)
        self.hub = None
        self.logs = deque(maxlen=LOG_KEPT)
        self.failure = None           # the ZkzapError that stopped the worker (a port failure)
        self.on_log = None            # also told every log entry (the command prints it on stderr)
        self._requests = deque()
        self._wake = threading.Condition()
        self._closing = False
        self._thread = None
        self._told = set()            # the kinds of internal error whose traceback went to stderr

    # -- life -----------------------------------------------------------------------------------

    def start(self, hub) -> None:
        self.hub = hub
        self._thread = threading.Thread(target=self._main, name=f"zkzap-web-{self.kind}", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """End the worker safely (blocking): the device is left as every command leaves it."""
        with self._wake:
            self._closing = True
            self._wake.notify_all()
        self.closing()
        if self._thread is not None:
            self._thread.join()
        self.shutdown()

    def closing(self) -> None:
        """Called once when the console starts closing (any thread): wake the worker."""

    def shutdown(self) -> None:
        """Called after the worker ended: close the device."""

    def _main(self):
        try:
            self.run()
        except ZkzapError as e:
            self.failure = e
            self.log(f"stopped: {e}", "error")
            self.broadcast({"type": "failed", "text": str(e)})
        except Exception as e:  # noqa: BLE001 - reported to the pages and on stderr, not swallowed
            self.failure = e
            traceback.print_exc()
            self.log(f"stopped by an internal error: {e!r}", "error")
            self.broadcast({"type": "failed", "text": f"internal error: {e!r}"})

    def run(self) -> None:
        raise NotImplementedError

    # -- to the pages ---------------------------------------------------------------------------

    def broadcast(self, msg: dict) -> None:
        if self.hub is not None:
            self.hub.broadcast(msg)

    def reply(self, ctx, **fields) -> None:
        if self.hub is not None and ctx is not None:
            self.hub.send(ctx.cid, {"type": "done", "req": ctx.req, **fields})

    def log(self, text: str, level: str = "info") -> None:
        """A line of the activity log every page shows (``level``: info, warn, error)."""
        entry = {"type": "log", "t": round(time.time(), 3), "level": level, "text": text}
        self.logs.append(entry)
        self.broadcast(entry)
        if self.on_log is not None:
            self.on_log(entry)

    def joined(self, label: str, controls: bool) -> None:
        self.log(f"{label} connected" + (" and controls" if controls else "; it watches"))

    def hello(self) -> dict:
        """What a page needs first (besides its id): the console's kind, port and settings."""
        from .. import __version__

        return {"kind": self.kind, "port": self.url, "simulated": not self.policy.real, "version": __version__}

    def snapshot(self) -> list:
        """Messages that bring a page that just connected up to date."""
        return [{"type": "logs", "items": list(self.logs)}]

    def deadman(self) -> bool:
        """Whether a controlling page that falls silent must lose control now (any thread)."""
        return False

    def control_lost(self, label: str, reason: str) -> None:
        """The controlling page lost control (closed, released, silent)."""
        self.log(f"{label} no longer controls: {reason}")

    def failsafe(self, reason: str) -> None:
        """A part the console's safety rests on failed (the pings and the dead-man rule): end
        what needs a live hand, and say so (any thread)."""
        self.log(f"{reason}; it runs again", "error")

    # -- requests -------------------------------------------------------------------------------

    def request(self, cid, label, msg) -> None:
        """A page's request (from the server's thread): queued for the worker."""
        with self._wake:
            self._requests.append(Request(cid, label, msg))
            self._wake.notify_all()
        self.woken()

    def woken(self) -> None:
        """Called after a request was queued (any thread)."""

    def wait(self, timeout: float) -> None:
        """Sleep on the worker until a request comes or ``timeout`` s pass."""
        with self._wake:
            if not self._requests and not self._closing:
                self._wake.wait(timeout)

    def pending(self) -> bool:
        return bool(self._requests)

    def handle_requests(self) -> None:
        """Handle every queued request (on the worker)."""
        while True:
            with self._wake:
                if not self._requests:
                    return
                ctx = self._requests.popleft()
            self.handle(ctx)

    def handle(self, ctx) -> None:
        op = ctx.msg.get("op")
        fn = getattr(self, "op_" + str(op).replace("-", "_"), None) if isinstance(op, str) else None
        if fn is None:
            self.error(ctx, f"unknown request {op!r}")
            return
        try:
            with self.granting(self.policy.allow(ctx.granted)):
                fn(ctx, ctx.msg)
        except Needed as e:
            self.hub.send(ctx.cid, {"type": "consent", "req": ctx.req, "op": op, **e.message()})
        except PermissionNeeded as e:      # the library refused a frame (nothing sent): ask for it
            self.hub.send(ctx.cid, {"type": "consent", "req": ctx.req, "op": op, **self.policy.needed(e).message()})
        except ZkzapError as e:
            self.error(ctx, str(e))
        except (ValueError, TypeError, KeyError, OverflowError) as e:
            self.error(ctx, f"{op}: {e}")
        except Exception as e:  # noqa: BLE001 - no request may end the worker: said, and it goes on
            if type(e).__name__ not in self._told:
                self._told.add(type(e).__name__)
                traceback.print_exc()
            self.log(f"{op} from {ctx.label}: internal error ({type(e).__name__}: {e})", "error")
            self.error(ctx, f"{op}: internal error ({type(e).__name__})")

    @contextlib.contextmanager
    def granting(self, allow):
        """While one request runs: the library's permissions ``allow`` (what the page granted)
        on this console's port; a console whose frames go out later (an engine session) gives
        them itself."""
        yield

    def error(self, ctx, text: str) -> None:
        if self.hub is not None:
            self.hub.send(ctx.cid, {"type": "error", "req": ctx.req, "text": text})

    @property
    def closing_now(self) -> bool:
        return self._closing


def number(msg, key, kind=float, lo=None, hi=None, what=None):
    """A number from a request, checked: ``ValueError`` naming the field otherwise (a huge
    integer, NaN or an infinity included: the range is checked before any conversion)."""
    value = msg.get(key)
    name = what or key
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        if isinstance(value, str) and len(value) <= 40:
            try:
                value = float(value) if kind is float or not value.strip().lstrip("+-").isdigit() else int(value)
            except ValueError:
                raise ValueError(f"{name}: {value!r} is not a number") from None
        else:
            raise ValueError(f"{name}: {_short(value)} is not a number")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{name}: {value!r} is not a finite number")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ValueError(f"{name}: {_short(value)} is out of range; allowed {lo:g}..{hi:g}")
    if kind is int:
        if value != int(value):
            raise ValueError(f"{name}: {value!r} is not a whole number")
        return int(value)
    return float(value)


def _short(value) -> str:
    """``value`` for a message: a number in a few characters, anything else cut short."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10 ** 15:
        return f"a {len(str(abs(value)))}-digit number"
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."
