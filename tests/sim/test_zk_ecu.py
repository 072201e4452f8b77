"""The ECU simulator driven directly with model times: stream, engine model, commands, faults."""

import pytest

from zkzap.codec import zk
from zkzap.codec.framing import ZkFramer
from zkzap.sim import make_device
from zkzap.sim import zk_ecu
from zkzap.sim.zk_ecu import LOSS_OF_SIGNAL_S, UNLOCK_S, ZkEcu, from_options


class Bench:
    """A host on the ECU's line: sends frames at model times, decodes what comes back."""

    def __init__(self, ecu, version=None):
        self.ecu = ecu
        self.t = 0.0
        self.framer = ZkFramer("status")
        self.decoder = zk.ZkDecoder(version)
        self.records = []

    def send(self, name, **values):
        frame = name if isinstance(name, bytes) else zk.encode_control(name, **values)[0]
        self.ecu.receive(frame, self.t)
        return frame

    def run(self, seconds, keep=None, step=0.05):
        """Advance ``seconds``; ``keep`` (a frame) is re-sent every ``step`` like a host at a rate."""
        out = []
        end = self.t + seconds
        while self.t < end - 1e-9:
            self.t = min(self.t + step, end)
            if keep is not None:
                self.ecu.receive(keep, self.t)
            for f in self.framer.feed(self.ecu.poll(self.t)):
                rec = self.decoder.decode(f)
                rec["t"] = self.t
                out.append(rec)
        self.records += out
        return out

    def last(self, sid):
        return next(r for r in reversed(self.records) if r["id"] == sid)

    def start(self, throttle=30.0, seconds=16.0):
        keep = zk.encode_control("control", sw="run", throttle_pct=throttle)[0]
        return keep, self.run(seconds, keep=keep)


def states(records):
    seq = []
    for r in records:
        if r["id"] == 1 and (not seq or seq[-1] != r["engine_state_name"]):
            seq.append(r["engine_state_name"])
    return seq


def test_stream_cycles_ids_at_the_rate_per_frame():
    b = Bench(ZkEcu())
    recs = b.run(0.99)
    assert len(recs) == 20                      # 20 Hz: one frame every 50 ms (t = 0 .. 0.95)
    assert [r["id"] for r in recs] == list(range(1, 11)) * 2
    six = b.last(6)
    assert six["protocol_version"] == 6 and six["status_rate_hz"] == 20
    assert six["max_rpm"] == 160000
    assert b.framer.bad == 0 and b.framer.skipped == 0


@pytest.mark.parametrize("version,ids", [(1, 8), (4, 8), (5, 9), (6, 10), (7, 10)])
def test_cycle_length_by_protocol_version(version, ids):
    b = Bench(ZkEcu(protocol_version=version))
    recs = b.run(2.0)
    assert sorted({r["id"] for r in recs}) == list(range(1, ids + 1))
    assert b.last(6)["protocol_version"] == version


@pytest.mark.parametrize("action,rate", [("rate-100hz", 100), ("rate-50hz", 50), ("rate-20hz", 20)])
def test_rate_actions_change_the_stream(action, rate):
    b = Bench(ZkEcu(rate=50 if rate != 50 else 20))
    b.run(0.5)
    b.send("action", param=action)
    recs = b.run(2.0)
    assert abs(len(recs) - 2 * rate) <= 1
    assert b.last(6)["status_rate_hz"] == rate


def test_start_sequence_reaches_running_through_the_appendix_states():
    b = Bench(ZkEcu())
    b.run(0.5)
    _, recs = b.start(30.0, 16.0)
    assert states(recs) == ["ignition", "preheat", "fuel-ramp", "running"]
    first_running = next(r["t"] for r in recs if r["id"] == 1 and r["engine_state_name"] == "running")
    assert 12.0 <= first_running - 0.5 <= 12.6
    assert b.last(8)["startup_time_s"] == pytest.approx(12.0, abs=0.1)
    one = b.last(1)
    assert one["sw_state_name"] == "run" and one["error_code"] == 0
    assert 400 < one["egt_c"] < 800


def test_rpm_follows_throttle_with_a_lag():
    ecu = ZkEcu()
    b = Bench(ecu)
    b.start(30.0, 20.0)
    assert b.last(1)["rpm"] == pytest.approx(40000 + 0.3 * 120000, rel=0.01)
    keep = zk.encode_control("control", sw="run", throttle_pct=80)[0]
    early = b.run(0.5, keep=keep)
    assert 76000 < early[-1]["rpm"] < 0.9 * 136000          # on its way, not there yet
    rpms = [r["rpm"] for r in b.run(8.0, keep=keep)]
    assert rpms == sorted(rpms)                              # a first-order lag does not overshoot
    assert rpms[-1] == pytest.approx(136000, rel=0.01)
    assert b.last(3)["throttle_pct"] == 80
    assert b.last(7)["fuel_flow_l_min"] > 0.3
    assert b.last(4)["thrust_kg"] > 8


