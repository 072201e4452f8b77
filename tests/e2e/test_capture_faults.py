"""Captures stay whole and readable after Ctrl-C, SIGTERM and a full disk (real subprocesses on
a pty simulator)."""

from __future__ import annotations

import signal
import subprocess

import pytest

from zkzap.link.pcapng import INBOUND, OUTBOUND, Reader

from .conftest import clean_env, executable
from .test_faults import LIMIT, small_disk


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_capture_is_whole_after_a_signal(start_sim, tmp_path, sig):
    url, _ = start_sim(["zk", "--speed", "20", "--pty"])
    cap = tmp_path / "run.pcapng"
    p = subprocess.Popen([executable("zk"), "monitor", "-p", url, "--keepalive", "-f", "jsonl", "--capture",
                          str(cap)], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, env=clean_env())
    lines = [p.stdout.readline() for _ in range(25)]        # running: 25 records written
    assert all(lines), lines
    p.send_signal(sig)
    _, err = p.communicate(timeout=15)
    assert p.returncode == (130 if sig == signal.SIGINT else 143), err
    r = Reader(str(cap), "zk")
    pkts = list(r)
    assert not r.truncated
    assert {k.direction for k in pkts} == {INBOUND, OUTBOUND}
    assert all(a.ts <= b.ts for a, b in zip(pkts, pkts[1:]))
    assert sum(len(k.data) for k in pkts if k.direction == INBOUND) >= 25 * 7


def test_capture_on_a_full_disk_keeps_its_whole_blocks(start_sim, tmp_path):
    url, _ = start_sim(["zk", "--speed", "100", "--pty"])
    cap = tmp_path / "run.pcapng"
    r = subprocess.run([executable("zk"), "monitor", "-p", url, "--count", "20000", "-f", "jsonl", "--capture",
                        str(cap)], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                       text=True, env=clean_env(), preexec_fn=small_disk, timeout=120)
    assert r.returncode == 7, r.stderr
    assert r.stderr.endswith(f"zk: error: capture: cannot write {cap}: File too large\n"), r.stderr
    assert 0 < cap.stat().st_size <= LIMIT
    rd = Reader(str(cap), "zk")
    assert len(list(rd)) > 100 and not rd.truncated
