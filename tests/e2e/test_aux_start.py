"""An aux source that ends before its first line fails the start check: exit 3 before anything
is sent (stdin at its end, a FIFO whose writer closes at once), for a session that only
listens and for one that would control the engine."""

from __future__ import annotations

import os
import subprocess
import threading

import pytest

from zkzap.sim import start_zk

from .conftest import clean_env, executable


@pytest.mark.parametrize("source", ["stdin", "fifo"])
@pytest.mark.parametrize("argv", [["zk", "monitor", "--duration", "2"],
                                  ["zk", "send", "control", "--state", "run", "--throttle", "20", "--for", "2",
                                   "--yes"]], ids=["monitor", "send-for"])
def test_an_aux_source_that_ends_before_its_first_line_is_exit_3_with_nothing_sent(tmp_path, source, argv):
    fifo = tmp_path / "sensor"
    if source == "fifo":
        os.mkfifo(fifo)

        def writer_closes():
            os.close(os.open(fifo, os.O_WRONLY))             # opens, writes nothing, closes

        threading.Thread(target=writer_closes, daemon=True).start()
    with start_zk(speed=10, transport="pty") as ecu:
        r = subprocess.run([executable("zkzap"), *argv, "-p", ecu.url, "-f", "jsonl",
                            "--aux", "-" if source == "stdin" else str(fifo)],
                           stdin=subprocess.DEVNULL, capture_output=True, text=True, env=clean_env(), timeout=60)
        with ecu.lock:
            received = list(ecu.device.received)
    assert r.returncode == 3, r.stderr
    assert "aux: no reading from" in r.stderr and "before it ended" in r.stderr
    assert r.stdout == "" and received == []