def test_accel_curve_changes_the_lag():
    def spool(curve):
        b = Bench(ZkEcu())
        b.send("unlock")
        b.send("accel-curve", accel_curve=curve)
        b.start(0.0, 20.0)
        keep = zk.encode_control("control", sw="run", throttle_pct=100)[0]
        return b.run(1.0, keep=keep)[-1]["rpm"]

    assert spool(70) > spool(10) + 20000


def test_rpm_mode_follows_the_id7_target_and_ignores_throttle():
    b = Bench(ZkEcu())
    b.send("mode", sw="run", rpm_factor=3)
    b.send("rpm", target_rpm=99990, rpm_factor=3)
    b.run(25.0, keep=zk.encode_control("control", sw="stop", throttle_pct=100)[0])
    assert b.last(1)["engine_state_name"] == "running"       # ID 6's run overrides ID 1's stop
    assert b.last(1)["rpm"] == pytest.approx(99990, rel=0.005)
    assert b.last(8)["scl"] == 1
    assert b.last(3)["throttle_pct"] == round((99990 - 40000) / 1200)


def test_rpm_mode_needs_protocol_version_4():
    ecu = ZkEcu(protocol_version=3)
    b = Bench(ecu)
    b.send("mode", sw="run", rpm_factor=3)
    b.run(2.0)
    assert ecu.rx_ignored == 1 and b.last(1)["engine_state_name"] == "stop"


def test_standby_cools_a_hot_engine_and_stop_does_not():
    b = Bench(ZkEcu())
    b.start(50.0, 18.0)
    recs = b.run(30.0, keep=zk.encode_control("control", sw="standby")[0])
    assert states(recs) == ["cooling", "standby"]
    cool = [r for r in recs if r["id"] == 1 and r["engine_state_name"] == "cooling"]
    assert cool and all(r["rpm"] > 0 for r in cool[5:])       # the starter spins it
    assert b.last(1)["egt_c"] <= 100 and b.last(1)["rpm"] == 0

    b2 = Bench(ZkEcu())
    b2.start(50.0, 18.0)
    recs = b2.run(10.0, keep=zk.encode_control("control", sw="stop")[0])
    assert states(recs) == ["stop"]
    assert b2.last(1)["egt_c"] > 150                          # no cooling: still hot
    assert b2.last(1)["rpm"] == 0


def test_hot_restart_cools_first():
    b = Bench(ZkEcu())
    b.start(50.0, 18.0)
    b.run(1.0, keep=zk.encode_control("control", sw="stop")[0])
    _, recs = b.start(20.0, 30.0)
    assert states(recs)[:3] == ["restart", "ignition", "preheat"]


def test_settings_need_unlock_first_and_show_in_status_5():
    ecu = ZkEcu()
    b = Bench(ecu)
    b.send("ignition-voltage", ignition_voltage_v=3.2)
    b.send("accel-curve", accel_curve=60)
    b.run(1.0)
    five = b.last(5)
    assert five["ignition_pump_voltage_v"] == 1.2 and five["curve_inc"] == 40
    assert ecu.rx_ignored == 2
    b.send("unlock")
    b.send("ignition-voltage", ignition_voltage_v=3.2)
    b.send("accel-curve", accel_curve=60)
    b.run(1.0)
    five = b.last(5)
    assert five["ignition_pump_voltage_v"] == 3.2 and five["curve_inc"] == 60
    b.run(UNLOCK_S)
    b.send("accel-curve", accel_curve=20)                    # the unlock has expired
    b.run(1.0)
    assert b.last(5)["curve_inc"] == 60


@pytest.mark.parametrize("action,state", [("test-glowplug", "test-glowplug"), ("test-main-valve", "test-main-valve"),
                                          ("test-ignition-valve", "test-ignition-valve"), ("test-pump", "test-pump"),
                                          ("test-starter", "test-starter"), ("drain-oil", "fuel-exhaust-air")])
def test_test_actions_show_their_state_briefly(action, state):
    b = Bench(ZkEcu())
    b.run(0.5)
    frame = zk.encode_control("action", param=action)[0]
    recs = b.run(8.0, keep=frame)                             # repeated frame after frame: runs once
    assert states(recs) == [state, "stop"]
    shown = [r["t"] for r in recs if r["id"] == 1 and r["engine_state_name"] == state]
    assert zk_ecu.TEST_S[zk_ecu.STATE[state]] - 0.6 <= shown[-1] - shown[0] <= 5.5


