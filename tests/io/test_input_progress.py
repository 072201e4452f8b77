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


def _screen_until(master, want, work, timeout=20.0):
    """What the terminal's side got while ``work(done)`` runs, until every text of ``want`` was
    shown (``done()`` then tells the work to end)."""
    got = []
    finished = threading.Event()
    worker = threading.Thread(target=work, args=(finished.is_set,), daemon=True)
    worker.start()
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        got.append(_drain(master))
        screen = b"".join(got).decode("utf-8", "replace")
        if all(w in screen for w in want):
            break
    finished.set()
    worker.join(10)
    got.append(_drain(master))
    return b"".join(got).decode("utf-8", "replace")


def test_a_pipe_of_unknown_size_gets_a_running_count_and_a_long_work_its_steps():
    pty = pytest.importorskip("pty")
    from zkzap.infile import counted
    from zkzap.io.term import STREAM_MIN, working

    master, slave = pty.openpty()
    r, w = os.pipe()
    stopped = threading.Event()

    size = STREAM_MIN + (2 << 20)       # 2 MiB more than the count needs

    def feed():                         # then the pipe stays open until the reader is done
        with os.fdopen(w, "wb") as out:
            out.write(b"\0" * size)
            out.flush()
            stopped.wait(30)

    def read(done):                     # the reader: through the counter, then it waits on the pipe
        with os.fdopen(r, "rb") as raw, counted(raw, "stdin") as f:
            got = 0
            while got < size:
                got += len(f.read(1 << 16))
            while not done():
                time.sleep(0.01)
        stopped.set()

    with os.fdopen(slave, "w", encoding="utf-8") as stream, input_progress(stream, minimum=1 << 20):
        feeder = threading.Thread(target=feed, daemon=True)
        feeder.start()
        screen = _screen_until(master, ["reading stdin", "MB read"], read)
        feeder.join(10)
        assert "reading stdin" in screen and "MB read" in screen, screen     # the bytes so far (and a rate)

        def draw(done):
            with working("report: drawing", total=3) as work:
                work.step("report: drawing engine speed", 1)
                while not done():
                    time.sleep(0.01)
        screen = _screen_until(master, ["report: drawing engine speed", "1/3"], draw)
        assert "report: drawing engine speed" in screen and "1/3" in screen, screen
    os.close(master)
    assert reading() == [] and STREAM_MIN > 0

