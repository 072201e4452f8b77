"""The MAVLink bridge against a pymavlink receiver over UDP: EFI_STATUS values equal the
simulator's (in MAVLink's units), HEARTBEAT, NAMED_VALUE_FLOAT, STATUSTEXT, IDs, and both
directions of a UDP link (udpout to a listening ground station, udpin answered to whoever calls)."""

from __future__ import annotations

import json
import math
import os
import struct
import threading
import time

import pytest

from zkzap.codec import zk

os.environ.setdefault("MAVLINK20", "1")
mavutil = pytest.importorskip("pymavlink.mavutil")

from zkzap.io.bridges import mavlink as bridge  # noqa: E402


def f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


class Receiver:
    """A ground station: collects every MAVLink message arriving on its connection."""

    def __init__(self, url, heartbeat=False):
        self.conn = mavutil.mavlink_connection(url, dialect="common", source_system=255, source_component=190)
        self.messages = []
        self.heartbeat = heartbeat
        self.empty = 0                     # how many reads found nothing waiting
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    @property
    def port(self):
        return self.conn.port.getsockname()[1]

    def _run(self):
        last_hb = 0.0
        while not self._stop.is_set():
            if self.heartbeat and time.monotonic() - last_hb > 0.2:
                self.conn.mav.heartbeat_send(6, 8, 0, 0, 0)        # a GCS says hello
                last_hb = time.monotonic()
            m = self.conn.recv_match(blocking=True, timeout=0.05)
            if m is None:
                self.empty += 1
            elif m.get_type() != "BAD_DATA":
                self.messages.append(m)

    def drained(self, timeout=30):
        """Wait until every datagram sent so far has been read (for a sender that has ended: two
        reads that began after this call found nothing waiting), however slow the thread is."""
        seen = self.empty
        deadline = time.monotonic() + timeout
        while self.empty < seen + 2:
            assert time.monotonic() < deadline, "the receiver never found its socket empty"
            time.sleep(0.01)

    def close(self):
        self._stop.set()
        self._thread.join(5)
        self.conn.close()

    def of(self, kind):
        return [m for m in self.messages if m.get_type() == kind]


@pytest.fixture
def gcs():
    made = []

    def make(url="udpin:127.0.0.1:0", heartbeat=False):
        r = Receiver(url, heartbeat)
        made.append(r)
        return r

    yield make
    for r in made:
        r.close()


def efi_states(records):
    """Every EFI_STATUS the records can give: the mapped values after each record, as float32."""
    latest, states = {}, set()
    for rec in records:
        latest.update(rec)
        vals = []
        for field, (key, factor, _) in bridge.EFI_FIELDS.items():
            v = latest.get(key)
            if v is None:
                break
            vals.append(f32(v * factor))
        else:
            states.add(tuple(vals))
    return states


def test_every_numeric_status_field_has_a_place():
    named = bridge.named_values()
    efi_keys = {key for key, _, _ in bridge.EFI_FIELDS.values()}
    for s in zk.STATUS:
        for f in s.fields:
            assert f.key in efi_keys or f.key in named, f.key
    assert all(len(n) <= 10 for n in named.values())
    assert len(set(named.values())) == len(named)
    assert set(bridge.FAST_NAMED) == {"thrust_kg", "engine_state", "pump_voltage_v", "ecu_temp_c"}
    fields = mavutil.mavlink.MAVLink_efi_status_message.fieldnames
    assert set(bridge.EFI_FIELDS) | set(bridge.EFI_UNUSED) | {"health", "ecu_index"} == set(fields)
    units = mavutil.mavlink.MAVLink_efi_status_message.fieldunits_by_name
    for field, (_, _, unit) in bridge.EFI_FIELDS.items():
        assert units.get(field, "rpm") == unit