def test_test_actions_are_ignored_while_running():
    ecu = ZkEcu()
    b = Bench(ecu)
    keep, _ = b.start(30.0, 16.0)
    b.send("action", param="test-starter")
    assert states(b.run(2.0, keep=keep)) == ["running"]
    assert ecu.rx_ignored == 1


def test_fuel_actions_pump_reset_and_thrust_zero():
    ecu = ZkEcu()
    b = Bench(ecu)
    b.send("action", param="pump-on")
    b.run(1.0)
    assert b.last(7)["fuel_flow_l_min"] > 0 and b.last(2)["pump_voltage_v"] > 0
    b.send("action", param="pump-off")
    b.run(1.0)
    assert b.last(7)["fuel_flow_l_min"] == 0 and b.last(10)["fuel_pump_rpm"] == 0
    b.start(100.0, 60.0)
    assert b.last(7)["fuel_used_l"] >= 0.2
    b.send("action", param="reset-fuel")
    b.run(0.5)
    assert b.last(7)["fuel_used_l"] == 0.0
    b.run(30.0, keep=zk.encode_control("control", sw="standby")[0])
    assert b.last(4)["thrust_kg"] == 0.2                      # the sensor's offset
    b.send("action", param="zero-thrust")
    b.run(0.5)
    assert b.last(4)["thrust_kg"] == 0.0


def test_actions_newer_than_the_ecu_are_ignored():
    ecu = ZkEcu(protocol_version=4)
    b = Bench(ecu)
    b.send("action", param="pump-on")                         # needs version 5
    b.run(1.0)
    assert ecu.rx_ignored == 1 and b.last(7)["fuel_flow_l_min"] == 0


def test_air_pressure_and_esr():
    b = Bench(ZkEcu(esr=True))
    b.run(0.5)
    assert b.last(8)["esr"] == 1 and b.last(3)["pressure_pa"] == 101300
    b.send("pressure", pressure_hpa=950)
    b.run(0.5)
    assert b.last(3)["pressure_pa"] == 95000 and b.last(8)["esr"] == 0


def test_voltage_units_follow_the_protocol_version():
    for version, raw in ((3, 120), (4, 60)):
        ecu = ZkEcu(protocol_version=version)
        frame = ecu.status_frame(2)
        assert frame[4] == raw                                 # 12.0 V in 0.1 V or 0.2 V units
        assert zk.decode_status(frame, version)["power_voltage_v"] == 12.0


def test_bad_crc_and_garbage_are_ignored():
    ecu = ZkEcu()
    b = Bench(ecu)
    good = zk.encode_control("control", sw="run", throttle_pct=30)[0]
    bad = good[:3] + bytes((good[3] ^ 0xFF,))
    for _ in range(40):
        ecu.receive(b"\x00\x12" + bad + b"\xff\x1d", b.t)
        b.run(0.05)
    assert states(b.records) == ["stop"]
    assert ecu.rx_bad >= 40 and not ecu.received
    ecu.receive(good, b.t)
    b.run(1.0)
    assert b.last(1)["engine_state_name"] == "ignition"


def test_loss_of_control_signal_below_version_5():
    ecu = ZkEcu(protocol_version=4)
    b = Bench(ecu)
    keep, _ = b.start(30.0, 16.0)
    assert b.last(1)["engine_state_name"] == "running"
    recs = b.run(LOSS_OF_SIGNAL_S + 1.0)                      # the host falls silent
    ones = [r for r in recs if r["id"] == 1]
    assert ones[0]["error_code"] == 0
    assert ones[-1]["error_code"] == 13 and ones[-1]["error_name"] == "loss-of-control-signal"
    assert ones[-1]["engine_state_name"] in ("cooling", "stop")
    # still latched while the host keeps asking to run; stop/standby clears it
    assert b.run(2.0, keep=keep)[-1]["rpm"] < 20000 and b.last(1)["error_code"] == 13
    b.run(1.0, keep=zk.encode_control("control", sw="standby")[0])
    assert b.last(1)["error_code"] == 0


def test_version_5_keeps_running_when_the_host_falls_silent():
    b = Bench(ZkEcu(protocol_version=5))
    b.start(30.0, 16.0)
    b.run(5.0)
    assert b.last(1)["engine_state_name"] == "running" and b.last(1)["error_code"] == 0


