"""Serve a simulated device on a pseudo-terminal or a TCP socket until SIGINT/SIGTERM.

The first line on stdout is the port to use (a pty path, or ``socket://HOST:PORT``), flushed
at once, so a script can read it and start talking. On a pty the host's line settings (baud
rate, stop bits) are read from the terminal settings on every transfer, so a device with line
settings of its own (``device.line``, see :mod:`zkzap.sim.uart`) misframes what a host at other
settings sends and reads. A pty needs a POSIX system (termios); TCP works everywhere.
"""

from __future__ import annotations

import os
import selectors
import socket
import sys
import time

from ..errors import UsageError
from .base import Clock

_BAUDS = (50, 75, 110, 134, 150, 200, 300, 600, 1200, 1800, 2400, 4800, 9600, 19200, 38400, 57600, 115200,
          230400, 460800, 500000, 576000, 921600, 1000000, 1152000, 1500000, 2000000, 2500000, 3000000,
          3500000, 4000000)


class PtyUnsupported(UsageError, RuntimeError):
    """Pseudo-terminals need a POSIX system (termios): a :class:`~zkzap.errors.UsageError`."""


def _termios():
    try:
        import termios
        import tty
    except ImportError:
        raise PtyUnsupported("a pseudo-terminal needs a POSIX system (Linux, macOS, BSD); "
                             "serve on TCP instead (--listen 127.0.0.1:0)") from None
    return termios, tty


def host_settings(termios, fd, speeds):
    """(baud, stop bits) of the terminal ``fd`` (the host's side of the pty)."""
    attrs = termios.tcgetattr(fd)
    return speeds.get(attrs[5]), 2 if attrs[2] & termios.CSTOPB else 1


class _Stop(Exception):
    pass


def stop_signals():
    """The signals that stop a simulator: SIGINT, SIGTERM, and on Windows SIGBREAK (Ctrl-Break)."""
    from ..signals import STOP_SIGNALS

    return list(STOP_SIGNALS)


def _install_signals():
    def handler(signum, frame):
        raise _Stop()

    from ..signals import handle

    handle(stop_signals(), handler)


def _deliver(device, data, now, settings):
    line = getattr(device, "line", None)
    if line is not None:
        device.receive(data, now, settings[0], settings[1])
    else:
        device.receive(data, now, settings[0])


def _outgoing(device, data, settings):
    line = getattr(device, "line", None)
    return data if line is None else line.to_host(data, *settings)


def _announce(text, out):
    out.write(text + "\n")
    out.flush()


#: How long the serving loop sleeps when nothing is due (it wakes at once for the host's bytes).
IDLE_S = 0.5


def _timeout(device, clock):
    wake = device.next_wakeup(clock.now())
    if wake is None:
        return IDLE_S
    return min(IDLE_S, clock.real_delay(wake - clock.now()))


def _selector():
    """A selector that wakes when a reply is due to the microsecond: select(2) takes its timeout
    in microseconds, where epoll and poll round it up to the next millisecond (every reply up to
    a millisecond late)."""
    if hasattr(selectors, "SelectSelector"):
        return selectors.SelectSelector()
    return selectors.DefaultSelector()