def test_efi_status_carries_the_simulators_values_in_mavlink_units(cli, gcs, tmp_path):
    rx = gcs()
    out = tmp_path / "run.jsonl"
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "50", "--for", "25", "-p", "sim://zk?speed=10",
            "--mavlink", f"udpout:127.0.0.1:{rx.port}", "--mavlink-rate", "20", "--sysid", "7", "--compid", "200",
            "--ecu-index", "2", "-o", str(out))
    assert r.exit_code == 0, r
    rx.drained()                           # the last datagrams on loopback
    records = [json.loads(x) for x in out.read_text().splitlines()]
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in rx.messages} == {(7, 200)}
    efi = rx.of("EFI_STATUS")
    assert 25 <= len(efi) <= 60, len(efi)                 # 20 Hz for 2.5 s
    states = efi_states(records)
    complete = [m for m in efi if not any(math.isnan(getattr(m, f)) for f in bridge.EFI_FIELDS)]
    assert len(complete) >= len(efi) - 3
    for m in complete:
        assert tuple(getattr(m, f) for f in bridge.EFI_FIELDS) in states
        assert m.health == 1 and m.ecu_index == 2.0
        assert m.engine_load == 0.0 and m.cylinder_head_temperature == 0.0
    running = [m for m in complete if m.rpm > 90000]
    assert running, "the engine reached 50 %"
    m = running[-1]
    assert m.barometric_pressure == pytest.approx(101.3, abs=1e-4)           # Pa -> kPa
    assert m.fuel_flow == pytest.approx(1000 * max(r_["fuel_flow_l_min"] for r_ in records if r_["id"] == 7),
                                        rel=0.2)                           # L/min -> cm^3/min
    assert m.throttle_position == 50.0
    # the rest as NAMED_VALUE_FLOAT, values from the same records
    named = {}
    for nv in rx.of("NAMED_VALUE_FLOAT"):
        named.setdefault(nv.name, set()).add(nv.value)
    names = bridge.named_values()
    for key in bridge.FAST_NAMED:
        seen = {f32(rec[key]) for rec in records if rec.get(key) is not None}
        assert named[names[key]] and named[names[key]] <= seen, key
    assert names["power_voltage_v"] in named and names["fuel_pump_rpm"] in named
    texts = [(t.severity, t.text) for t in rx.of("STATUSTEXT")]
    assert (mavutil.mavlink.MAV_SEVERITY_INFO, "ZK engine: running") in texts
    hb = rx.of("HEARTBEAT")
    assert 2 <= len(hb) <= 5
    assert {(h.type, h.autopilot) for h in hb} == {(mavutil.mavlink.MAV_TYPE_GENERIC,
                                                     mavutil.mavlink.MAV_AUTOPILOT_INVALID)}
    assert hb[-1].system_status == mavutil.mavlink.MAV_STATE_ACTIVE
    assert "mavlink:" in r.stderr and "EFI_STATUS" in r.stderr


def test_an_ecu_error_is_a_critical_statustext_and_unhealthy(cli, gcs):
    rx = gcs()
    # the error 6 model seconds in (0.6 s): a first EFI_STATUS before it even when the host is slow
    # to start; then 1.4 s of error, past a heartbeat
    r = cli("zk", "monitor", "-p", "sim://zk?speed=10&error=egt-high&error_after=6", "--duration", "20",
            "--mavlink", f"udpout:127.0.0.1:{rx.port}", "-f", "jsonl")
    assert r.exit_code == 0, r
    rx.drained()
    code = next(c for c, n in zk.ERRORS.items() if n == "egt-high")
    texts = [(t.severity, t.text) for t in rx.of("STATUSTEXT")]
    assert (mavutil.mavlink.MAV_SEVERITY_CRITICAL, f"ZK ECU error {code}: egt-high") in texts
    efi = rx.of("EFI_STATUS")
    assert efi[0].health == 1 and efi[-1].health == 0
    assert rx.of("HEARTBEAT")[-1].system_status == mavutil.mavlink.MAV_STATE_CRITICAL


def test_udpin_answers_the_ground_station_that_calls(cli, gcs):
    import socket

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    rx = None
    result = {}

    def run():
        result["r"] = cli("zk", "monitor", "-p", "sim://zk?speed=10", "--duration", "25",
                          "--mavlink", f"udpin:127.0.0.1:{port}", "-f", "jsonl")

    t = threading.Thread(target=run)
    t.start()
    rx = gcs(f"udpout:127.0.0.1:{port}", heartbeat=True)     # says hello every 0.2 s until heard
    t.join(30)
    assert result["r"].exit_code == 0, result["r"]
    assert rx.of("EFI_STATUS") and rx.of("HEARTBEAT")