def test_keepalive_prevents_loss_of_signal():
    b = Bench(ZkEcu(protocol_version=3))
    b.start(30.0, 16.0)
    b.send("control", sw="run", throttle_pct=30)
    b.run(5.0, keep=zk.encode_control("keepalive")[0])
    assert b.last(1)["engine_state_name"] == "running" and b.last(1)["error_code"] == 0


def test_injected_error_stops_the_engine_until_rearmed():
    ecu = from_options(error="egt-high", error_after="14")
    b = Bench(ecu)
    keep, recs = b.start(30.0, 20.0)
    assert "running" in states(recs)
    assert b.last(1)["error_code"] == 8 and b.last(1)["engine_state_name"] in ("cooling", "stop")
    b.run(20.0, keep=keep)
    assert b.last(1)["engine_state_name"] == "stop"          # no restart while the error is latched
    b.send("control", sw="stop")
    _, recs = b.start(30.0, 5.0)
    assert b.last(1)["error_code"] == 0 and "ignition" in states(recs)


def test_pwm_hands_control_to_an_idle_input():
    b = Bench(ZkEcu())
    b.start(30.0, 16.0)
    recs = b.run(3.0, keep=zk.encode_control("control", sw="pwm")[0])
    assert recs[-1]["id"] and b.last(1)["engine_state_name"] == "stop"
    assert b.last(1)["sw_state_name"] == "stop"


def test_fault_injection_corrupt_and_silent():
    ecu = from_options(corrupt_every="5", silent_after="2")
    b = Bench(ecu)
    recs = b.run(3.0)
    assert len(recs) == 32 and b.framer.bad == 8              # 40 sent in 2 s, every 5th damaged
    assert not b.run(1.0)
    ecu.set_silent(False)
    ecu.set_corrupt_every(0)
    assert len(b.run(1.0)) == 20
    ecu.inject_error(17)
    b.run(0.5)
    assert b.last(1)["error_name"] == "current-overload"


def test_wrong_baud_is_not_heard():
    ecu = from_options(baud="9600")
    frame = zk.encode_control("control", sw="run")[0]
    ecu.receive(frame, 0.1, 115200)
    assert not ecu.received and ecu.rx_wrong_baud == 4
    ecu.receive(frame, 0.2, 9600)
    ecu.receive(frame, 0.3, None)                            # a socket: baud unknown
    assert len(ecu.received) == 2


def test_long_pause_is_a_bounded_burst():
    ecu = ZkEcu(rate=100)
    assert ecu.next_wakeup(0.0) == 0.0
    data = ecu.poll(600.0)
    assert len(data) == zk_ecu.MAX_BURST * 7
    assert ecu.next_wakeup(600.0) == pytest.approx(600.01)


def test_from_options_strings_none_and_unknown():
    ecu = make_device("zk", protocol_version="4", speed="10", rate="50", max_rpm="120000", idle_rpm=None,
                      esr="true", error=None)
    assert (ecu.version, ecu.rate, ecu.max_rpm, ecu.esr) == (4, 50, 120000.0, True)
    with pytest.raises(ValueError, match="unknown options bogus, colour"):
        from_options(bogus="1", colour="red")
    with pytest.raises(ValueError, match="rate: 30 is not a status rate"):
        from_options(rate="30")
    with pytest.raises(ValueError, match="protocol_version: 'x' is not an integer"):
        from_options(protocol_version="x")
    with pytest.raises(ValueError, match="error=melted: not an ECU error code or name"):
        from_options(error="melted")
    with pytest.raises(ValueError, match="esr"):
        from_options(esr="maybe")


@pytest.mark.parametrize("host_baud,clean", [(115200, False), (19200, False), (9600, True), (None, True)],
                         ids=["other-baud", "half-speed", "same-baud", "socket"])
def test_a_host_at_another_baud_reads_garbage_never_a_frame(host_baud, clean):
    from zkzap.codec.framing import ZkFramer

    ecu = from_options(baud="9600")
    sent = ecu.poll(1.0)
    heard = ecu.line.to_host(sent, host_baud, 1)       # what the pty and sim:// transports deliver
    frames = ZkFramer("status").feed(heard)
    if clean:
        assert heard == sent and len(frames) == len(sent) // 7
    else:
        assert heard != sent and frames == []


def test_zk_monitor_at_the_wrong_baud_hears_nothing(cli):
    r = cli("zk", "monitor", "-p", "sim://zk?speed=10&baud=9600", "-b", "115200", "--count", "3",
            "--timeout", "0.3")
    assert r.exit_code == 3 and r.stdout == ""
    assert "no status frame" in r.stderr
