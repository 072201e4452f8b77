"""--reconnect: a port that vanishes mid-run (a USB adapter dropping out) and comes back.

The ECU simulator serves a pty behind a symlink (--link); stopping it makes the device vanish,
a second simulator on the same link brings it back. Readiness is the first record on stdout,
never a fixed sleep.
"""

import json
import os
import selectors
import signal
import subprocess
import time

import pytest

from cmdtree import LocalServer

from .conftest import clean_env, executable, stop_sim

FAST = ["--speed", "10"]


def _lines(proc, want, timeout=20.0):
    """Read stdout lines until ``want(line)`` is true (returns the lines read)."""
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    out = []
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            if not sel.select(max(0.0, deadline - time.monotonic())):
                break
            line = proc.stdout.readline()
            if not line:
                break
            out.append(line)
            if want(line):
                return out
    finally:
        sel.close()
    pytest.fail(f"no such line within {timeout} s; got {out[-3:]}")


def _until_absent(path, timeout=5.0):
    end = time.monotonic() + timeout
    while os.path.lexists(path) and time.monotonic() < end:
        time.sleep(0.01)


@pytest.mark.parametrize("command,controls,sig,code", [
    (["zk", "monitor", "--duration", "30"], False, signal.SIGTERM, 143),
    # engine control was cut by the port failure: Ctrl-C only ends the logging, exit 4 says why
    (["zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "0", "--yes"], True,
     signal.SIGINT, 4),
], ids=["monitor", "send-for-0"])
def test_reconnect_after_the_port_vanished(start_sim, tmp_path, command, controls, sig, code):
    link = str(tmp_path / "ecu")
    _, first = start_sim(["zk", "--pty", "--link", link, *FAST])
    out = tmp_path / "log.csv"
    tool = executable(command[0])
    proc = subprocess.Popen([tool, *command[1:], "-p", link, "--reconnect", "20", "-f", "jsonl",
                             "--protocol-version", "6", "--raw-log", str(tmp_path / "raw.bin")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=clean_env())
    try:
        _lines(proc, lambda line: '"kind":"status"' in line)             # logging has begun
        stop_sim(first)                                                  # the adapter drops out
        _until_absent(link)
        start_sim(["zk", "--pty", "--link", link, *FAST])                # ... and comes back
        after = _lines(proc, lambda line: '"kind":"gap"' in line)
        gap = json.loads(after[-1])
        assert gap["gap_s"] > 0 and "failed" in gap["reason"]
        more = _lines(proc, lambda line: '"kind":"status"' in line)       # same stream goes on
        assert more
        if controls:
            # the engine session aborted on reconnect: the ECU goes to standby
            _lines(proc, lambda line: '"sw_state_name":"standby"' in line)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert "port back after" in err
    if controls:
        assert "sent standby" in err and "no longer controlling" in err
        assert "the port came back after" in err.splitlines()[-1]       # the error line says why
    assert proc.returncode == code
    assert os.path.getsize(tmp_path / "raw.bin") > 0
    assert not out.exists()


@pytest.mark.parametrize("extra,message", [
    ([], "failed"),                                                    # no --reconnect: at once
    (["--reconnect", "0.5"], "not back within --reconnect 0.5 s"),     # gives up after its time
], ids=["without-reconnect", "reconnect-gives-up"])
def test_a_vanished_port_is_exit_4(start_sim, tmp_path, extra, message):
    link = str(tmp_path / "ecu")
    _, first = start_sim(["zk", "--pty", "--link", link, *FAST])
    proc = subprocess.Popen([executable("zk"), "monitor", "-p", link, "--duration", "30", "-f", "jsonl", *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=clean_env())
    try:
        _lines(proc, lambda line: '"kind":"status"' in line)
        stop_sim(first)
        _, err = proc.communicate(timeout=15)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 4 and message in err, err


class FlappingBridge(LocalServer):
    """A TCP bridge to a device (``target``: host, port) that loses it when :meth:`die` is
    called: from then on it accepts each connection and closes it at once, as a network
    serial server whose device is unplugged does (the port opens, then fails)."""

    def __init__(self, target):
        import threading

        self.target = target
        self.dead = threading.Event()
        self.opened = 0
        self._conns = []
        super().__init__()

    def _pump(self, a, b):
        try:
            while not self.dead.is_set() and (chunk := a.recv(4096)):
                b.sendall(chunk)
        except OSError:
            pass
        for s in (a, b):
            try:
                s.close()
            except OSError:
                pass

    def handle(self, conn):
        import socket
        import threading

        self.opened += 1
        if self.dead.is_set():
            conn.close()
            return
        dev = socket.create_connection(self.target)
        self._conns += [conn, dev]
        for a, b in ((conn, dev), (dev, conn)):
            threading.Thread(target=self._pump, args=(a, b), daemon=True).start()

    def die(self):
        self.dead.set()
        for s in self._conns:
            try:
                s.shutdown(2)
            except OSError:
                pass


def _give_up_time(start_sim, bridge_cls, window):
    """``(exit status, stderr, seconds from the device's loss to the end, the bridge)`` of
    ``zk monitor --reconnect WINDOW`` through a ``bridge_cls`` bridge whose device is lost."""
    url, _ = start_sim(["zk", "--listen", "127.0.0.1:0", *FAST])
    host, port = url[len("socket://"):].rsplit(":", 1)
    bridge = bridge_cls((host, int(port)))
    proc = subprocess.Popen([executable("zk"), "monitor", "-p", bridge.url, "--duration", "30", "-f", "jsonl",
                             "--reconnect", window],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=clean_env())
    try:
        _lines(proc, lambda line: '"kind":"status"' in line)
        t0 = time.monotonic()
        bridge.die()
        _, err = proc.communicate(timeout=20)
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        bridge.close()
    return proc.returncode, err, took, bridge


def test_reconnect_gives_up_after_its_time_when_the_port_opens_but_fails_again(start_sim):
    """--reconnect 2 on a port that keeps opening and failing (nothing ever comes from it):
    that is one outage, counted from its first failure, never a port back; the run ends at
    2 s (exit 4), not a window later for every reopen."""
    code, err, took, bridge = _give_up_time(start_sim, FlappingBridge, "2")
    assert code == 4 and "not back within --reconnect 2 s" in err, err
    assert bridge.opened >= 3                           # it was reopened, and failed each time
    assert "port back" not in err, err
    assert 2.0 <= took < 3.5, f"gave up after {took:.2f} s"

class HangingBridge(FlappingBridge):
    """A bridge that, once its device is gone, stops taking connections at all: its listening
    socket's queue is full, so a connect hangs (no answer to the SYN), as to a network serial
    server that lost power. pyserial waits 5 s for such a connect."""

    def die(self):
        import socket

        self._stop.set()                    # nobody accepts any more ...
        self._thread.join(1)
        super().die()
        addr = self._srv.getsockname()
        self._fillers = []
        for _ in range(16):                 # ... and the queue is full: the next SYN goes unanswered
            s = socket.socket()
            s.setblocking(False)
            try:
                s.connect(addr)
            except (BlockingIOError, OSError):
                pass
            self._fillers.append(s)

    def close(self):
        for s in getattr(self, "_fillers", ()):
            s.close()
        super().close()


def test_a_reopen_that_hangs_does_not_outlast_the_reconnect_window(start_sim):
    """--reconnect 1.5 on a TCP port whose server stops answering connects: each reopen attempt
    hangs, and the run still ends when the window does (exit 4), not pyserial's 5 s connect
    timeout later."""
    code, err, took, _ = _give_up_time(start_sim, HangingBridge, "1.5")
    assert code == 4 and "not back within --reconnect 1.5 s" in err, err
    assert "port back" not in err, err
    assert 1.5 <= took < 3.0, f"gave up after {took:.2f} s"
