"""The stand's alarm list and start interlock (zkzap.api.alarms): latching, acknowledgement,
the restart rule after a trip, setpoint 0, and the hung- and hot-start watches, on records and
through a session on the simulator."""

from __future__ import annotations

import pytest

from zkzap.api.alarms import Alarms, StartAlarm, StartRefused
from zkzap.api.expr import parse
from zkzap.api.session import Session
from zkzap.api.telemetry import Telemetry
from zkzap.codec import zk
from zkzap.codec.permissions import Permission
from zkzap.link.zk_port import ZkLink
from zkzap.link.zk_sources import LiveSource

RUN30 = zk.encode_control("control", sw="run", throttle_pct=30)[0]


def id1(state, egt, rpm=0):
    return {"id": 1, "engine_state": state, "engine_state_name": zk.ENGINE_STATES[state], "egt_c": egt, "rpm": rpm}


def test_a_violated_limit_latches_until_acknowledged_and_a_start_waits_for_rest_and_cool():
    cond = parse("egt_c<=650,warn=620", {"egt_c"})
    a = Alarms([cond])
    a.observe(1.0, dict(id1(11, 630, 100000), warnings=[cond.text]))
    assert [x.level for x in a.entries] == ["warning"] and a.refusal() is None       # a warning latches nothing
    a.observe(1.5, dict(id1(11, 663, 100000), limit=[cond.text]))
    assert a.entries[-1].latched and a.entries[-1].value == 663 and not a.entries[0].active
    a.observe(1.6, {"id": 2, "power_voltage_v": 12.0})           # a frame without the field says nothing
    assert a.entries[-1].active
    assert "alarm latched: limit egt_c<=650,warn=620 violated: egt_c=663" in a.refusal()
    with pytest.raises(StartRefused):
        a.check_start()
    assert [x.id for x in a.acknowledge("bench")] == [2]
    d = a.to_list()[0]
    assert d["acked_by"] == "bench" and d["acked_at"].endswith("Z") and not d["latched"]
    a.observe(2.0, id1(12, 420, 20000))                          # cooling: still hot
    assert "not back at rest and cool" in a.refusal() and "cooling, EGT 420" in a.refusal()
    a.observe(9.0, id1(1, 140, 0))                               # standby, rotor stopped, below 150 degC
    assert "setpoint 0 (asked 30)" in a.refusal(setpoint=30)
    assert a.refusal(setpoint=0) is None
    a.started()
    assert a.refusal(setpoint=30) is None


def test_the_trip_of_a_session_is_not_listed_twice():
    cond = parse("egt_c<=650", {"egt_c"})
    a = Alarms([cond])
    a.observe(1.0, dict(id1(11, 700), limit=[cond.text]))
    a.trip("limit", "limit violated: egt_c=700 at t=1.00 s (egt_c<=650); sent standby, throttle 0", limit=cond.text)
    assert len(a.entries) == 1
    a.trip("abort", "abort from page 1; sent standby, throttle 0")
    assert len(a.latched) == 2


def test_hung_and_hot_starts():
    a = Alarms(hung_start_s=30, hot_start_egt_c=850)
    a.observe(0.0, id1(3, 100))
    a.observe(20.0, id1(4, 870))                                 # preheat above 850 degC
    assert isinstance(a.tripped, StartAlarm) and "hot start: EGT 870" in str(a.tripped)
    a.tripped = None
    a.observe(31.0, id1(5, 600))
    assert "hung start" in str(a.tripped) and [x.kind for x in a.entries] == ["hot-start", "hung-start"]
    a.observe(40.0, id1(5, 600))
    assert len(a.entries) == 2                                   # once per start
    b = Alarms(hung_start_s=0, hot_start_egt_c=0)                # not watched
    for t in range(0, 200, 10):
        b.observe(float(t), id1(4, 900))
    assert b.entries == [] and b.tripped is None


@pytest.mark.parametrize("settings,kind", [({"hung_start_s": 2.0}, "hung start"),
                                           ({"hot_start_egt_c": 300.0}, "hot start")])
def test_a_session_that_starts_the_engine_ends_a_hung_or_hot_start_with_the_abort(settings, kind):
    link = ZkLink.open("sim://zk?speed=20", 115200, allow=Permission.ENGINE)
    src = LiveSource(link)
    tel = Telemetry(None, None, False, wall0=src.wall0)
    out = []
    alarms = Alarms(**settings)
    outcome = Session(src, tel, out.append, control=lambda t: RUN30, duration=60, alarms=alarms).run()
    ecu = link.device
    link.close()
    assert outcome.reason == "alarm" and outcome.exit_code == 5 and kind in str(outcome.error)
    assert outcome.aborted == "standby" and list(ecu.received)[-1]["state"] == "standby"
    assert [r["kind"] for r in out].count("trip") == 1 and out[-1]["kind"] == "rundown"
    assert alarms.latched and kind in alarms.latched[0].text and len(alarms.latched) == 1
    # the next start of the stand is refused
    link = ZkLink.open("sim://zk?speed=20", 115200, allow=Permission.ENGINE)
    src = LiveSource(link)
    outcome = Session(src, Telemetry(None, None, False, wall0=src.wall0), out.append, control=lambda t: RUN30,
                      duration=1, alarms=alarms).run()
    sent = list(link.device.received)
    link.close()
    assert outcome.reason == "refused" and isinstance(outcome.error, StartRefused) and outcome.exit_code == 5
    assert not any(r["command"] == "control" for r in sent)


@pytest.mark.parametrize("settings,kind", [({"hung_start_s": 2.0}, "hung start"),
                                           ({"hot_start_egt_c": 300.0}, "hot start")])
def test_the_start_watches_see_the_ecu_whatever_the_records_hold(settings, kind):
    """--ids 2,3 writes no record of status ID 1 (the engine state and EGT): the watches see every
    decoded frame, not the records."""
    link = ZkLink.open("sim://zk?speed=20", 115200, allow=Permission.ENGINE)
    src = LiveSource(link)
    tel = Telemetry(None, {2, 3}, False, wall0=src.wall0)
    out = []
    alarms = Alarms(**settings)
    outcome = Session(src, tel, out.append, control=lambda t: RUN30, duration=60, alarms=alarms).run()
    link.close()
    assert outcome.reason == "alarm" and kind in str(outcome.error) and outcome.aborted == "standby"
    assert {r["id"] for r in out if r.get("kind") not in ("trip", "rundown")} <= {2, 3}
    assert tel.on_frame is None                      # the session's watch is not left on the telemetry
