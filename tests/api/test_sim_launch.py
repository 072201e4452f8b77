"""zkzap.sim: simulators started from Python with typed arguments; the pytest plugin."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from zkzap import Bus, Ecu
from zkzap.errors import NoReply
from zkzap.sim import INSTANCES, start, start_zap, start_zk


@pytest.mark.parametrize("transport", ["inprocess", "pty", "tcp"])
def test_zap_every_transport(transport):
    with start_zap(ids=[3, (4, 115200)], return_mode=2, transport=transport) as sim:
        prefix = {"inprocess": "sim://zap?instance=", "pty": "/dev/", "tcp": "socket://127.0.0.1:"}[transport]
        assert sim.url.startswith(prefix)
        with Bus(sim, return_mode=2) as bus:
            assert bus.store(3, "goal-speed", 700) is not None      # mode 2 acknowledges writes
            assert bus.load(3, "goal-speed") == 700
            if transport != "tcp":                                  # a socket has no baud rate
                assert bus.ping(4) is None                          # it talks at 115200
        assert sim.device.actuator(3).get("goal-speed") == 700
    assert sim.key not in INSTANCES


@pytest.mark.parametrize("transport", ["pty", "tcp"])
def test_zk_server_reaches_another_process(transport):
    with start_zk(speed=10, transport=transport) as sim:
        p = subprocess.run([sys.executable, "-m", "zkzap", "zk", "monitor", "-p", sim.url, "--count", "3",
                            "-f", "jsonl"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert len(p.stdout.splitlines()) == 3


def test_typed_arguments_are_checked():
    with pytest.raises(ValueError, match="protocol_version"):
        start_zk(protocol_version=99)
    with pytest.raises(ValueError, match="baud"):
        start_zap(baud=1234)
    with pytest.raises(ValueError, match="kind"):
        start("can")


def test_faults_typed_and_as_text():
    with start_zap(ids=[1, 2], faults=["2:silent"]) as sim, Bus(sim, retries=0) as bus:
        assert bus.ping(1) is not None and bus.ping(2) is None
        sim.inject(1, "overload")
        assert bus.echo(1, check=False).errors == ["overload"]


def test_fixtures_from_the_plugin(zap_sim, zk_sim):
    """The pytest11 plugin's fixtures: what a user's own test suite gets."""
    with Bus(zap_sim) as bus:
        assert bus[1].present_voltage == 12.0
    with Ecu(zk_sim) as ecu:
        assert next(iter(ecu.status()))["kind"] == "status"


def test_plugin_is_registered_by_entry_point():
    from importlib.metadata import entry_points

    names = {ep.value for ep in entry_points(group="pytest11")}
    assert "zkzap.pytest_plugin" in names


def test_zk_stop_bits_typed_and_checked():
    with pytest.raises(ValueError, match=r"stop_bits: 3; allowed 1, 2"):
        start_zk(stop_bits=3)
    with pytest.raises(ValueError, match=r"stop_bits: '2'; allowed 1, 2"):
        start_zk(stop_bits="2")
    with pytest.raises(ValueError, match=r"stop_bits: True"):
        start_zk(stop_bits=True)
    with start_zk(baud=9600, stop_bits=2) as sim:
        assert sim.device.stop_bits == 2 and sim.device.baud == 9600
    with start_zk() as sim:
        assert sim.device.stop_bits == 1


def test_zk_stop_bits_heard_only_at_the_ecus_setting():
    """An ECU at 9600 8N2 over a pty: a host at 8N2 gets its status frames and is heard; the
    frames of a host at 8N1 (one stop bit short) are misframed by the ECU's UART."""
    with start_zk(baud=9600, stop_bits=2, speed=10, transport="pty") as sim:
        def zk(bits, *args):
            return subprocess.run([sys.executable, "-m", "zkzap", "zk", *args, "-p", sim.url, "-b", "9600",
                                   "--stop-bits", bits], capture_output=True, text=True, timeout=60)
        good = zk("2", "monitor", "--count", "3", "-f", "jsonl")
        assert good.returncode == 0, good.stderr
        assert len(good.stdout.splitlines()) == 3
        assert zk("2", "send", "keepalive").returncode == 0
        with sim.lock:
            assert sim.device.rx_wrong_baud == 0
        assert zk("1", "send", "keepalive").returncode == 0
        deadline = time.monotonic() + 20                  # the server thread reads it when it can
        while sim.device.rx_wrong_baud < 4 and time.monotonic() < deadline:
            time.sleep(0.01)
        with sim.lock:
            assert sim.device.rx_wrong_baud == 4          # the 4-byte frame, misframed


