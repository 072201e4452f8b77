"""The ZK link through the in-process simulator (sim://): records, control rate, abort, faults,
replay and telemetry rules."""

import os
import signal

import pytest

from zkzap.codec import zk
from zkzap.errors import DeviceError, NoReply, PortError, UsageError
from zkzap.link import zk_link as L

RUN30 = zk.encode_control("control", sw="run", throttle_pct=30)[0]
STANDBY0 = zk.encode_control("control", sw="standby", throttle_pct=0)[0]
STOP0 = zk.encode_control("control", sw="stop", throttle_pct=0)[0]
MODE_NONE = zk.encode_control("mode", sw="none", rpm_factor=0)[0]


def session(url, *, snapshot=False, protocol_version=None, ids=None, **kw):
    link = L.ZkLink.open(url, 115200)
    src = L.LiveSource(link)
    tel = L.Telemetry(protocol_version, ids, snapshot, wall0=src.wall0)
    out = []
    sink = kw.pop("sink", None) or out.append
    s = L.Session(src, tel, sink, **kw)
    return s, tel, out, link


def test_records_from_the_simulator():
    s, tel, out, link = session("sim://zk?speed=10", count=25)
    outcome = s.run()
    link.close()
    assert outcome.reason == "count" and outcome.ok and outcome.exit_code == 0
    assert len(out) == 25
    assert {r["id"] for r in out} == set(range(1, 11))
    r = out[0]
    assert r["time"].endswith("Z") and r["time"][10] == "T" and r["kind"] == "status"
    assert zk.check_frame(bytes.fromhex(r["frame"])) == "status"
    ts = [r["t"] for r in out]
    assert ts == sorted(ts) and ts[-1] < 2.0
    assert tel.decoder.version_source == "frame" and tel.decoder.version == 6


def test_control_frames_go_out_at_the_rate():
    # the session runs in the in-process simulator's model time: 1.2 s at 50 Hz (0.6 s of real time)
    s, tel, out, link = session("sim://zk?speed=2", control=lambda t: RUN30, rate=50, duration=1.2)
    outcome = s.run()
    ecu = link.device
    link.close()
    assert outcome.reason == "duration"
    sent = [r for r in ecu.received if r["id"] == 1]
    assert 50 <= len(sent) <= 64                                     # 50 Hz for 1.2 s of model time
    assert outcome.aborted is None                                   # a normal end sends no abort
    assert [r for r in out if r["id"] == 1][-1]["engine_state_name"] != "stop"
    assert 1.1 <= out[-1]["t"] <= 1.3                                 # the last frame before the end (20 Hz)


def test_sigint_stops_between_records_and_sends_the_abort():
    def sink(rec):
        out.append(rec)
        if len(out) == 40:
            os.kill(os.getpid(), signal.SIGINT)

    out = []
    s, tel, _, link = session("sim://zk?speed=20", control=lambda t: RUN30, sink=sink)
    outcome = s.run()
    ecu = link.device
    link.close()
    assert outcome.reason == "interrupted" and outcome.exit_code == 130
    assert outcome.aborted == "standby"
    assert sum(r["command"] == "control" and r["state"] == "run" for r in ecu.received) >= 1
    tail = list(ecu.received)[-4:]
    assert [r["command"] for r in tail] == ["control", "mode", "control", "control"]
    assert tail[0]["state"] == "standby" and tail[0]["throttle_pct"] == 0.0
    assert tail[1]["state"] == "none" and tail[1]["rpm_factor"] == 0
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with pytest.raises(KeyboardInterrupt):
        outcome.raise_for_status()


def test_sigterm_is_terminated_with_stop_abort():
    def sink(rec):
        out.append(rec)
        if len(out) == 10:
            os.kill(os.getpid(), signal.SIGTERM)

    out = []
    s, tel, _, link = session("sim://zk?speed=20", control=lambda t: RUN30, sink=sink, abort="stop")
    outcome = s.run()
    ecu = link.device
    link.close()
    assert outcome.reason == "terminated" and outcome.exit_code == 143 and outcome.aborted == "stop"
    assert list(ecu.received)[-1]["state"] == "stop"


