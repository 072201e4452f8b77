"""zkzap.Ecu against the ECU simulator (model time sped up)."""

from __future__ import annotations

import pytest

from zkzap import Ecu
from zkzap.errors import DeviceError, NoReply, UsageError


def test_status_records_version_aware(zk_sim):
    with Ecu(zk_sim) as ecu:
        recs = list(ecu.status(count=12))
        assert ecu.protocol_version == 6
        assert ecu.telemetry.decoder.version_source == "frame"
    assert len(recs) == 12
    two = next(r for r in recs if r.id == 2)
    assert two.power_voltage_v == 12.0 and two["kind"] == "status"
    with pytest.raises(AttributeError):
        two.egt_c  # noqa: B018


@pytest.mark.zk_sim(speed=60)
def test_hold_runs_the_engine_and_close_aborts(zk_sim):
    with Ecu(zk_sim) as ecu:
        states = [r.engine_state_name for r in ecu.hold("control", 4.0, state="run", throttle_pct=40) if r.id == 1]
        assert ecu.controlling
        assert states[0] == "stop" and states[-1] != "stop"          # the start sequence began
        h = ecu.health
        assert h["frames"] > 50 and h["crc_errors"] == 0 and h["stale_ids"] == []
    last = zk_sim.device.received[-1]
    assert last["command"] == "control" and last["state"] == "standby" and last["throttle_pct"] == 0


@pytest.mark.zk_sim(speed=20)
def test_abandoned_hold_sends_the_abort(zk_sim):
    with Ecu(zk_sim, abort="stop") as ecu:
        for rec in ecu.hold("control", 60, state="run", throttle_pct=30):
            if rec.t > 0.3:
                break
        assert not ecu.controlling               # the generator's close sent the abort
        assert zk_sim.device.received[-1]["state"] == "stop"


def test_send_keepalive_does_not_control(zk_sim):
    with Ecu(zk_sim) as ecu:
        cf = ecu.send("keepalive")
        assert cf.frame == bytes.fromhex("FF000000") and not cf.controls_engine
        assert not ecu.controlling
        with pytest.raises(Exception, match="throttle"):
            ecu.send("control", state="run", throttle_pct=200)


@pytest.mark.zk_sim(speed=20, error="egt-high", error_after=0.5)
def test_new_ecu_error_stops_a_hold(zk_sim):
    with Ecu(zk_sim) as ecu:
        with pytest.raises(DeviceError, match="ECU error"):
            for _ in ecu.hold("control", 30, state="run", throttle_pct=30):
                pass


@pytest.mark.zk_sim(silent_after=0.0)
def test_silent_ecu(zk_sim):
    with Ecu(zk_sim, silence=0.3) as ecu:
        with pytest.raises(NoReply) as e:
            list(ecu.status(count=1))
    assert e.value.timeout == 0.3 and e.value.code == 3


@pytest.mark.zk_sim(speed=20)
def test_run_profile(zk_sim):
    seen = []
    with Ecu(zk_sim) as ecu:
        result = ecu.run_profile("time_s,throttle_pct,state\n0,20,run\n0.3,50\n0.6,0,stop\n", on_record=seen.append)
    assert result.ok and result.records == len(seen) > 0
    assert result.summary["outcome"] == "duration" and result.summary["frames"] >= len(seen)
    with Ecu(zk_sim) as ecu, pytest.raises(UsageError):
        ecu.run_profile([(0, 10)])


def test_bad_abort_kind(zk_sim):
    with pytest.raises(UsageError, match="abort"):
        Ecu(zk_sim, abort="explode")


@pytest.mark.zk_sim(speed=20)
def test_run_profile_reads_a_schedule_file_as_zk_profile_does(zk_sim, tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("time_s,throttle_pct,state\n0,20.04,run\n0.4,0,stop\n", encoding="utf-8")
    for schedule in (path, str(path)):
        with Ecu(zk_sim) as ecu:
            result = ecu.run_profile(schedule)
        assert result.ok and result.summary["schedule_s"] == 0.4 and result.outcome.aborted is None
        assert result.notes == [f"{path}:2: throttle: 20.04 % is not a multiple of 0.1 %; rounded to 20 %"]
    with Ecu(zk_sim) as ecu, pytest.raises(UsageError, match="schedule: cannot read .*none.csv"):
        ecu.run_profile(str(tmp_path / "none.csv"))


@pytest.mark.zk_sim(speed=20)
def test_run_profile_ending_in_run_sends_the_abort(zk_sim):
    with Ecu(zk_sim) as ecu:
        result = ecu.run_profile("0,30\n0.3,30\n")
    assert result.ok and result.outcome.aborted == "standby"
    assert zk_sim.device.received[-1]["state"] == "standby"
