"""Standard-day corrections against hand-computed values, sensor quantities and units, the
three line shapes of an external sensor, and the ESR answer's rate."""

from __future__ import annotations

import pytest

from zkzap.api import ambient as A
from zkzap.api.aux import LineParser, field_name
from zkzap.api.esr import PressureAnswer
from zkzap.api.schedule import Schedule
from zkzap.api.steady import StepAverager
from zkzap.errors import UsageError


def test_corrections_worked_example():
    # 1000 hPa, 30 °C: delta = 1000/1013.25 = 0.986923, theta = 303.15/288.15 = 1.052056, sqrt 1.025698
    assert A.delta(1000) == pytest.approx(0.986923, abs=1e-6) and A.theta(30) == pytest.approx(1.052056, abs=1e-6)
    c = A.corrected(1000, 30, thrust=10.0, rpm=100000, flow=0.5)
    assert c["thrust"] == pytest.approx(10.1325, abs=1e-4)            # 10 / 0.986923
    assert c["rpm"] == pytest.approx(97494.6, abs=0.1)                 # 100000 / 1.025698
    assert c["flow"] == pytest.approx(0.493932, abs=1e-6)              # 0.5 / (0.986923 * 1.025698)
    assert A.corrected(None, 30, thrust=10.0, rpm=1.0)["thrust"] is None
    assert A.corrected(1013.25, 15, thrust=7.0, rpm=5.0, flow=0.2) == {"thrust": 7.0, "rpm": 5.0, "flow": 0.2}


def test_step_with_sensor_thrust_and_corrections_matches_the_hand_calculation():
    sched = Schedule.parse("0,50\n10,50,standby\n", name="s")
    temp, press = A.Quantity.parse("30", "temperature", "ambient-temp"), None        # pressure: the ECU's
    avg = StepAverager(sched.steps(), settle=2, average=None, thrust=A.Quantity.parse("load_n", "thrust", "t"),
                       ambient=(temp, press))
    for i in range(100):
        t = i * 0.1
        avg.feed(t, {"id": 1, "rpm": 100000, "engine_state_name": "running"})
        avg.feed(t, {"id": 3, "rpm": 100000, "pressure_pa": 100000})              # 1000 hPa
        avg.feed(t, {"id": 4, "rpm": 100000, "thrust_kg": 9.8})                    # the ECU's 0.1 kg reading
        avg.feed(t, {"id": 7, "rpm": 100000, "fuel_flow_l_min": 0.5})
        avg.feed_aux(t, {"load_n": 98.0665})                                       # 10 kgf on the load cell
    (row,) = avg.rows()
    assert row["thrust_kg_mean"] == 9.8 and row["thrust_from"] == "load_n" and row["thrust_from_kg_mean"] == 10.0
    # TSFC from the load cell: 0.5 L/min x 0.8 kg/L = 6.6667 g/s over 98.0665 N -> 67.98 g/(kN*s)
    assert (row["tsfc_g_kn_s"], row["tsfc_kg_kgf_h"]) == (67.98, 2.4)
    assert (row["ambient_temp_c"], row["ambient_pressure_hpa"], row["delta"], row["theta"]) == \
        (30, 1000, 0.98692, 1.05206)
    assert (row["rpm_corrected"], row["thrust_corrected_kg"], row["fuel_flow_corrected_l_min"]) == \
        (97494.6, 10.1325, 0.4939)
    assert row["tsfc_corrected_g_kn_s"] == 66.28                                   # 67.981 / 1.025698
    assert list(row) == avg.columns()


def test_a_start_up_row_is_no_step():
    sched = Schedule.parse("0,0,run\n5,30\n10,30,standby\n12,0,standby\n", name="s")
    avg = StepAverager(sched.steps(), settle=1, average=None)
    for i in range(100):
        t = i * 0.1
        avg.feed(t, {"id": 1, "rpm": 40000, "engine_state_name": "preheat" if t < 4 else "running"})
    rows = avg.rows()
    assert [(r["step"], r["target"]) for r in rows] == [(1, "30 %")]
    assert [(row.line, why) for row, _, _, why in avg.skipped] == [(1, "start-up")]