def test_new_ecu_error_ends_the_session_with_the_abort():
    s, tel, out, link = session("sim://zk?speed=20&error=egt-high&error_after=14", control=lambda t: RUN30,
                                stop_on_error=True, duration=20)
    outcome = s.run()
    ecu = link.device
    link.close()
    assert outcome.reason == "ecu-error" and isinstance(outcome.error, DeviceError)
    assert outcome.exit_code == 5 and "ECU error 8 (egt-high" in str(outcome.error)
    assert outcome.aborted == "standby" and list(ecu.received)[-1]["state"] == "standby"
    assert out[-1]["id"] == 1 and out[-1]["error_code"] == 8         # the record that showed it is written
    assert tel.errors and 8 in tel.errors


def test_error_present_at_the_start_is_not_new():
    ecu_url = "sim://zk?speed=20&error=voltage-low&error_after=0"
    notes = []
    s, tel, out, link = session(ecu_url, control=lambda t: RUN30, stop_on_error=True, count=30,
                                notify=notes.append)
    outcome = s.run()
    link.close()
    assert outcome.reason == "count" and list(tel.errors) == [2]
    assert tel.new_error is None and tel.initial_error == (2, "voltage-low")
    assert notes == ["the ECU reports error 2 (voltage-low) from before; an ECU starts again only after stop "
                     "or standby"]
    assert [r["engine_state_name"] for r in out if r["id"] == 1][-1] == "stop"   # latched: no start


def test_no_abort_when_the_session_does_not_control_the_engine():
    def sink(rec):
        out.append(rec)
        if len(out) == 10:
            os.kill(os.getpid(), signal.SIGINT)

    out = []
    keep = zk.encode_control("keepalive")[0]
    s, tel, _, link = session("sim://zk?speed=20", control=lambda t: keep, sink=sink)
    outcome = s.run()
    ecu = link.device
    link.close()
    assert outcome.reason == "interrupted" and outcome.aborted is None
    assert {r["id"] for r in ecu.received} == {0}


def test_silent_ecu_is_no_reply():
    s, tel, out, link = session("sim://zk?speed=20&silent_after=1", silence=0.3)
    outcome = s.run()
    link.close()
    assert outcome.reason == "silence" and isinstance(outcome.error, NoReply) and outcome.exit_code == 3
    assert "fell silent" in str(outcome.error)
    assert len(out) == 20                                              # 1 model second at 20 Hz


def test_no_ecu_at_all_is_no_reply():
    s, tel, out, link = session("loop://", silence=0.2, control=lambda t: RUN30)
    outcome = s.run()
    link.close()
    assert outcome.reason == "silence" and "no status frame from the ECU on loop://" in str(outcome.error)
    assert outcome.aborted == "standby"                                # sent anyway: the TX line may work


class FailingPort:
    """A port that works for a few reads, then fails like an unplugged adapter."""

    def __init__(self, inner, after):
        self.inner, self.after, self.reads, self.written = inner, after, 0, []

    def read(self, n):
        self.reads += 1
        if self.reads > self.after:
            import serial

            raise serial.SerialException("read failed: [Errno 5] Input/output error")
        return self.inner.read(n)

    def write(self, data):
        self.written.append(bytes(data))
        if self.reads > self.after:
            import serial

            raise serial.SerialException("write failed: [Errno 5] Input/output error")
        return self.inner.write(data)

    def flush(self):
        pass

    def close(self):
        self.inner.close()


def test_port_failure_is_port_error_and_abort_is_tried():
    base = L.ZkLink.open("sim://zk?speed=20", 115200)
    port = FailingPort(base.ser, 30)
    src = L.LiveSource(L.ZkLink(port, "/dev/ttyUSB9"))
    tel = L.Telemetry()
    notes = []
    s = L.Session(src, tel, lambda r: None, control=lambda t: RUN30, notify=notes.append)
    outcome = s.run()
    src.close()
    assert outcome.reason == "port" and isinstance(outcome.error, PortError) and outcome.exit_code == 4
    assert str(outcome.error) == "port /dev/ttyUSB9 failed: read failed: Input/output error"
    assert port.written[-1] == STANDBY0 and outcome.aborted == "failed"
    assert notes and "could not send the abort command" in notes[0]


