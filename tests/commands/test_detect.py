"""zk detect and zk monitor --baud auto: the ECU's line settings found by listening, at every
setting the ZK document allows, against the ECU simulator."""

import json

import pytest

from zkzap.api import detect as D
from zkzap.link.port import close_port, open_port

SETTINGS = [(b, s) for b in D.BAUDS for s in (1, 2)]


@pytest.mark.parametrize("baud, stop", SETTINGS)
def test_detects_every_documented_setting(cli, baud, stop):
    r = cli("zk", "detect", "-p", f"sim://zk?baud={baud}&stop_bits={stop}&speed=10", "-f", "json")
    assert r.exit_code == 0, r
    rec = json.loads(r.stdout)
    assert (rec["found"], rec["baud"], rec["stop_bits"]) == (True, baud, stop)
    assert (rec["protocol_version"], rec["status_rate_hz"]) == (6, 20)
    verdicts = {(a["baud"], a["stop_bits"]): a["verdict"] for a in rec["tried"]}
    assert verdicts[(baud, 1)] == "status frames"          # 1 stop bit reads either sender
    assert verdicts[(baud, 2)] == ("status frames" if stop == 2 else "garbage")
    assert all(v != "status frames" for (b, _), v in verdicts.items() if b != baud)
    assert rec["elapsed_s"] <= rec["budget_s"] + D.VERSION_WAIT_S


def test_version_and_rate_come_from_status_id_6(cli):
    r = cli("zk", "detect", "-p", "sim://zk?baud=19200&protocol_version=4&rate=50&speed=5", "-f", "json")
    rec = json.loads(r.stdout)
    assert (rec["baud"], rec["protocol_version"], rec["status_rate_hz"]) == (19200, 4, 50)


def test_nothing_is_transmitted_unless_probe():
    for probe, expect in ((False, 0), (True, 1)):
        ser = open_port("sim://zk?baud=9600&speed=10", 115200, timeout=0.02)
        try:
            result = D.detect(ser, probe=probe)
            assert result.found and result.baud == 9600
            heard = list(ser.device.received)
        finally:
            close_port(ser)
        assert (len(heard) > 0) == bool(expect)
        assert all(rec["command"] == "keepalive" for rec in heard)


def test_a_silent_ecu_is_exit_3_with_what_was_tried(cli):
    r = cli("zk", "detect", "-p", "sim://zk?silent_after=0", "-b", "115200,9600", "--window", "0.1")
    assert r.exit_code == 3 and r.stdout.strip() != ""
    rec = json.loads(r.stdout)
    assert rec["found"] is False and [(a["baud"], a["verdict"]) for a in rec["tried"]] == [
        (115200, "silent"), (9600, "silent")]
    assert "no ZK status frames on sim://zk?silent_after=0 at any setting tried" in r.stderr
    assert "115200/1 silent, 9600/1 silent" in r.stderr


def test_the_budget_bounds_the_search(cli):
    r = cli("zk", "detect", "-p", "sim://zk?silent_after=0", "--budget", "0.3", "--window", "0.2")
    rec = json.loads(r.stdout)
    assert r.exit_code == 3 and rec["elapsed_s"] < 1.0 and len(rec["tried"]) <= 2
    assert "out of time budget" in r.stderr


def test_monitor_and_check_baud_auto_detect_then_run(cli):
    r = cli("zk", "monitor", "-p", "sim://zk?baud=4800&stop_bits=2&speed=10", "--baud", "auto", "--count", "5",
            "-f", "jsonl")
    assert r.exit_code == 0, r
    assert len(r.stdout.splitlines()) == 5
    assert "detected 4800 baud, 2 stop bits, protocol version 6, 20 Hz" in r.stderr
    r = cli("zk", "check", "-p", "sim://zk?baud=9600&speed=10", "--baud", "auto", "--count", "12",
            "--limit", "power_voltage_v>=7.4")
    assert r.exit_code == 0 and json.loads(r.stdout)["verdict"] == "pass", r
    assert "detected 9600 baud, 1 stop bit" in r.stderr


@pytest.mark.parametrize("args, needle", [
    (["zk", "detect", "-p", "sim://zk", "-b", "1234"], "baud: '1234' is not a baud rate of the ZK document"),
    (["zk", "detect", "-p", "sim://zk", "--stop-bits", "3"], "'--stop-bits'"),
    (["zk", "monitor", "-p", "sim://zk", "--stop-bits", "3"], "'--stop-bits'"),
    (["zk", "send", "keepalive", "-n", "--stop-bits", "3"], "'--stop-bits'"),
    (["zap", "echo", "-n", "--stop-bits", "0"], "'--stop-bits'"),
    (["zk", "send", "keepalive", "-n", "--baud", "auto"], "only 'zk monitor', 'zk check' and 'zk detect'"),
    (["zk", "profile", "--example", "--baud", "auto"], "only 'zk monitor', 'zk check' and 'zk detect'"),
    (["zap", "echo", "--sim", "--baud", "auto"], "'--baud': 'auto' is not allowed"),
    (["zk", "monitor", "--replay", "README.md", "--baud", "auto"], "auto makes no sense with --replay"),
])
def test_bad_line_settings_exit_2_before_anything_opens(cli, args, needle):
    r = cli(*args)
    assert r.exit_code == 2 and r.stdout == "", r
    assert needle in r.stderr


def test_a_host_at_the_wrong_setting_reads_garbage_not_frames(cli):
    r = cli("zk", "monitor", "-p", "sim://zk?baud=9600&speed=10", "-b", "19200", "--count", "3",
            "--timeout", "0.5", "-f", "jsonl")
    assert r.exit_code == 3 and r.stdout == ""
    r = cli("zk", "monitor", "-p", "sim://zk?baud=9600&stop_bits=1&speed=10", "-b", "9600", "--stop-bits", "2",
            "--count", "3", "--timeout", "0.5", "-f", "jsonl")
    assert r.exit_code == 3 and r.stdout == ""


def test_stop_bits_lengthen_every_wire_time():
    from zkzap.link.port import wire_time
    from zkzap.link.zap_bus import ZapBus

    assert wire_time(10, 9600, 2) == pytest.approx(wire_time(10, 9600, 1) * 11 / 10)
    ser1 = open_port("loop://", 9600, stop_bits=1)
    ser2 = open_port("loop://", 9600, stop_bits=2)
    try:
        t1 = ZapBus(ser1, margin=0).reply_timeout(9, 9)
        t2 = ZapBus(ser2, margin=0).reply_timeout(9, 9)
    finally:
        close_port(ser1)
        close_port(ser2)
    assert t2 - t1 == pytest.approx(18 / 9600, rel=1e-6)


def test_a_line_too_slow_for_the_rates_is_said(cli):
    r = cli("zk", "monitor", "-p", "sim://zk?baud=2400&rate=100&speed=5", "-b", "2400", "--count", "12",
            "-f", "jsonl")
    assert r.exit_code == 0, r
    assert "status rate (100 Hz): 100 frames/s of 7 bytes need 7,000 baud at 8N1" in r.stderr
    r = cli("zk", "send", "keepalive", "--for", "0.3", "--rate", "200", "-b", "2400", "-p", "sim://zk?speed=5",
            "-f", "jsonl")
    assert "control rate: 200 frames/s of 4 bytes need 8,000 baud at 8N1" in r.stderr
