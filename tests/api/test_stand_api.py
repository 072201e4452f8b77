"""Limits on status frames, steady-state reduction with TSFC, and the SQLite logbook."""

from __future__ import annotations

import multiprocessing
import sqlite3

import pytest

from zkzap.api import limits as L
from zkzap.api import logbook as lb
from zkzap.api.schedule import Schedule
from zkzap.api.steady import SETTLED_FRACTION, StepAverager, columns, tsfc
from zkzap.errors import UsageError


def frame(sid, **values):
    return dict({"kind": "status", "id": sid, "rpm": 50000}, **values)


def test_limits_are_evaluated_only_on_frames_that_carry_the_field():
    lims = L.LimitSet([L.parse("egt_c<=850,warn=800", L.FIELDS), L.parse("rpm<=165000", L.FIELDS)], "exit")
    assert lims.check(0.0, frame(1, egt_c=700)) == {}
    assert lims.check(0.05, frame(2, power_voltage_v=12.0)) == {}      # no egt_c: only rpm tested
    assert lims.check(0.10, frame(1, egt_c=820)) == {"warnings": ["egt_c<=850,warn=800"]}
    assert lims.tripped is None
    assert lims.check(0.15, frame(1, egt_c=861)) == {"limit": ["egt_c<=850,warn=800"]}
    assert lims.tripped is not None and lims.tripped.code == 5 and "egt_c=861 at t=0.15 s" in str(lims.tripped)
    lims.check(0.20, frame(1, egt_c=870))
    s = {x["limit"]: x for x in lims.summary()}
    egt = s["egt_c<=850,warn=800"]
    assert (egt["checked"], egt["extreme"], egt["first_warning_t"], egt["first_violation_t"], egt["verdict"]) == \
        (4, 870, 0.1, 0.15, "violated")
    assert s["rpm<=165000"]["checked"] == 5 and s["rpm<=165000"]["verdict"] == "ok"
    assert lims.dashboard_lines()[0][0] == "violated"


def test_lower_limits_keep_the_lowest_value_and_unseen_fields_are_unchecked():
    lims = L.LimitSet([L.parse("power_voltage_v>=7.2", L.FIELDS), L.parse("prop_rpm<=100", L.FIELDS)], "warn")
    for t, v in ((0, 8.0), (1, 7.1), (2, 7.5)):
        lims.check(t, frame(2, power_voltage_v=v))
    s = lims.summary()
    assert s[0]["extreme"] == 7.1 and s[0]["extreme_t"] == 1 and s[0]["violations"] == 1
    assert lims.tripped is None                      # warn: the session goes on
    assert s[1]["verdict"] == "unchecked" and s[1]["checked"] == 0


def test_limits_file_and_bad_expressions(tmp_path):
    f = tmp_path / "engine.limits"
    f.write_text("\ufeff# K-100 limits\negt_c <= 850, warn=800\n\nrpm<=165000  # redline\n")
    assert [c.text for c in L.read_limits(["error_code==0"], [str(f)])] == \
        ["egt_c <= 850, warn=800", "rpm<=165000", "error_code==0"]
    f.write_text("egt_c<=850\negt<=3\n")
    with pytest.raises(UsageError, match=f"{f}:2: 'egt<=3': unknown field 'egt'"):
        L.read_limits([], [str(f)])
    with pytest.raises(UsageError, match="cannot read"):
        L.read_limits([], [str(tmp_path / "none")])
    with pytest.raises(UsageError, match="not a finite number"):
        L.read_limits(["egt_c<=nan"])


def test_tsfc_worked_example():
    # 0.5 L/min of Jet A-1 (0.8 kg/L) = 6.667 g/s; 10 kgf = 98.0665 N -> 67.98 g/(kN*s), 2.4 kg/(kgf*h)
    assert tsfc(0.5, 10.0, 0.8) == (67.98, 2.4)
    assert tsfc(0.5, 0.0, 0.8) == (None, None) and tsfc(None, 3, 0.8) == (None, None)
    assert tsfc(0.5, 10.0, 0.84)[1] == 2.52                    # diesel


