"""Schedules: throttle and RPM rows, spreadsheet exports, finite cells, and a plan whose cost does not
depend on the schedule's duration."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zkzap.api.schedule import RPM_MAX, Schedule, ScheduleError, ScheduleTargetError
from zkzap.codec import zk
from zkzap.codec.crc import crc8_maxim
from zkzap.errors import UsageError


def parse(text, **kw):
    return Schedule.parse(text, name="s.csv", **kw)


@pytest.mark.parametrize("text", [
    "time_s,throttle_pct,state\n0,10,run\n5,20\n",
    "\ufefftime_s,throttle_pct,state\r\n0,10,run\r\n5,20,\r\n",                 # Excel UTF-8: BOM, CRLF
    '"time_s","throttle_pct","state"\n"0","10","run"\n"5","20",""\n',         # quoted cells
    "time_s;throttle_pct;state\n0;10;run\n5;20;;\n",                            # ';' separators, padding
    "time_s;throttle_pct;state\n0;10,0;run\n5,0;20,0\n",                         # decimal commas
    "time_s\tthrottle_pct\n0\t10\n5\t20\n",                                      # tab separated
    "0,10\n5,20  # a comment\n",
])
def test_spreadsheet_exports_read_alike(text):
    s = parse(text)
    assert [(r.t, r.throttle, r.state) for r in s.rows] == [(0.0, 10.0, "run"), (5.0, 20.0, "run")]


@pytest.mark.parametrize("text,where,what", [
    ("0,nan\n", "s.csv:1", "throttle_pct: 'nan' is not a finite number"),
    ("0,10\ninf,20\n", "s.csv:2", "time_s: 'inf' is not a finite number"),
    ("0,10\n1e400,20\n", "s.csv:2", "time_s: '1e400' is out of range"),
    ("time_s,rpm\n0,NaN\n", "s.csv:2", "rpm: 'NaN' is not a finite number"),
    ("0,rpm=-inf\n", "s.csv:1", "rpm: '-inf' is not a finite number"),
    ("0,10\n1,130\n", "s.csv:2", "throttle: 130 is out of range"),
    ("0,rpm=300000\n", "s.csv:1", f"rpm: 300000 is out of range; allowed 0..{RPM_MAX}"),
    ("0,rpm=90000,pwm\n", "s.csv:1", "state: 'pwm' with an rpm target"),
    ("time_s,throttle_pct,rpm\n0,10,9000\n", "s.csv:2", "give throttle_pct or rpm, not both"),
    ("time_s,throttle,state\n", "s.csv:1", "header"),
    ("0,10\n2,10\n1,10\n", "s.csv:3", "times must not decrease"),
    ("0,speed=3\n", "s.csv:1", "expected rpm=N or throttle_pct=N"),
    ("0,10,run,4\n", "s.csv:1", "4 cells"),
])
def test_bad_cells_name_file_and_line(text, where, what):
    with pytest.raises(ScheduleError) as e:
        parse(text)
    assert str(e.value).startswith(where) and what in str(e.value)


def test_rpm_rows_choose_the_finest_factor_and_leave_rpm_mode():
    s = parse("0,0,run\n10,rpm=95000\n20,rpm=120000\n30,0,standby\n40,0,standby\n")
    assert s.has_rpm and s.rpm_factor == 3 and s.max_target == 120000      # 40950 x 3 >= 120000
    plan = s.plan(20)
    assert [(t, mode, state, value) for t, mode, state, value, _ in plan] == [
        (0.0, "throttle", "run", 0.0), (10.0, "rpm", "run", 95010), (20.0, "rpm", "run", 120000),
        (30.0, "throttle", "standby", 0.0)]
    mode6, id7 = plan[1][4]
    assert zk.decode_control(mode6)["rpm_factor"] == 3 and zk.decode_control(mode6)["state"] == "run"
    assert zk.decode_control(id7)["rpm_value"] == 3167
    # throttle rows in an RPM schedule pair ID 1 with ID 6 none: RPM mode is left
    leave = [zk.decode_control(f) for f in plan[-1][4]]
    assert leave[0]["id"] == 1 and leave[1] == dict(leave[1], id=6, rpm_factor=0, state="none")
    assert any("rounded to 95010" in n for n in s.notes)


def _six(max_rpm, version=6):
    """A status ID 6 frame reporting ``max_rpm`` and protocol ``version``."""
    body = bytes([0xF6, 0, 0, max_rpm // 1000, 0, version << 2])
    return body + bytes([crc8_maxim(body)])


def test_the_schedule_plan_is_checked_against_the_ecu_before_any_frame():
    from zkzap.api.prestart import EcuLimits

    plan = parse("0,rpm=150000\n5,rpm=150000\n").plan_check()
    assert plan.needs_ecu and plan.needs == 4
    plan.check(EcuLimits(_six(160000)))                                   # within the ECU's limits
    with pytest.raises(ScheduleTargetError, match=r"s.csv:1: target 150000 rpm is above the ECU's max rpm 120000"):
        plan.check(EcuLimits(_six(120000)))
    with pytest.raises(ScheduleTargetError, match="needs protocol version 4 or later; the ECU reports 3") as e:
        parse("0,rpm=90000\n5,0\n").plan_check().check(EcuLimits(_six(160000, version=3)))
    assert e.value.code == 2 and e.value.protocol_version == 3        # a usage error: nothing sent
    with pytest.raises(ScheduleTargetError, match="max rpm is not known"):
        plan.check(EcuLimits(None))                                    # no status ID 6 heard
    assert not parse("0,30\n5,0,standby\n").plan_check().needs_ecu    # throttle rows need nothing


def test_plan_cost_does_not_grow_with_duration():
    # a billion seconds at 200 Hz would be 2e11 periods if each one were evaluated
    s = parse("0,10\n1e9,0,standby\n")
    assert [p[0] for p in s.plan(200)] == [0.0, 1e9]
    s = parse("0,0\n1e9,100\n", interpolate="linear")
    plan = s.plan(200)
    assert len(plan) == 1001 and plan[-1][3] == 100.0


def _brute(s, rate):
    out, last = [], None
    for i in range(int(s.length * rate + 1e-9) + 1):
        cmd = s.command_at(i / rate)
        if cmd is None:
            continue
        frames = s._frames(*cmd)
        if frames != last:
            out.append((round(i / rate, 3), frames))
            last = frames
    return out


rows = st.lists(st.tuples(st.integers(1, 40), st.one_of(st.integers(0, 1000).map(lambda v: ("thr", v / 10)),
                                                       st.integers(0, 16000).map(lambda v: ("rpm", v * 10)))),
                min_size=1, max_size=6)


@settings(max_examples=60, deadline=None)
@given(rows, st.sampled_from(["step", "linear"]), st.sampled_from([5, 20]))
def test_plan_matches_stepping_every_period(spec, interpolate, rate):
    t = 0.0
    lines = []
    for dt, (kind, v) in spec:
        t += dt / 10
        lines.append(f"{t:g},{v:g}" if kind == "thr" else f"{t:g},rpm={v:g}")
    s = parse("\n".join(lines) + "\n", interpolate=interpolate)
    assert [(t, f) for t, _, _, _, f in s.plan(rate)] == _brute(s, rate)


RUN30 = zk.encode_control("control", sw="run", throttle_pct=30)[0]
STANDBY0 = zk.encode_control("control", sw="standby", throttle_pct=0)[0]


def test_header_in_any_order_comments_and_a_state_carried_over():
    s = parse("# test\ntime_s,state,throttle_pct\n\n0,run,0\n10,,30  # climb\n20,standby,0\n")
    assert s.length == 20 and s.final_state == "standby"
    assert s.frame_at(5) == zk.encode_control("control", sw="run", throttle_pct=0)[0]
    assert s.frame_at(15) == RUN30                                    # the empty state cell keeps run
    assert s.frame_at(25) == STANDBY0
    assert [p[2:4] for p in s.plan(10)] == [("run", 0.0), ("run", 30.0), ("standby", 0.0)]


def test_linear_ramps_and_nothing_before_the_first_row():
    s = parse("2,0\n12,100\n14,100,stop\n", interpolate="linear")
    assert s.frame_at(1.0) is None
    assert zk.decode_control(s.frame_at(7.0))["throttle_pct"] == 50.0
    assert zk.decode_control(s.frame_at(7.0))["state"] == "run"       # the default first state
    assert zk.decode_control(s.frame_at(2.05))["throttle_pct"] == 0.5
    assert zk.decode_control(s.frame_at(13.0))["throttle_pct"] == 100.0
    assert s.final_state == "stop"


@pytest.mark.parametrize("text,msg", [
    ("", "s.csv: no rows"),
    ("0,10\n5,20,fly\n", "s.csv:2: state: unknown name 'fly'"),
    ("x,10\n", "s.csv:1: header 'x,10'"),
    ("0\n", "s.csv:1: 1 cells"),
    ("-1,0\n", "s.csv:1: time_s: -1 is out of range"),
    ("0,10\n1e308,20\n", "s.csv:2: time_s: 1e308 is out of range; allowed 0..1000000000 s"),
    ("0,ten\n", "s.csv:1: throttle_pct: 'ten' is not a number"),
])
def test_more_bad_rows_name_file_and_line(text, msg):
    with pytest.raises(ScheduleError) as e:
        parse(text)
    assert str(e.value).startswith(msg)


def test_throttle_rounding_is_noted_and_a_zero_length_schedule_refused():
    assert parse("0,33.33\n5,0\n").notes == ["s.csv:1: throttle: 33.33 % is not a multiple of 0.1 %; rounded to 33.3 %"]
    with pytest.raises(UsageError, match="s.csv: the last row is at 0 s"):
        parse("0,10\n").check_length()


def test_load_reads_a_file_and_names_it(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("0,10\n5,20\n", encoding="utf-8")
    s = Schedule.load(str(path))
    assert s.name == str(path) and s.length == 5
    with pytest.raises(UsageError, match=r"schedule: cannot read .*none\.csv: No such file"):
        Schedule.load(str(tmp_path / "none.csv"))
    path.write_bytes(b"0,10\n\xff\xfe\n")
    with pytest.raises(UsageError, match=r"run\.csv:2: not UTF-8 text \(byte 0xFF at byte 5\)"):
        Schedule.load(str(path))


def test_ramps_are_no_steps_and_repeated_targets_are_one_step():
    from zkzap.commands.zk.profile import example_text

    step = Schedule.parse(example_text(), name="x")
    assert [(r.target_text(), a, b) for _, r, a, b in step.steps()] == [
        ("0 %", 0, 25), ("30 %", 25, 40), ("60 %", 40, 55), ("100 %", 55, 62), ("30 %", 62, 70), ("0 %", 70, 75)]
    assert step.ramps() == []
    linear = Schedule.parse(example_text(), name="x", interpolate="linear")
    assert [(r.target_text(), a, b) for _, r, a, b in linear.steps()] == [
        ("0 %", 0, 20), ("30 %", 25, 35), ("60 %", 40, 50), ("100 %", 55, 60), ("0 %", 70, 75)]
    assert [(a, b, why) for _, a, b, why in linear.ramps()] == [
        (20, 25, "ramp 0 % to 30 %"), (35, 40, "ramp 30 % to 60 %"), (50, 55, "ramp 60 % to 100 %"),
        (60, 62, "ramp 100 % to 30 %"), (62, 70, "ramp 30 % to 0 %")]