def test_raw_log_and_replay_give_the_same_records(tmp_path):
    raw = tmp_path / "run.bin"
    with open(raw, "wb") as f:
        s, tel, live, link = session("sim://zk?speed=20&corrupt_every=7", count=60)
        link.raw_log = f
        s.run()
        link.close()
    assert raw.stat().st_size >= 60 * 7

    def replay(fast):
        src = L.ReplaySource(str(raw), fast=fast)
        t = L.Telemetry(wall0=src.wall0)
        out = []
        outcome = L.Session(src, t, out.append, count=60).run()
        src.close()
        return outcome, out, src

    strip = ("time", "t", "stale", "stale_ids")
    outcome, fast, src = replay(True)
    assert outcome.reason == "count"
    assert [{k: v for k, v in r.items() if k not in strip} for r in fast] == \
        [{k: v for k, v in r.items() if k not in strip} for r in live]
    assert [r["t"] for r in fast[:3]] == [0.0, 0.05, 0.1]                # rebuilt from the 20 Hz rate
    assert src.framer.bad > 0                                          # the corrupted frames were kept
    outcome, _, _ = replay(True)
    src = L.ReplaySource(str(raw))
    t = L.Telemetry(wall0=src.wall0)
    out = []
    L.Session(src, t, out.append, count=8).run()                         # real time: 8 frames at 20 Hz
    assert 0.3 <= src.now() <= 1.0
    src.close()


def test_replay_to_the_end_and_missing_file(tmp_path):
    raw = tmp_path / "short.bin"
    from zkzap.sim.zk_ecu import ZkEcu

    ecu = ZkEcu()
    raw.write_bytes(ecu.poll(0.99) + b"\x00\xF1\x02")                   # 20 frames and a torn one
    src = L.ReplaySource(str(raw), fast=True)
    out = []
    outcome = L.Session(src, L.Telemetry(), out.append).run()
    assert outcome.reason == "end" and len(out) == 20
    with pytest.raises(UsageError, match="replay: cannot read"):
        L.ReplaySource(str(tmp_path / "none.bin"))


# --- telemetry rules ---------------------------------------------------------------------------

def frames_of(ecu, seconds, start=0.0):
    from zkzap.codec.framing import ZkFramer

    data = ecu.poll(start + seconds)
    return ZkFramer("status").feed(data)


def test_frames_are_held_until_id6_so_voltages_use_the_ecu_unit():
    from zkzap.sim.zk_ecu import ZkEcu

    frames = frames_of(ZkEcu(protocol_version=3), 0.99)
    frames = frames[1:] + frames[:1]                                   # start mid-cycle, at ID 2
    tel = L.Telemetry()
    out = []
    for i, f in enumerate(frames):
        out += tel.feed(i * 0.05, f)
    assert out[0]["id"] == 2 and out[0]["power_voltage_v"] == 12.0    # 0.1 V units, version 3
    assert tel.decoder.version == 3 and tel.version_note is None
    given = L.Telemetry(protocol_version=4)                            # told wrong: decoded at once
    assert given.feed(0.0, frames[0])[0]["power_voltage_v"] == 24.0


def test_without_id6_the_default_version_is_used_and_said():
    from zkzap.sim.zk_ecu import ZkEcu

    frames = [f for f in frames_of(ZkEcu(), 2.0) if f[0] != 0xF6]
    tel = L.Telemetry()
    out = []
    for i, f in enumerate(frames[:5]):
        out += tel.feed(i * 0.05, f)
    assert out == []
    out += tel.flush()
    assert len(out) == 5 and "assume protocol version 4" in tel.version_note
    tel = L.Telemetry()
    for i, f in enumerate(frames[:L.HOLD_FRAMES]):
        out = tel.feed(i * 0.05, f)
    assert len(out) == L.HOLD_FRAMES


def test_snapshot_rows_ids_filter_and_stale_rule():
    from zkzap.sim.zk_ecu import ZkEcu

    frames = frames_of(ZkEcu(), 1.99)
    tel = L.Telemetry(ids=frozenset({1, 6}), snapshot=True)
    rows = []
    for i, f in enumerate(frames):
        rows += tel.feed(i * 0.05, f)
    assert [r["id"] for r in rows] == [1, 6] * 4
    assert list(rows[0]) == L.record_columns(True, frozenset({1, 6}))
    assert rows[-1]["max_rpm"] == 160000 and rows[-1]["egt_c"] == 20 and "pump_voltage_v" not in rows[-1]
    assert not any(r["stale"] for r in rows)
    # IDs 1..10 at 20 Hz: 0.5 s apiece; stale after 3 periods (ID 1 last at 1.5 s, ID 6 at 1.75 s)
    assert tel.stale_ids(2.95) == [] and tel.stale_ids(3.05) == [1] and tel.stale_ids(3.3) == [1, 6]
    h = tel.health(3.3, None)
    assert h["stale"] is True and h["protocol_version"] == 6 and h["version_source"] == "frame"
    assert h["frames"] == 40
    snap = tel.snapshot(3.0)
    assert snap["time_s"] == 3.0 and set(zk.STATUS_KEYS) <= set(snap)