def test_step_averages_windows_and_settling():
    sched = Schedule.parse("0,30\n10,60\n20,60\n", name="s")
    avg = StepAverager(sched.steps(), settle=2, average=5)
    for i in range(200):
        t = i * 0.1
        rpm = 80000 if t < 10 else 100000 + (t - 10) * 2000      # step 2 keeps accelerating
        avg.feed(t, {"id": 1, "rpm": rpm, "egt_c": 600})
        avg.feed(t + 0.05, {"id": 4, "rpm": rpm, "thrust_kg": 5.0})
        avg.feed(t + 0.07, {"id": 7, "rpm": rpm, "fuel_flow_l_min": 0.3})
    one, two = avg.rows()
    assert (one["window_start_s"], one["window_end_s"], one["rpm_mean"], one["settled"]) == (2, 7, 80000, True)
    assert one["frames"] == 150 and one["thrust_kg_mean"] == 5.0 and one["tsfc_g_kn_s"] == tsfc(0.3, 5, 0.8)[0]
    assert two["settled"] is False and "never settled" in two["note"] and two["target"] == "60 %"
    assert f"more than {SETTLED_FRACTION * 100:g} %" in two["note"]
    assert list(one) == columns()
    cut = StepAverager(sched.steps(), settle=8, average=5).rows()[0]
    assert cut["window_end_s"] == 10 and "window cut to 2 s" in cut["note"] and cut["settled"] is None


