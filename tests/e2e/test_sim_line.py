"""The TCP simulators behave like a serial line with one host: a second client is refused while
the first keeps the device, and takes it once the first has gone."""

from __future__ import annotations

import socket
import time

import pytest

from zkzap.codec import zap


def _connect(url):
    host, port = url[len("socket://"):].rsplit(":", 1)
    return socket.create_connection((host, int(port)), timeout=5)


def _read_until_closed_or(sock, predicate, timeout=5.0):
    sock.settimeout(0.2)
    data = b""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            chunk = sock.recv(4096)
        except socket.timeout:
            if predicate(data):
                return data, False
            continue
        if not chunk:
            return data, True
        data += chunk
        if predicate(data):
            return data, False
    return data, False


@pytest.mark.parametrize("kind,args", [("zk", []), ("zap", ["--ids", "1"])])
def test_a_second_client_is_refused_while_the_first_keeps_the_device(start_sim, kind, args):
    url, proc = start_sim([kind, *args, "--listen", "127.0.0.1:0"])
    first = _connect(url)
    if kind == "zap":
        first.sendall(zap.echo(1))
    data, closed = _read_until_closed_or(first, lambda d: len(d) >= 7)
    assert not closed and len(data) >= 7                      # the first client is served
    second = _connect(url)
    data2, closed2 = _read_until_closed_or(second, lambda d: False, timeout=5)
    assert closed2 and data2 == b""                           # refused: closed at once
    line = proc.stderr.readline().decode()
    assert "refused a second client" in line and "one host at a time" in line
    if kind == "zap":
        first.sendall(zap.echo(1))
    data, closed = _read_until_closed_or(first, lambda d: len(d) >= 7)
    assert not closed and len(data) >= 7                      # ... and the first still is
    first.close()
    third = None
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:                        # once it has gone, the next one is served
        third = _connect(url)
        if kind == "zap":
            third.sendall(zap.echo(1))
        data, closed = _read_until_closed_or(third, lambda d: len(d) >= 7, timeout=2)
        if not closed and len(data) >= 7:
            break
        third.close()
        third = None
    assert third is not None
    third.close()
    second.close()