@pytest.mark.parametrize("text,kind,raw,want", [
    ("load_n", "thrust", 98.0665, 10.0), ("w:lbf", "thrust", 10.0, 4.5359237), ("f:mL/min", "fuel_flow", 500, 0.5),
    ("f:kg/h", "fuel_flow", 24.0, 0.5), ("baro_pa", "pressure", 101325, 1013.25), ("p:inHg", "pressure", 29.92, 1013.21),
    ("t:K", "temperature", 288.15, 15.0), ("t:F", "temperature", 59, 15.0),
])
def test_sensor_units(text, kind, raw, want):
    assert A.Quantity.parse(text, kind, "x").convert(raw, density=0.8) == pytest.approx(want, abs=0.01)


@pytest.mark.parametrize("text,kind,msg", [
    ("load", "thrust", r"which unit\? write load:UNIT"), ("load:stone", "thrust", "unit 'stone'; allowed"),
    ("12", "thrust", "give the field of an --aux sensor"), ("nan", "temperature", "not a finite number"),
])
def test_sensor_quantities_refused(text, kind, msg):
    with pytest.raises(UsageError, match=msg):
        A.Quantity.parse(text, kind, "x", constant=kind != "thrust")


@pytest.mark.parametrize("lines,want", [
    (["thrust_n=12.5 T-amb=21", "thrust_n=13;T-amb=21.5"], [{"thrust_n": 12.5, "t_amb": 21},
                                                          {"thrust_n": 13, "t_amb": 21.5}]),
    (["Thrust N;flow", "12,5;250", "1;2;3"], [{"flow": 250}]),
    (['{"rpm": 1, "load": 2.5}', "not json", '[1]'], [{"aux_rpm": 1, "load": 2.5}]),
])
def test_the_three_line_shapes(lines, want):
    p = LineParser(taken={"rpm"})
    assert [r.values for r in map(p.feed, lines) if r] == want


def test_a_csv_without_header_and_names():
    p = LineParser(set())
    assert p.feed("1.5,2.5") is None and p.skipped == 1 and p.shape is None     # no header: no reading
    assert field_name("9 load", {"t"}) == "_9_load" and field_name("t", {"t"}) == "aux_t"


def test_garbage_is_rejected_and_counted_never_stored():
    from zkzap.api.sensors import parse_decl

    (decl,) = parse_decl("cell.log,thrust:kgf:0..100", taken={"rpm"})
    p = LineParser({"rpm"}, decl)
    lines = ["HX711 load cell v1.2 ready", "thrust=12.3 status=OK", "thrust=abc", "thrust=-5",
             "thrust=12.3 thrust=99", "thrust=NaN", "thrust=1" + "0" * 400, "> ", ""]
    got = [p.feed(line) for line in lines]
    assert [r.values for r in got if r] == [{"thrust": 12.3}] + [{}] * 5
    assert [(k, why) for r in got if r for k, why, _ in r.rejected] == [
        ("thrust", "not a number"), ("thrust", "outside 0..100 kgf"), ("thrust", "given twice in one line"),
        ("thrust", "not a finite number"), ("thrust", "not a finite number")]
    assert p.skipped == 3 and p.ignored == ["status"] and p.stats["thrust"][0] == 1


def test_a_banner_is_no_csv_header():
    p = LineParser(set())
    got = [p.feed(line) for line in ("HX711 load cell v1.2 ready", "thrust_n,flow", "12.5,3", "abc", "13,x")]
    assert p.header == ["thrust_n", "flow"] and p.skipped == 2                      # the banner and 'abc'
    assert [r.values for r in got if r] == [{"thrust_n": 12.5, "flow": 3}, {"thrust_n": 13}]
    p = LineParser(set())
    assert [p.feed(line) for line in ("HX711 load cell v1.2 ready", "thrust=12.5")][1].values == {"thrust": 12.5}
    assert p.shape == "pairs" and p.skipped == 1


