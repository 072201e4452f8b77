"""One open port for many commands (``zap batch``, ``zk batch``, ``zkzap shell``).

While :func:`sharing` is active, the commands' own port openings (:func:`zkzap.commands.zap.
compose.open_link`, :meth:`zkzap.link.zk_port.ZkLink.open`) borrow the shared link instead of
opening the port again: each command runs over the same open port, and its "close" leaves the
port open. The line settings a command changes for itself (the return mode, retries and timeout
of the bus, the permissions it was given, its late window and latency hint; a scan's baud rate)
are put back when it returns it; what the bus learned (the actuators' latencies) stays for the
next command.
"""

from __future__ import annotations

import contextlib
import operator

#: The shared link by protocol: "zap" -> ZapBus, "zk" -> ZkLink.
_SHARED: dict = {}


@contextlib.contextmanager
def sharing(protocol: str, link):
    """Share ``link`` (a ZapBus or a ZkLink) for ``protocol`` while the block runs."""
    old = _SHARED.get(protocol)
    _SHARED[protocol] = link
    try:
        yield link
    finally:
        if old is None:
            _SHARED.pop(protocol, None)
        else:
            _SHARED[protocol] = old


def shared(protocol: str):
    """The link shared for ``protocol``, or None."""
    return _SHARED.get(protocol)


#: The bus settings a command may change for itself (put back when it returns the bus).
SETTINGS = ("return_mode", "retries", "timeout", "latency", "allow")
#: A bus's SETTINGS as a tuple, in one call (a batch borrows its bus on every line).
_settings = operator.attrgetter(*SETTINGS)


class Borrowed:
    """A shared ZapBus lent to one command: ``with`` gives the bus itself; leaving the block
    restores the bus's settings (and its baud rate, unless ``keep_baud``) instead of closing."""

    keep_baud = False

    def __init__(self, bus, **settings):
        self.bus = bus
        self.saved = _settings(bus)
        self.baud = bus.baud
        for k, v in settings.items():
            if getattr(bus, k) != v:
                setattr(bus, k, v)

    def __getattr__(self, name):
        return getattr(self.bus, name)

    def __enter__(self):
        return self.bus

    def __exit__(self, *exc):
        self.close()

    def close(self):
        """Give the bus back: restore its settings (and baud rate), leave the port open."""
        bus = self.bus
        if _settings(bus) != self.saved:
            for k, v in zip(SETTINGS, self.saved):
                if getattr(bus, k) != v:   # (what the command changed, and nothing else)
                    setattr(bus, k, v)
        if not Borrowed.keep_baud and self.bus.baud != self.baud:
            self.bus.set_baud(self.baud)
