"""A tapped serial link: a relay copies bytes between a host pty and a simulator's pty, keeps
what each side sent, and (for the sniffer tests) feeds copies to the sniffer's ptys, as
receive-only adapters on a real link would see them. Whatever the sniffer writes to its ptys is
kept in ``sniffer_wrote``."""

from __future__ import annotations

import os
import select
import termios
import threading
import tty


def _pty(baud=None):
    master, slave = os.openpty()
    tty.setraw(slave)
    if baud:
        _speed(slave, baud)
    return master, slave, os.ttyname(slave)


def _speed(fd, baud):
    attrs = termios.tcgetattr(fd)
    attrs[4] = attrs[5] = getattr(termios, f"B{baud}")
    termios.tcsetattr(fd, termios.TCSANOW, attrs)


class Relay(threading.Thread):
    """``host_path``: the pty the host opens. ``taps``: 0 (none), 1 (one sniffer pty seeing
    both directions) or 2 (``tap_paths[0]`` sees the host's bytes, ``tap_paths[1]`` the
    device's). :meth:`sent` is what the host wrote so far."""

    def __init__(self, device_path, baud, taps=1):
        super().__init__(daemon=True)
        self.dev = os.open(device_path, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self.dev)
        _speed(self.dev, baud)          # the simulator hears a host at this baud
        self.host_m, self.host_s, self.host_path = _pty(baud)
        self.taps = [_pty(baud) for _ in range(taps)]
        self.tap_paths = [p for _, _, p in self.taps]
        self.sniffer_wrote = bytearray()
        self.host_bytes = bytearray()
        self.device_bytes = bytearray()
        self.lock = threading.Lock()
        self._halt = threading.Event()
        self._r, self._w = os.pipe()

    def run(self):
        taps = [m for m, _, _ in self.taps]
        to_host_tap = taps[0] if taps else None
        to_dev_tap = taps[-1] if taps else None
        watch = [self.host_m, self.dev, self._r] + taps
        while not self._halt.is_set():
            ready, _, _ = select.select(watch, [], [], 0.5)
            for fd in ready:
                try:
                    data = os.read(fd, 4096)
                except OSError:
                    data = b""
                if not data:
                    continue
                if fd == self.host_m:
                    with self.lock:
                        self.host_bytes += data
                    os.write(self.dev, data)
                    if to_host_tap is not None:
                        os.write(to_host_tap, data)
                elif fd == self.dev:
                    self.device_bytes += data
                    os.write(self.host_m, data)
                    if to_dev_tap is not None:
                        os.write(to_dev_tap, data)
                elif fd in taps:
                    self.sniffer_wrote += data

    def sent(self) -> bytes:
        """What the host wrote so far."""
        with self.lock:
            return bytes(self.host_bytes)

    def stop(self):
        self._halt.set()
        os.write(self._w, b"x")
        self.join(5)
        for fd in [self.dev, self.host_m, self.host_s, self._r, self._w] + [x for m, s, _ in self.taps for x in (m, s)]:
            try:
                os.close(fd)
            except OSError:
                pass
