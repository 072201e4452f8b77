"""The ECU simulator's UART over a real pty: detection and monitoring at its line settings."""

import json

import pytest


@pytest.mark.parametrize("baud, stop", [(9600, 2), (2400, 1), (115200, 2)])
def test_detect_over_a_pty(start_sim, sh, baud, stop):
    url, _ = start_sim(["zk", "--pty", "--baud", str(baud), "--stop-bits", str(stop), "--speed", "5"])
    r = sh("zk", "detect", "-p", url)
    assert r.exit_code == 0, r
    rec = json.loads(r.stdout)
    assert (rec["baud"], rec["stop_bits"], rec["protocol_version"]) == (baud, stop, 6)


def test_monitor_at_the_wrong_setting_then_auto(start_sim, sh):
    url, _ = start_sim(["zk", "--pty", "--baud", "19200", "--stop-bits", "2", "--speed", "5"])
    r = sh("zk", "monitor", "-p", url, "-b", "57600", "--count", "3", "--timeout", "0.6", "-f", "jsonl")
    assert r.exit_code == 3 and r.stdout == ""
    r = sh("zk", "monitor", "-p", url, "-b", "auto", "--count", "3", "-f", "jsonl")
    assert r.exit_code == 0, r
    assert len(r.stdout.splitlines()) == 3
    assert "detected 19200 baud, 2 stop bits" in r.stderr


def test_sim_line_options_are_checked(sh):
    r = sh("zkzap", "sim", "zk", "--stop-bits", "3")
    assert r.exit_code == 2 and r.stdout == ""
    r = sh("zkzap", "sim", "zk", "--baud", "9600", "--set", "baud=4800")
    assert r.exit_code == 2 and "give one" in r.stderr
