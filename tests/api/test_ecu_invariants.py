"""The session invariants through the public API (:class:`zkzap.Ecu`), as the commands keep them:
a silent ECU never passes, nothing is sent that the ECU's reported limits refuse, a signal at
any moment leaves the engine in standby or stop, and a session's times are on one clock."""

from __future__ import annotations

import os
import random
import signal
import threading

import pytest

from zkzap import Ecu
from zkzap.api.prestart import EcuLimitError
from zkzap.errors import NoReply
from zkzap.sim import start_zk

# --- a silent ECU never passes ------------------------------------------------------------------

SESSIONS = {
    "status": lambda ecu: list(ecu.status(duration=0.5)),
    "hold": lambda ecu: list(ecu.hold("control", 0.5, state="stop")),
    "keepalive": lambda ecu: list(ecu.keepalive(0.5)),
    "run_profile": lambda ecu: ecu.run_profile([(0, 0, "stop"), (0.5, 0, "stop")]),
    "send (limits)": lambda ecu: ecu.send("rpm", target_rpm=60000, rpm_factor=2),
}


@pytest.mark.parametrize("call", list(SESSIONS))
@pytest.mark.zk_sim(silent_after=0.0, speed=10)
def test_a_silent_ecu_raises_no_reply_however_short_the_call(zk_sim, call):
    with Ecu(zk_sim, silence=2.0) as ecu, pytest.raises(NoReply) as e:
        SESSIONS[call](ecu)
    assert e.value.code == 3 and not e.value.noise
    assert not [r for r in zk_sim.device.received if r["id"] == 7]       # no RPM target went out


# --- the ECU's reported limits, before the first frame ----------------------------------------------

REFUSED = {
    # (simulator options, call, what the refusal names)
    "rpm above max": ({"max_rpm": 120000},
                      lambda ecu: ecu.send("rpm", target_rpm=150000, rpm_factor=4), "above the ECU's max rpm 120000"),
    "hold too new": ({"protocol_version": 3},
                     lambda ecu: list(ecu.hold("mode", 1, state="run", rpm_factor=3)), "needs protocol version 4"),
    "pump-on too new": ({"protocol_version": 4},
                        lambda ecu: ecu.send("action", action="pump-on"), "needs protocol version 5"),
    "schedule": ({"max_rpm": 120000},
                 lambda ecu: ecu.run_profile("0,0,run\n2,rpm=150000\n4,0,standby\n"), "150000 rpm"),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_plan_the_ecu_cannot_follow_is_refused_before_anything_is_sent(case):
    options, call, needle = REFUSED[case]
    with start_zk(speed=10, **options) as sim, Ecu(sim.url) as ecu:
        with pytest.raises(EcuLimitError, match=needle) as e:
            call(ecu)
        assert e.value.code == 2 and ecu.limits is not None
        assert not ecu.controlling
    assert list(sim.device.received) == []                  # not even the schedule's start frame


def test_within_the_limits_the_frame_goes_out():
    with start_zk(speed=10, max_rpm=120000) as sim, Ecu(sim.url) as ecu:
        ecu.send("mode", state="run", rpm_factor=3)
        ecu.send("rpm", target_rpm=90000, rpm_factor=3)
        assert ecu.limits.max_rpm == 120000 and ecu.limits.version == 6
    assert [r["command"] for r in sim.device.received][:2] == ["mode", "rpm"]


# --- a signal at any moment ---------------------------------------------------------------------------

HOLDING = {
    "hold": lambda ecu, ready: [ready() for _ in ecu.hold("control", 600, state="run", throttle_pct=30)],
    "rpm hold": lambda ecu, ready: [ready() for _ in ecu.hold("rpm", 600, target_rpm=60000, rpm_factor=2)],
    "run_profile": lambda ecu, ready: ecu.run_profile("0,30,run\n600,0,standby\n", on_record=lambda r: ready()),
    "send, then read": lambda ecu, ready: (ecu.send("control", state="run", throttle_pct=30),
                                           [ready() for _ in ecu.status()]),
}


@pytest.mark.parametrize("case", list(HOLDING))
def test_a_signal_at_a_seeded_moment_leaves_the_engine_in_standby_or_stop(case):
    rng = random.Random(case)
    sig = signal.SIGTERM if rng.random() < 0.5 and case != "send, then read" else signal.SIGINT
    moment = rng.uniform(0.0, 0.3)
    started = threading.Event()
    fired = []

    def ready():
        if not started.is_set():
            started.set()
            timer = threading.Timer(moment, lambda: (fired.append(sig), os.kill(os.getpid(), sig)))
            timer.daemon = True
            timer.start()

    late = signal.signal(signal.SIGTERM, lambda *a: None)    # a signal after the session: harmless here
    try:
        with start_zk(speed=10) as sim:
            with pytest.raises(KeyboardInterrupt):
                with Ecu(sim.url) as ecu:
                    HOLDING[case](ecu, ready)
            ecu_state = sim.device.effective_sw(), sim.device.rpm_mode
    finally:
        signal.signal(signal.SIGTERM, late)
    assert fired == [sig]
    assert ecu_state[0] in ("standby", "stop") and not ecu_state[1], (case, moment, ecu_state)


# --- one clock ---------------------------------------------------------------------------------------

def test_reads_are_sliced_in_real_time_so_the_control_rate_holds_at_any_speed():
    with start_zk(speed=10) as sim, Ecu(sim.url) as ecu:
        for rec in ecu.hold("keepalive", 0.3, rate=50):
            pass
        # half a control period (20 ms of model time) is 1 ms of real time at speed 10
        assert ecu.link.slice_s == pytest.approx(0.001)
        assert ecu.source.clock.speed == 10


def test_record_times_are_the_real_moments_of_their_session_times():
    import calendar
    import time

    with start_zk(speed=10) as sim, Ecu(sim.url) as ecu:
        before = time.time()
        recs = list(ecu.status(count=40))
        after = time.time()
    clock = ecu.source.clock
    for r in recs:
        wall = calendar.timegm(time.strptime(r.time[:19], "%Y-%m-%dT%H:%M:%S")) + int(r.time[20:23]) / 1000
        assert abs(wall - clock.wall(r.t)) < 0.002
    assert before - 0.01 <= clock.wall(recs[-1].t) <= after + 0.01      # never in the future