def test_the_manual_mapping_table_is_the_code_mapping():
    page = os.path.join(os.path.dirname(__file__), "..", "..", "..", "docs", "how-to", "telemetry.md")
    with open(page, encoding="utf-8") as f:
        text = f.read()
    table = text.split("<!-- efi-status-mapping -->", 1)[1].strip().split("\n\n", 1)[0].splitlines()[2:]
    rows = {}
    for row in table:
        cells = [c.strip() for c in row.strip("|").split("|")]
        rows[cells[0].strip("`")] = cells
    assert set(rows) == set(bridge.EFI_FIELDS) | {"health", "ecu_index"}
    for field, (key, factor, unit) in bridge.EFI_FIELDS.items():
        assert f"`{key}`" in rows[field][2], field
        assert rows[field][1].replace("³", "^3").replace("°C", "degC") == unit, field
        if factor != 1:
            assert ("× 1000" if factor == 1000 else "÷ 1000") in rows[field][2], field


def test_an_unreachable_tcp_ground_station_is_exit_4_with_nothing_on_stdout(cli):
    import socket

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()                                  # nobody listens there
    r = cli("zk", "monitor", "-p", "/dev/nonexistent-zkzap", "--mavlink", f"tcp:127.0.0.1:{port}")
    assert r.exit_code == 4 and r.stdout == "" and "mavlink: cannot open" in r.stderr, r


def test_profile_sends_mavlink_and_reports_the_bridge_in_its_summary(cli, gcs, tmp_path):
    rx = gcs()
    sched = tmp_path / "s.csv"
    sched.write_text("0,0,stop\n10,0,stop\n")             # model seconds
    summary = tmp_path / "summary.json"
    r = cli("zk", "profile", str(sched), "-p", "sim://zk?speed=10", "--mavlink", f"udpout:127.0.0.1:{rx.port}",
            "-f", "jsonl", "-o", str(tmp_path / "t.jsonl"), "--summary-json", str(summary))
    assert r.exit_code == 0, r
    data = json.loads(summary.read_text())
    b = data["bridges"]["mavlink"]
    assert b["dropped"] == 0 and b["submitted"] >= data["records"] and b["sent"]["EFI_STATUS"] >= 5


def test_a_serial_telemetry_radio_gets_the_same_messages(cli, tmp_path):
    """A serial device (here a pty standing in for the radio) with its baud rate."""
    import select
    import tty

    master, slave = os.openpty()
    tty.setraw(master)
    path = os.ttyname(slave)
    got = bytearray()
    stop = threading.Event()

    def read():
        while not stop.is_set():
            if select.select([master], [], [], 0.05)[0]:
                try:
                    got.extend(os.read(master, 4096))
                except OSError:
                    return

    t = threading.Thread(target=read, daemon=True)
    t.start()
    try:
        r = cli("zk", "monitor", "-p", "sim://zk?speed=10", "--duration", "15", "--mavlink", f"{path},57600",
                "-f", "jsonl")
    finally:
        stop.set()
        t.join(5)
        os.close(slave)
        os.close(master)
    assert r.exit_code == 0, r
    parser = mavutil.mavlink.MAVLink(None)
    parser.robust_parsing = True
    kinds = {m.get_type() for m in parser.parse_buffer(bytes(got)) or []}
    assert {"HEARTBEAT", "EFI_STATUS", "NAMED_VALUE_FLOAT", "STATUSTEXT"} <= kinds, kinds


@pytest.mark.parametrize("error", [0, 3])
def test_no_status_frames_is_warned_one_second_after_the_last_record(error):
    """On the bridge's own clock: the warning is due exactly SILENT_S after the last status record
    was handed over, with or without an ECU error active, and the thread is woken for it."""
    now = [100.0]
    b = bridge.MavlinkBridge("udpout:127.0.0.1:9", clock=lambda: now[0])
    sent = []
    b.m = mavutil.mavlink

    class Mav:
        def __getattr__(self, name):
            return lambda *args, **kw: sent.append((name, args))

    b.mav, b._pump_input = Mav(), lambda: None
    rec = {"kind": "status", "id": 1, "rpm": 50000, "error_code": error, "error_name": "x",
           "engine_state_name": "running"}
    b.submit(rec)
    b.absorb(b.queue.get_nowait())
    now[0] = 100.3
    b.submit({"kind": "control", "id": 1})                # the session's own frames are no status
    wake = b.step(now[0])
    assert min(wake, 101.0) == wake and b.step(100.99) <= 101.0

    def warned():
        return [a for name, a in sent if name == "statustext_send" and b"no status frames" in a[1]]

    assert not warned()
    now[0] = 101.0
    b.step(now[0])
    assert len(warned()) == 1 and warned()[0][0] == mavutil.mavlink.MAV_SEVERITY_WARNING
    b.step(101.5)
    assert len(warned()) == 1 and b.efi_values()["health"] == 0