def test_json_values_a_record_cannot_hold_are_rejected():
    p = LineParser(set())
    got = [p.feed(line) for line in ('{"load": NaN, "ok": 1}', '{"load": 1e400, "x": Infinity, "y": "1"}',
                                     '{"load": 2, "load": 3}', '{"load": -Infinity}', "[1]")]
    assert [r.values for r in got if r] == [{"ok": 1}, {}, {}, {}]
    assert sum(len(r.rejected) for r in got if r) == 6 and p.skipped == 1


def test_calibration_tare_scale_and_curve():
    from zkzap.api.sensors import Calibration

    assert Calibration(tare=0.5, scale=2).apply(10.5) == 20.0
    c = Calibration(tare=1.0, points=[[0, 0], [100, 98.0665], [200, 200]])
    assert c.apply(1.0) == 0 and c.apply(51.0) == pytest.approx(49.03325) and c.apply(301.0) == pytest.approx(301.9335)
    with pytest.raises(UsageError, match="given twice"):
        Calibration(points=[[1, 2], [1, 3]])
    with pytest.raises(UsageError, match="one point is a scale"):
        Calibration(points=[[1, 2]])
    with pytest.raises(UsageError, match="scale 0"):
        Calibration(scale=0)


def test_esr_is_answered_at_once_then_at_most_once_a_second():
    said = []
    ans = PressureAnswer(lambda t: 1007.6 if t >= 0.3 else None, "--air-pressure", notify=said.append)
    sent = [t for t in (0.0, 0.25, 0.5, 0.75, 1.0, 1.3, 1.45, 2.0)
            if ans.on_frame(t, {"id": 8, "esr": 1}) is not None]
    assert ans.on_frame(3.0, {"id": 8, "esr": 0}) is None and ans.on_frame(3.0, {"id": 3, "esr": 1}) is None
    assert sent == [0.5, 1.45] and ans.sent[0] == (0.5, 1008, "FF 83 F0 0E") and ans.asked == 8
    assert "no value from --air-pressure yet" in said[0] and "answering 1008 hPa" in said[1]
    big = PressureAnswer(lambda t: 1030, "x", notify=said.append)
    from zkzap.codec import zk

    assert big.on_frame(0, {"id": 8, "esr": 1}) == zk.encode_control("pressure", pressure_hpa=1023)[0]
    assert big.sent[0][1] == 1023 and "does not fit control ID 8" in said[2]


def test_esr_answers_keep_a_schedule_of_one_a_second_whatever_the_jitter():
    # status ID 8 twice a second, each read up to 0.12 s late: one answer a second, not one every
    # 1.5 s (as a rule of "at least 0.9 s since the last answer" gives)
    ans = PressureAnswer(lambda t: 1000, "x")
    jitter = (0.0, 0.12, 0.03, 0.11, 0.0, 0.09, 0.12, 0.01, 0.1, 0.05)
    asks = [k * 0.5 + jitter[k % len(jitter)] for k in range(21)]
    sent = [t for t in asks if ans.on_frame(t, {"id": 8, "esr": 1}) is not None]
    assert len(sent) == 11 and all(t >= n - 0.1 for n, t in enumerate(sent))
    assert all(b - a >= 0.5 for a, b in zip(sent, sent[1:]))
    # a bunch read at once after a stall gets one answer; after a pause the schedule starts again
    assert ans.on_frame(13.0, {"id": 8, "esr": 1}) is not None and ans.on_frame(13.0, {"id": 8, "esr": 1}) is None
    assert ans.on_frame(13.49, {"id": 8, "esr": 1}) is None and ans.on_frame(13.9, {"id": 8, "esr": 1}) is not None