def _fine_timers() -> None:
    """Wake this thread when its timers expire, not up to 50 us later: Linux lets a sleeping
    thread's timer slip by its timer slack (50 us by default) to batch wake-ups, and every
    reply the simulator sends would come that much later than the line it models."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(29, 1, 0, 0, 0)     # PR_SET_TIMERSLACK, 1 ns
    except (OSError, AttributeError):
        pass


#: With ``precise``, the last this-many seconds of a wait for a due reply byte are a poll loop,
#: not a sleep: a sleeping thread wakes 0.1-0.2 ms after its timer (an idle core, a virtual
#: machine), and every reply would reach the host that much later than the line it models.
SPIN_S = 0.0003
#: With ``precise``, for this long after a reply has gone out the loop polls for the host's next
#: request instead of sleeping: a thread asleep in select(2) saw the host's bytes 0.05-0.09 ms
#: after they were written (measured on a virtual machine, against 0.03-0.06 ms polling), and a
#: host that asks again at once (a batch, a poll loop) would have its request heard, and its
#: reply sent, that much later than the line allows.
LISTEN_S = 0.0005


def _poll(sel, until):
    """Poll ``sel`` until something is ready or the monotonic time ``until`` has come."""
    while True:
        events = sel.select(0)
        if events or time.monotonic() >= until:
            return events


def _select(sel, wait, precise, listen_until=0.0):
    """``sel.select(wait)``; with ``precise`` (and a reply byte due within the wait), the end of
    the wait polls, so the byte goes out on time, and so does the time up to ``listen_until``
    (a monotonic time: see :data:`LISTEN_S`), so the host's next request is heard when it comes.
    Only for a simulator in a process of its own (``zkzap sim``): in a thread of the host's
    process it would hold the interpreter lock that the host needs to read the reply."""
    if not precise or wait <= 0:
        return sel.select(wait)
    due = wait < IDLE_S                    # a reply byte is due within the wait (else nothing is)
    now = time.monotonic()
    deadline = now + wait
    if listen_until > now:                 # the host's next request: heard as it comes
        events = _poll(sel, min(listen_until, deadline))
        now = time.monotonic()
        if events or now >= deadline:
            return events
        wait = deadline - now
    if not due:
        return sel.select(wait)
    if wait > SPIN_S:
        events = sel.select(wait - SPIN_S)
        if events:
            return events
    return _poll(sel, deadline)


class _NoLock:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def run_pty(device, clock: Clock, ready, *, stop_fd=None, lock=None, link=None, precise=False) -> None:
    """Serve ``device`` on a new pseudo-terminal until ``stop_fd`` becomes readable (or a signal
    handler raises). ``ready(path)`` is called once the pty exists (with ``link``, the path is
    also a symlink there); ``lock`` (a context manager) is held around every use of the device,
    for a caller that inspects it from another thread; ``precise``: see :func:`_select`. The
    device is not closed here."""
    termios, tty = _termios()
    speeds = {getattr(termios, f"B{b}"): b for b in _BAUDS if hasattr(termios, f"B{b}")}
    lock = lock or _NoLock()
    _fine_timers()
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        path = os.ttyname(slave)
        if link:
            from ..outfile import make_link

            make_link(path, link)           # only an old symlink is replaced, never a file or device
        sel = _selector()
        sel.register(master, selectors.EVENT_READ, "data")
        if stop_fd is not None:
            sel.register(stop_fd, selectors.EVENT_READ, "stop")
        try:
            ready(link or path)
            listen = 0.0
            while True:
                with lock:
                    wait = _timeout(device, clock)
                events = _select(sel, wait, precise, listen)
                heard = clock.now()               # the host's bytes were there when select saw them
                settings = host_settings(termios, slave, speeds)     # the host's, once a turn
                for key, _ in events:
                    if key.data == "stop":
                        return
                    try:
                        data = os.read(master, 4096)
                    except OSError:
                        data = b""
                    if data:
                        with lock:
                            _deliver(device, data, heard, settings)
                with lock:
                    reply = device.poll_line(clock.now(), settings[0])
                if reply:
                    os.write(master, _outgoing(device, reply, settings))
                    listen = time.monotonic() + LISTEN_S
        finally:
            sel.close()
    finally:
        os.close(master)
        os.close(slave)
        if link:
            try:
                os.unlink(link)
            except OSError:
                pass


def serve_pty(device, clock: Clock, out=sys.stdout, link=None) -> None:
    """Run ``device`` on a new pseudo-terminal until SIGINT/SIGTERM; its path is announced on
    ``out`` (and, with ``link``, also made available as a symlink at that path)."""
    _termios()                             # a clear refusal on a system without ptys, first
    _install_signals()
    try:
        # a signal right after the line is announced is a stop
        run_pty(device, clock, lambda path: _announce(path, out), link=link, precise=True)
    except _Stop:
        pass
    finally:
        device.close()


def _refuse(conn, addr) -> None:
    """A second host on a one-host line: closed at once, and said so on stderr."""
    where = f"{addr[0]}:{addr[1]}" if isinstance(addr, tuple) and len(addr) >= 2 else str(addr)
    try:
        conn.close()
    finally:
        sys.stderr.write(f"note: refused a second client ({where}): one host at a time, like a serial line\n")
        sys.stderr.flush()


def run_tcp(device, clock: Clock, ready, *, host="127.0.0.1", port=0, stop_fd=None, lock=None,
            precise=False) -> None:
    """Serve ``device`` behind a TCP socket until ``stop_fd`` becomes readable (or a signal
    handler raises); ``ready(url)`` gets ``socket://HOST:PORT`` once it listens (port 0 picks a
    free port); ``lock`` and ``precise`` as for :func:`run_pty`. The device is not closed here.

    One client at a time, like a serial line with one host: while a client is connected, a
    second connection is accepted and closed at once (its reads see the end of the stream) and
    a line on stderr says so; the first client keeps the device. Once it disconnects, the next
    client gets it."""
    lock = lock or _NoLock()
    _fine_timers()
    srv = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
    client = None
    sel = _selector()
    try:
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        srv.bind((host, port))
        srv.listen(1)
        actual = srv.getsockname()[1]
        sel.register(srv, selectors.EVENT_READ, "accept")
        if stop_fd is not None:
            sel.register(stop_fd, selectors.EVENT_READ, "stop")
        shown = f"[{host}]" if ":" in host else host
        ready(f"socket://{shown}:{actual}")

        def drop():
            nonlocal client
            sel.unregister(client)
            client.close()
            client = None

        listen = 0.0
        while True:
            with lock:
                wait = _timeout(device, clock)
            # a client's bytes (or its going) first: one that leaves frees the line for the next
            events = _select(sel, wait, precise, listen)
            heard = clock.now()                   # the client's bytes were there when select saw them
            for key, _ in sorted(events, key=lambda e: e[0].data != "client"):
                if key.data == "stop":
                    return
                if key.data == "accept":
                    conn, addr = srv.accept()
                    if client is not None:
                        _refuse(conn, addr)
                        continue
                    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    client = conn
                    sel.register(client, selectors.EVENT_READ, "client")
                    continue
                try:
                    data = client.recv(4096)
                except OSError:
                    data = b""
                if data:
                    with lock:
                        _deliver(device, data, heard, (None, None))
                else:
                    drop()
            with lock:
                reply = device.poll(clock.now())
            if reply and client is not None:
                try:
                    client.sendall(reply)
                except OSError:
                    drop()
                listen = time.monotonic() + LISTEN_S
    finally:
        if client is not None:
            client.close()
        sel.close()
        srv.close()


def serve_tcp(device, clock: Clock, host="127.0.0.1", port=0, out=sys.stdout) -> None:
    """Run ``device`` behind a TCP socket until SIGINT/SIGTERM (see :func:`run_tcp`); the URL
    ``socket://HOST:PORT`` is announced on ``out``."""
    _install_signals()
    try:
        run_tcp(device, clock, lambda url: _announce(url, out), host=host, port=port, precise=True)
    except _Stop:
        pass
    finally:
        device.close()
