"""The late window, the latency hint and the USB adapter's latency timer, from the command line."""

import json
import os

import pytest

from zkzap.link import adapters, zap_timing
from zkzap.link.port import sim_url
from zkzap.sim import start_zap


def slow(ms):
    return sim_url("zap", ids="1", turnaround=str(ms))


def test_a_reply_later_than_the_window_is_missed_and_the_latency_hint_widens_it(cli, monkeypatch):
    r = cli("zap", "echo", "--id", "1", "--retries", "0", "-p", slow(300))
    assert r.exit_code == 3 and "within 150.0 ms" in r.stderr       # the default window: 150 ms
    r = cli("zap", "echo", "--id", "1", "--retries", "0", "-f", "jsonl", "--latency", "300", "-p", slow(300))
    assert r.exit_code == 0, r
    assert json.loads(r.stdout)["rtt_ms"] >= 300                    # its true round trip
    monkeypatch.setenv("ZKZAP_ZAP_LATENCY", "300")
    r = cli("zap", "echo", "--id", "1", "--retries", "0", "-p", slow(300))
    assert r.exit_code == 0, r
    r = cli("zap", "echo", "--id", "1", "--retries", "0", "--timeout", "0.4", "-p", slow(300))
    assert r.exit_code == 0, r                                      # --timeout is the window


def test_low_latency_where_the_port_has_none_is_a_note(cli):
    r = cli("zap", "echo", "--id", "1", "--sim", "--low-latency")
    assert r.exit_code == 0, r
    assert "--low-latency:" in r.stderr and "not available" in r.stderr


def test_low_latency_is_the_batchs_own_port_option(cli, tmp_path):
    f = tmp_path / "b.txt"
    f.write_text("echo --id 1 --low-latency\n")
    r = cli("zap", "batch", str(f), "--sim")
    assert r.exit_code == 2 and "low-latency" in r.stderr


@pytest.fixture
def ftdi(tmp_path, monkeypatch):
    """A pty to a simulated bus answering 18 ms late, posing as an FTDI adapter whose latency
    timer (in a fake sysfs tree) is ``timer`` ms."""
    def make(timer):
        sim = start_zap(ids=[1], turnaround=18, transport="pty")
        sysfs = tmp_path / "sys"
        name = os.path.basename(os.path.realpath(sim.url))
        (sysfs / name).mkdir(parents=True)
        (sysfs / name / "latency_timer").write_text(f"{timer}\n")
        monkeypatch.setattr(adapters, "SYSFS_USB_SERIAL", str(sysfs))
        started.append(sim)
        return sim.url, sysfs / name / "latency_timer"

    started = []
    yield make
    for sim in started:
        sim.close()


def test_a_latency_that_shows_the_adapters_timer_says_once_how_to_lower_it(cli, ftdi, tmp_path):
    url, path = ftdi(16)
    r = cli("zap", "echo", "--id", "1", "--count", "3", "-p", url)
    assert r.exit_code == 0, r
    hint = [line for line in r.stderr.splitlines() if "USB adapter" in line]
    assert len(hint) == 1 and "its latency timer is 16 ms" in hint[0]
    assert f"echo 1 | sudo tee {path}" in hint[0] and "--low-latency" in hint[0]
    batch = tmp_path / "b.txt"
    batch.write_text("echo --id 1\nload present-position --id 1\necho --id 1\n")
    zap_timing._POLICIES.clear()                                    # as a new process would start
    r = cli("zap", "batch", str(batch), "-p", url)
    assert r.exit_code == 0, r
    assert sum("USB adapter" in line for line in r.stderr.splitlines()) == 1     # once a process


def test_a_fast_timer_or_a_fast_bus_gets_no_hint(cli, ftdi):
    url, _ = ftdi(1)
    r = cli("zap", "echo", "--id", "1", "--count", "2", "-p", url)
    assert r.exit_code == 0 and "USB adapter" not in r.stderr
