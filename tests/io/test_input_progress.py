"""A large input file read on a terminal gets a progress bar on stderr (bytes read of its size,
the speed, the time left), erased when it has been read; off a terminal nothing at all."""

from __future__ import annotations

import io
import os
import select
import threading
import time

import pytest

from zkzap.infile import open_input, reading
from zkzap.io.term import input_progress


def _slowly(path, pause=0.08):
    with open_input(str(path)) as f:
        while f.read(256 << 10):
            time.sleep(pause)                   # a slow reader: a decoder of a large capture


def _drain(fd) -> bytes:
    out = b""
    while select.select([fd], [], [], 0.2)[0]:
        try:
            chunk = os.read(fd, 65536)
        except OSError:
            break
        if not chunk:
            break
        out += chunk
    return out


def test_a_large_input_gets_a_progress_bar_on_a_terminal(tmp_path):
    pty = pytest.importorskip("pty")
    big = tmp_path / "capture.bin"
    big.write_bytes(b"\0" * (4 << 20))
    master, slave = pty.openpty()
    got = []
    stop = threading.Event()

    def collect():                              # the terminal's side: read as it is written
        while not stop.is_set():
            got.append(_drain(master))

    reader = threading.Thread(target=collect, daemon=True)
    reader.start()
    with os.fdopen(slave, "w", encoding="utf-8") as stream:
        with input_progress(stream, minimum=1 << 20):
            threads = threading.active_count()
            with input_progress(stream, minimum=1 << 20):       # a command inside (a batch's line)
                assert threading.active_count() == threads      # no second watcher: one bar
                _slowly(big)
    stop.set()
    reader.join(5)
    got.append(_drain(master))
    os.close(master)
    screen = b"".join(got).decode("utf-8", "replace")
    assert "reading capture.bin" in screen and "/4.2 MB" in screen, screen
    assert screen.count("reading capture.bin") == screen.count("/4.2 MB")
    assert reading() == []                      # closed: no longer an input being read


def test_off_a_terminal_nothing_is_shown(tmp_path):
    big = tmp_path / "run.csv"
    big.write_bytes(b"x" * (2 << 20))
    threads = threading.active_count()
    out = io.StringIO()
    with input_progress(out, minimum=1):
        assert threading.active_count() == threads          # no watcher, no rich: not a terminal
        _slowly(big, pause=0)
    assert out.getvalue() == ""
    with open_input(str(big)) as f:
        f.read(1000)
        ((path, done, size),) = reading()
        assert path == str(big) and size == 2 << 20 and 1000 <= done <= size