def test_zap_reply_timing_typed_and_checked():
    with start_zap(ids=[1], turnaround=15, gap=1.5) as sim:
        assert sim.device.turnaround == pytest.approx(0.015) and sim.device.gap == pytest.approx(0.0015)
        with Bus(sim) as bus:
            assert bus.ping(1) is not None
            assert bus.load(1, "goal-speed") == 1023
    with start_zap(ids=[1]) as sim:
        assert sim.device.turnaround == pytest.approx(0.002) and sim.device.gap == 0.0
    for bad, message in (({"turnaround": 1001}, r"turnaround: 1001 is out of range; allowed 0\.\.1000 ms"),
                         ({"gap": -1}, r"gap: -1 is out of range; allowed 0\.\.100 ms"),
                         ({"gap": float("nan")}, r"gap: nan is out of range"),
                         ({"turnaround": "soon"}, r"turnaround: 'soon' is not a number"),
                         ({"turnaround": True}, r"turnaround: True is not a number")):
        with pytest.raises(ValueError, match=message):
            start_zap(ids=[1], **bad)


def write_capture(path, protocol, chunks):
    from zkzap.link.pcapng import Writer

    w = Writer(str(path))
    i = w.interface(protocol, "/dev/ttyUSB0", 57600 if protocol == "zap" else 115200)
    for ts, data, direction in chunks:
        w.packet(i, ts, data, direction)
    w.close()


def test_zap_replay_answers_as_recorded(tmp_path):
    from zkzap.codec import zap
    from zkzap.link.pcapng import INBOUND, OUTBOUND

    cap = tmp_path / "field.pcapng"
    volts = zap.load(3, "present-voltage")
    write_capture(cap, "zap", [
        (10.0, volts, OUTBOUND), (10.004, zap.packet(3, 0, bytes([87])), INBOUND),     # 8.7 V in the field
        (10.1, zap.load(3, "present-position"), OUTBOUND),                               # ... and then silence
    ])
    with start_zap(replay=cap) as sim, Bus(sim, retries=0) as bus:
        assert [a.ident for a in sim.device.model.actuators] == [3]   # the IDs that answered
        assert bus[3].present_voltage == 8.7                          # the recorded reply, not the model's
        with pytest.raises(NoReply):
            bus.load(3, "present-position")                           # the recorded silence
        assert bus[3].goal_speed == sim.device.model.actuator(3).get("goal-speed")   # the rest: the model


def test_zk_replay_plays_the_recorded_status_frames(tmp_path):
    from zkzap.codec import zk
    from zkzap.link.pcapng import INBOUND

    cap = tmp_path / "flight.pcapng"
    rpm = [zk.encode_status(1, rpm=r, egt_c=500) for r in (90000, 95000, 100000)]
    write_capture(cap, "zk", [(1.0 + 0.05 * n, f, INBOUND) for n, f in enumerate(rpm)])
    seen = []
    with start_zk(replay=cap, loop=True, speed=10, on_control=seen.append) as sim, Ecu(sim) as ecu:
        got = [rec["rpm"] for rec, _ in zip(ecu.status(), range(6))]
        ecu.send("keepalive")
        for _ in zip(ecu.status(), range(3)):
            pass
    assert got[:3] in ([90000, 95000, 100000], [95000, 100000, 90000], [100000, 90000, 95000])
    assert set(got) == {90000, 95000, 100000}                         # looped
    assert seen and seen[0]["command"] == "keepalive"


def test_replay_arguments_are_checked(tmp_path):
    from zkzap.errors import UsageError

    not_a_capture = tmp_path / "x.pcapng"
    not_a_capture.write_bytes(b"hello")
    with pytest.raises(UsageError):
        start_zap(replay=not_a_capture)
    with pytest.raises(UsageError):
        start_zk(replay=not_a_capture)
    with pytest.raises(ValueError, match="only with replay"):
        start_zk(loop=True)


def test_the_plugin_fixture_replays_a_recording(request, tmp_path):
    from zkzap.codec import zap
    from zkzap.link.pcapng import INBOUND, OUTBOUND

    cap = tmp_path / "field.pcapng"
    write_capture(cap, "zap", [(1.0, zap.echo(7), OUTBOUND), (1.003, zap.packet(7, 0), INBOUND)])
    request.node.add_marker(pytest.mark.zap_sim(replay=str(cap)))
    sim = request.getfixturevalue("zap_sim")
    with Bus(sim) as bus:
        assert bus.ping(7) is not None and bus.ping(1, retries=0) is None   # the recording's ID, not the default 1
