"""``zkzap ports`` against faked pyserial port lists and a fake sysfs / dev tree."""

from __future__ import annotations

import json
import os

import pytest

from zkzap.link import adapters


class FakePort:
    """What pyserial's ListPortInfo offers (the attributes zkzap reads)."""

    def __init__(self, device, description="n/a", vid=None, pid=None, serial_number=None, manufacturer=None,
                 product=None, location=None):
        self.device = device
        self.name = os.path.basename(device)
        self.description = description
        self.vid, self.pid = vid, pid
        self.serial_number = serial_number
        self.manufacturer, self.product, self.location = manufacturer, product, location


@pytest.fixture
def machine(tmp_path, monkeypatch):
    """Three adapters and a built-in UART, with sysfs latency timers and by-id links."""
    dev = tmp_path / "dev"
    dev.mkdir()
    for name in ("ttyUSB0", "ttyUSB1", "ttyUSB2", "ttyS0"):
        (dev / name).write_text("")
    (dev / "ttyUSB2").chmod(0o000)
    sysfs = tmp_path / "sys"
    for name, value in (("ttyUSB0", "16"), ("ttyUSB2", "1")):
        (sysfs / name).mkdir(parents=True)
        (sysfs / name / "latency_timer").write_text(value + "\n")
    by_id = tmp_path / "by-id"
    by_id.mkdir()
    os.symlink(dev / "ttyUSB0", by_id / "usb-FTDI_FT232R_USB_UART_A50285BI-if00-port0")
    ports = [
        FakePort(str(dev / "ttyUSB1"), "USB Serial", 0x1A86, 0x7523, None, None, "USB Serial", "1-1.3"),
        FakePort(str(dev / "ttyUSB0"), "FT232R USB UART", 0x0403, 0x6001, "A50285BI", "FTDI", "FT232R USB UART",
                 "1-1.2:1.0"),
        FakePort(str(dev / "ttyS0")),
        FakePort(str(dev / "ttyUSB2"), "FT230X Basic UART", 0x0403, 0x6015, "DK0AB1CD", "FTDI"),
    ]
    monkeypatch.setattr(adapters, "SYSFS_USB_SERIAL", str(sysfs))
    monkeypatch.setattr(adapters, "DEV_BY_ID", str(by_id))
    monkeypatch.setattr("serial.tools.list_ports.comports", lambda *a, **k: list(ports))
    # port_records' defaults were bound at definition: route them to the fakes
    real = adapters.port_records
    monkeypatch.setattr(adapters, "port_records",
                        lambda comports=None, **kw: real(comports, sysfs=str(sysfs), dev_by_id=str(by_id), **kw))
    return {"dev": dev, "sysfs": sysfs, "by_id": by_id}


def records(cli, *args):
    r = cli("ports", *args)
    assert r.exit_code == 0, r
    return {os.path.basename(x["device"]): x for x in map(json.loads, r.stdout.splitlines())}


def test_every_port_with_its_usb_identity(cli, machine):
    recs = records(cli)
    assert list(recs) == ["ttyS0", "ttyUSB0", "ttyUSB1", "ttyUSB2"]       # sorted by device
    ftdi = recs["ttyUSB0"]
    assert (ftdi["description"], ftdi["vid_pid"], ftdi["serial_number"], ftdi["chip"], ftdi["location"]) == \
        ("FT232R USB UART", "0403:6001", "A50285BI", "FTDI FT232R/FT245R", "1-1.2:1.0")
    assert ftdi["by_id"] == str(machine["by_id"] / "usb-FTDI_FT232R_USB_UART_A50285BI-if00-port0")
    assert recs["ttyUSB1"]["chip"] == "WCH CH340" and recs["ttyUSB1"]["vid_pid"] == "1A86:7523"
    uart = recs["ttyS0"]
    assert (uart["description"], uart["vid_pid"], uart["chip"], uart["hints"]) == (None, None, None, [])


def test_ftdi_latency_timer_hint_says_how_to_set_1_ms(cli, machine):
    ftdi = records(cli)["ttyUSB0"]
    assert ftdi["latency_timer_ms"] == 16
    hint = ftdi["hints"][0]
    assert "FTDI latency timer is 16 ms" in hint
    assert f"echo 1 | sudo tee {machine['sysfs'] / 'ttyUSB0' / 'latency_timer'}" in hint
    assert 'ATTR{latency_timer}="1"' in hint


def test_ftdi_already_at_1_ms_and_ch341_have_no_advice_to_act_on(cli, machine):
    recs = records(cli)
    assert recs["ttyUSB2"]["latency_timer_ms"] == 1
    assert "FTDI latency timer is 1 ms (fastest)" in recs["ttyUSB2"]["hints"]
    ch = recs["ttyUSB1"]
    assert ch["latency_timer_ms"] is None
    assert ch["hints"] == ["CH34x adapter (the chip of IR Robot's own USB adapter): no latency timer to set"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root may open any device, so no permission hint applies")
def test_permission_hint(cli, machine):
    rec = records(cli)["ttyUSB2"]
    assert rec["permission"] is False
    assert any("no read/write permission" in h and "usermod -aG" in h for h in rec["hints"])


def test_permission_hint_text():
    rec = {"name": "ttyUSB3", "vid": None, "device": "/dev/ttyUSB3", "permission": False, "group": "dialout",
           "latency_timer_ms": None}
    assert adapters.hints_for(rec) == [
        "no read/write permission on /dev/ttyUSB3: add yourself to the group 'dialout' "
        "(sudo usermod -aG dialout $USER) and log in again"]


def test_usb_only_and_json_array(cli, machine):
    r = cli("ports", "--usb", "-f", "json")
    data = json.loads(r.stdout)
    assert [os.path.basename(x["device"]) for x in data] == ["ttyUSB0", "ttyUSB1", "ttyUSB2"]
    assert isinstance(data[0]["hints"], list)


def test_csv_joins_hints(cli, machine):
    r = cli("ports", "-f", "csv")
    header, *lines = r.stdout.splitlines()
    assert header.startswith("device,name,description,vid_pid,vid,pid,serial_number")
    assert len(lines) == 4


def test_table_on_a_terminal(cli, machine, monkeypatch):
    monkeypatch.setenv("COLUMNS", "220")
    r = cli("ports", "-f", "table")
    assert "VID:PID" in r.stdout and "0403:6001" in r.stdout and "A50285BI" in r.stdout
    assert "FTDI latency timer is 16 ms" in r.stdout


def test_no_ports(cli, monkeypatch):
    monkeypatch.setattr("serial.tools.list_ports.comports", lambda *a, **k: [])
    r = cli("ports", "-f", "json")
    assert r.exit_code == 0
    assert json.loads(r.stdout) == []
    assert "no serial ports found" in r.stderr


def test_latency_timer_unreadable_outside_linux(tmp_path):
    assert adapters.read_latency_timer("ttyUSB0", str(tmp_path)) is None
    rec = {"name": "ttyUSB0", "vid": adapters.FTDI_VID, "device": "/dev/ttyUSB0", "permission": True,
           "latency_timer_ms": None}
    assert "set its latency timer to 1 ms in the driver settings" in adapters.hints_for(rec, str(tmp_path))[0]