def test_logbook_two_concurrent_writers(tmp_path):
    path = str(tmp_path / "engine.db")
    lb.check_writable(path)
    ctx = multiprocessing.get_context("spawn")
    from logbook_writer import write_runs

    procs = [ctx.Process(target=write_runs, args=(path, 25, f"stand {k}")) for k in (1, 2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
        assert p.exitcode == 0
    runs = lb.runs(path)
    assert len(runs) == 50 and sorted({r["command"] for r in runs}) == ["stand 1", "stand 2"]
    tot = lb.totals(runs)
    assert tot["starts"] == 50 and tot["fuel_used_l"] == 12.5 and tot["running_hours"] == round(1500 / 3600, 4)
    assert sqlite3.connect(path).execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_run_stats_count_starts_and_running_time():
    s = lb.RunStats()
    for t, name in ((0, "stop"), (1, "ignition"), (5, "running"), (9, "running"), (10, "cooling"), (12, "running"),
                    (13, "stop")):
        s.feed(t, {"id": 1, "engine_state_name": name})
        s.feed(t, {"id": 2})
    assert s.starts == 2 and s.running_s == 6.0


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

ops = st.sampled_from(["<", "<=", ">", ">="])


@settings(max_examples=80, deadline=None)
@given(ops, st.integers(0, 1000), st.lists(st.tuples(st.sampled_from([1, 2, 3]), st.integers(0, 1000)),
                                           max_size=40))
def test_limit_bookkeeping_matches_a_direct_count(op, threshold, stream):
    cond = L.parse(f"egt_c{op}{threshold}", L.FIELDS)
    lims = L.LimitSet([cond], "exit")
    test = L.parse.__globals__["OPERATORS"][op]
    for i, (sid, v) in enumerate(stream):
        extra = lims.check(i * 0.05, frame(sid, egt_c=v) if sid == 1 else frame(sid))
        assert ("limit" in extra) == (sid == 1 and not test(v, threshold))
    carried = [(i, v) for i, (sid, v) in enumerate(stream) if sid == 1]
    s = lims.summary()[0]
    bad = [(i, v) for i, v in carried if not test(v, threshold)]
    assert s["checked"] == len(carried) and s["violations"] == len(bad)
    assert s["first_violation_t"] == (round(bad[0][0] * 0.05, 3) if bad else None)
    values = [v for _, v in carried]
    want = None if not values else (max(values) if op in ("<", "<=") else min(values))
    assert s["extreme"] == want
    assert (lims.tripped is not None) == bool(bad)


def _fed(rpm, egt=600.0, thrust=5.0):
    sched = Schedule.parse("0,60\n10,60,standby\n", name="s")
    avg = StepAverager(sched.steps(), settle=2, average=None)
    for i in range(100):
        t = i * 0.1
        avg.feed(t, {"id": 1, "rpm": rpm(t), "egt_c": egt if not callable(egt) else egt(t)})
        avg.feed(t + 0.05, {"id": 4, "rpm": rpm(t), "thrust_kg": thrust if not callable(thrust) else thrust(t)})
    (row,) = avg.rows()
    return row


def test_settling_is_the_drift_across_the_window_on_rpm_egt_and_thrust():
    # a 2 % rise across the window whose half-means differ by under 1 %: not settled
    row = _fed(lambda t: 100000 + max(0.0, t - 2) / 8 * 2000)
    assert row["settled"] is False and "rpm drifted +1.98 %" in row["note"] and "(more than 1 %)" in row["note"]
    assert row["drift_rpm"] == pytest.approx(2000, rel=0.02) and row["rpm_std"] > 0
    flat = _fed(lambda t: 100000 + (50 if int(t * 10) % 2 else -50))          # noise, no trend
    assert flat["settled"] is True and flat["note"] == "" and flat["rpm_std"] == pytest.approx(50, rel=0.05)
    egt = _fed(lambda t: 100000, egt=lambda t: 600 + 2 * t)                  # +16 °C across 8 s
    assert egt["settled"] is False and "EGT drifted +16.0 °C across the window (more than 10 °C)" in egt["note"]
    thrust = _fed(lambda t: 100000, thrust=lambda t: 5.0 + 0.05 * t)         # +0.4 kgf on 5.2
    assert thrust["settled"] is False and "thrust drifted +7." in thrust["note"]


def test_one_stand_session_runs_a_trip_its_rundown_and_the_interlock_over_sessions(tmp_path):
    """StandSession, as a console runs it: sessions one after the other on one source and one
    alarm list; a trip latches, the rundown is recorded, a start waits for the acknowledgement
    and a cool engine, and the logbook gets the run."""
    from zkzap.api.alarms import StartRefused
    from zkzap.api.stand import Stand, StandSession
    from zkzap.api.telemetry import Telemetry
    from zkzap.codec import zk
    from zkzap.codec.permissions import Permission
    from zkzap.link.zk_port import ZkLink
    from zkzap.link.zk_sources import LiveSource

    said = []
    limits = L.LimitSet([L.parse("egt_c<=500", L.FIELDS)], "abort")
    book = tmp_path / "engine.db"
    ss = StandSession(Stand(limits, logbook=str(book), engine="K100-1"), notify=said.append)
    ss.start(2.0)
    link = ZkLink.open("sim://zk?speed=20", 115200, allow=Permission.ENGINE)
    src = LiveSource(link)
    records = []
    ss.attach(src, Telemetry(None, {2, 3}, False, clock=src.clock), records.append)
    run = zk.encode_control("control", sw="run", throttle_pct=40)[0]
    try:
        outcome = ss.run(control=lambda t: run, duration=60, stop_on_error=True)
        assert outcome.reason == "limit" and outcome.aborted == "standby" and outcome.exit_code == 5
        kinds = [r.get("kind") for r in records]
        assert kinds.count("trip") == 1 and kinds[-1] == "rundown"
        assert ss.alarms.latched and "egt_c<=500" in ss.alarms.latched[0].text
        assert ss.refusal().startswith("start refused: alarm latched")
        again = ss.run(control=lambda t: run, duration=1, restart=False)
        assert again.reason == "refused" and isinstance(again.error, StartRefused)
        (acked,) = ss.acknowledge("bench")
        assert acked.acked_by == "bench" and ss.alarms.latched == []
        zero = zk.encode_control("control", sw="run", throttle_pct=0)[0]
        assert ss.refusal(setpoint=0) is None                # the rundown ended at rest, and cool
        # the sessions go on on the source's one clock (restart=False): a duration is a time on
        # it, so this session runs 0.5 s from now (a bare 0.5 was long past: a session that ended
        # at its first read, and failed as silent when that read held no whole frame)
        at_zero = ss.run(control=lambda t: zero, duration=src.now() + 0.5, restart=False)
        assert at_zero.ok, (at_zero.reason, at_zero.error)
        summary = ss.summary()
        assert summary["engine"] == "K100-1" and summary["alarms"][0]["acked_by"] == "bench"
    finally:
        link.close()
        ss.close()
    assert ss.log_run(command="test", port="sim://zk", outcome=outcome) == 1
    with sqlite3.connect(book) as db:
        assert db.execute("select engine, limits_violated from runs").fetchone() == ("K100-1", '["egt_c<=500"]')
