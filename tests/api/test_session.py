"""The ZK session loop through the in-process simulator (sim://): records, control rate, the
abort on signals, ECU errors, silence and port failures."""

import os
import signal

import pytest

from zkzap.api.session import Session, abort_frames, controls_engine
from zkzap.api.telemetry import Telemetry
from zkzap.codec import zk
from zkzap.codec.permissions import Permission
from zkzap.errors import DeviceError, NoReply, PortError, UsageError
from zkzap.link.zk_port import ZkLink
from zkzap.link.zk_sources import LiveSource

RUN30 = zk.encode_control("control", sw="run", throttle_pct=30)[0]
STANDBY0 = zk.encode_control("control", sw="standby", throttle_pct=0)[0]
STOP0 = zk.encode_control("control", sw="stop", throttle_pct=0)[0]
MODE_NONE = zk.encode_control("mode", sw="none", rpm_factor=0)[0]


def session(url, *, snapshot=False, protocol_version=None, ids=None, **kw):
    link = ZkLink.open(url, 115200, allow=Permission.ENGINE)      # the session's behaviour, not consent
    src = LiveSource(link)
    tel = Telemetry(protocol_version, ids, snapshot, wall0=src.wall0)
    out = []
    sink = kw.pop("sink", None) or out.append
    s = Session(src, tel, sink, **kw)
    return s, tel, out, link


def abort_tail(received):
    """The abort's four frames after the last run command, and the frames sent after them (the
    rundown's held state)."""
    got = list(received)
    last_run = max(i for i, r in enumerate(got) if r["command"] == "control" and r["state"] == "run")
    return got[last_run + 1:last_run + 5], got[last_run + 5:]


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
    tail, held = abort_tail(ecu.received)
    assert [r["command"] for r in tail] == ["control", "mode", "control", "control"]
    assert tail[0]["state"] == "standby" and tail[0]["throttle_pct"] == 0.0
    assert tail[1]["state"] == "none" and tail[1]["rpm_factor"] == 0
    # the rundown: standby repeated until the engine is at rest, marked in the records
    assert all(r["command"] == "control" and r["state"] == "standby" and r["throttle_pct"] == 0 for r in held)
    kinds = [r.get("kind") for r in out]
    assert kinds.count("trip") == 1 and kinds[-1] == "rundown" and out[-1]["ended"] == "rest"
    assert outcome.rundown["ended"] == "rest"
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with pytest.raises(KeyboardInterrupt):
        outcome.raise_for_status()


@pytest.mark.parametrize("kind", ["stop", "standby"])
def test_sigterm_is_terminated_with_the_abort_and_nothing_else_goes_after_it(kind):
    def sink(rec):
        out.append(rec)
        if len(out) == 10:
            os.kill(os.getpid(), signal.SIGTERM)

    out = []
    s, tel, _, link = session("sim://zk?speed=20", control=lambda t: RUN30, sink=sink, abort=kind)
    outcome = s.run()
    ecu = link.device
    assert outcome.reason == "terminated" and outcome.exit_code == 143 and outcome.aborted == kind
    assert list(ecu.received)[-1]["state"] == kind
    # once the abort went out, the session sends nothing but its frames
    assert s.sealed == frozenset(abort_frames(kind, tel.decoder.known))
    before = len(ecu.received)
    s._send(RUN30)                                     # a control frame with the old setpoint, late
    s._send(STOP0 if kind == "stop" else STANDBY0)     # the abort's own state still goes
    got = list(ecu.received)[before:]
    link.close()
    assert [(r["state"], r["throttle_pct"]) for r in got] == [(kind, 0.0)]


def test_new_ecu_error_ends_the_session_with_the_abort():
    s, tel, out, link = session("sim://zk?speed=20&error=egt-high&error_after=14", control=lambda t: RUN30,
                                stop_on_error=True, duration=20)
    outcome = s.run()
    ecu = link.device
    link.close()
    assert outcome.reason == "ecu-error" and isinstance(outcome.error, DeviceError)
    assert outcome.exit_code == 5 and "ECU error 8 (egt-high" in str(outcome.error)
    assert outcome.aborted == "standby" and list(ecu.received)[-1]["state"] == "standby"
    trip = next(i for i, r in enumerate(out) if r.get("kind") == "trip")
    assert out[trip - 1]["id"] == 1 and out[trip - 1]["error_code"] == 8    # the record that showed it is written
    assert "ECU error 8" in out[trip]["trip"] and out[trip]["reason"] == "ecu-error"
    assert out[-1]["kind"] == "rundown" and out[-1]["ended"] in ("rest", "max")
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
    base = ZkLink.open("sim://zk?speed=20", 115200)
    port = FailingPort(base.ser, 30)
    src = LiveSource(ZkLink(port, "/dev/ttyUSB9", allow=Permission.ENGINE))
    tel = Telemetry()
    notes = []
    s = Session(src, tel, lambda r: None, control=lambda t: RUN30, notify=notes.append)
    outcome = s.run()
    src.close()
    assert outcome.reason == "port" and isinstance(outcome.error, PortError) and outcome.exit_code == 4
    assert str(outcome.error) == "port /dev/ttyUSB9 failed: read failed: Input/output error"
    assert port.written[-1] == STANDBY0 and outcome.aborted == "failed"
    assert notes and "could not send the abort command" in notes[0]


def test_abort_frames_and_engine_control():
    assert abort_frames("standby") == [STANDBY0, MODE_NONE, STANDBY0]
    assert abort_frames("stop", 3) == [STOP0]
    assert abort_frames("none") == []
    assert abort_frames("standby", 5, pump=True)[-1] == zk.encode_control("action", param="pump-off")[0]
    with pytest.raises(UsageError):
        abort_frames("land")
    yes = [RUN30, STOP0, zk.encode_control("mode", sw="none", rpm_factor=2)[0],
           zk.encode_control("rpm", target_rpm=50000, rpm_factor=2)[0],
           zk.encode_control("action", param="test-starter")[0]]
    no = [zk.encode_control("keepalive")[0], zk.encode_control("control", sw="pwm")[0],
          zk.encode_control("action", param="rate-100hz")[0], zk.encode_control("unlock")[0],
          zk.encode_control("pressure", pressure_hpa=1000)[0], MODE_NONE]
    assert all(map(controls_engine, yes)) and not any(map(controls_engine, no))