def test_summary_and_error_tracking():
    tel = L.Telemetry(protocol_version=6)

    def one(t, state, code, egt, rpm):
        return tel.feed(t, zk.encode_status(1, 6, rpm=rpm, engine_state=state, error_code=code, egt_c=egt,
                                           sw_state=2))

    one(0.0, 11, 2, 500, 80000)
    assert tel.new_error is None                                       # present at the start
    one(0.5, 11, 0, 650, 90000)
    one(1.0, 12, 8, 700, 50000)
    assert tel.new_error == (8, "egt-high", 1.0)
    tel.feed(1.2, zk.encode_status(7, 6, fuel_flow_l_min=0.2, fuel_used_l=1.0))
    tel.feed(1.7, zk.encode_status(7, 6, fuel_flow_l_min=0.2, fuel_used_l=1.3))
    s = tel.summary()
    assert s["max_rpm"] == 90000 and s["max_egt_c"] == 700 and s["fuel_used_l"] == 0.3
    assert s["states"] == ["running", "cooling"]
    assert [e["code"] for e in s["errors"]] == [2, 8]


# --- helpers -----------------------------------------------------------------------------------

def test_abort_frames_and_engine_control():
    assert L.abort_frames("standby") == [STANDBY0, MODE_NONE, STANDBY0]
    assert L.abort_frames("stop", 3) == [STOP0]
    assert L.abort_frames("none") == []
    assert L.abort_frames("standby", 5, pump=True)[-1] == zk.encode_control("action", param="pump-off")[0]
    with pytest.raises(UsageError):
        L.abort_frames("land")
    yes = [RUN30, STOP0, zk.encode_control("mode", sw="none", rpm_factor=2)[0],
           zk.encode_control("rpm", target_rpm=50000, rpm_factor=2)[0],
           zk.encode_control("action", param="test-starter")[0]]
    no = [zk.encode_control("keepalive")[0], zk.encode_control("control", sw="pwm")[0],
          zk.encode_control("action", param="rate-100hz")[0], zk.encode_control("unlock")[0],
          zk.encode_control("pressure", pressure_hpa=1000)[0], MODE_NONE]
    assert all(map(L.controls_engine, yes)) and not any(map(L.controls_engine, no))


def test_parse_ids():
    assert L.parse_ids("1,2,6") == {1, 2, 6}
    assert L.parse_ids("1-3, 9") == {1, 2, 3, 9}
    for bad, msg in (("0", "out of range"), ("15", "out of range"), ("a", "not an ID"), ("3-1", "empty range"),
                     (",", "no ID given")):
        with pytest.raises(UsageError, match=msg):
            L.parse_ids(bad)


def test_iso_utc():
    assert L.iso_utc(0.5) == "1970-01-01T00:00:00.500Z"
    assert L.iso_utc(1700000000.123) == "2023-11-14T22:13:20.123Z"


def test_replay_keeps_a_frame_held_for_look_ahead_at_the_end(tmp_path):
    """After damage, a framer holds a valid frame until what follows confirms it; at the end of
    a replay that frame comes out of flush() and must not be lost."""
    from zkzap.codec import zk as zkc
    from zkzap.codec.framing import ZkFramer
    from zkzap.link.zk_link import ReplaySource

    good = zkc.status_frame(1, b"\x00\x00\x00\x00\x4c")
    data = good + bytes.fromhex("4cf2f24c4c") + good    # damage with rival heads before the last frame
    framer = ZkFramer("status")
    assert framer.feed(data) == [good]         # the last frame waits for confirmation ...
    assert framer.flush() == [good]            # ... and comes out at the end
    expected = [good, good]
    log = tmp_path / "raw.bin"
    log.write_bytes(data)
    src = ReplaySource(str(log), fast=True)
    got = []
    while True:
        due = src.poll()
        if due is None:
            break
        got += [f for _, f in due]
    assert got == expected
