"""Limits beyond a status field's level: its rate of change (FIELD/s), limits of some engine
states only (when=), and the fields of external sensors and corrected values."""

from __future__ import annotations

import pytest

from zkzap.api.expr import ExpressionError
from zkzap.api.limits import FIELDS, LimitSet, parse_limit, read_limits


def rec(t, state, egt, rpm=0):
    return {"id": 1, "engine_state": state, "egt_c": egt, "rpm": rpm}


def test_a_rate_limit_tests_the_change_per_second_over_its_window():
    lim = LimitSet([parse_limit("egt_c/s<=50,warn=30")], "exit")
    assert lim.conditions[0].rate and lim.conditions[0].field == "egt_c"
    # 20 degC/s for 2 s: fine; then 100 degC/s: violated once the window holds it
    t, egt, got = 0.0, 100.0, []
    for _ in range(40):
        got.append(lim.check(t, rec(t, 11, egt)))
        t, egt = t + 0.05, egt + 1.0
    assert all(not g for g in got) and lim.tripped is None
    for _ in range(30):
        got.append(lim.check(t, rec(t, 11, egt)))
        t, egt = t + 0.05, egt + 5.0
    assert lim.tripped is not None and "egt_c/s=" in str(lim.tripped)
    assert lim.summary()[0]["field"] == "egt_c/s" and lim.summary()[0]["extreme"] > 50


def test_a_limit_of_some_engine_states_only():
    run_only = parse_limit("egt_c<=700,when=running")
    start_or_cool = parse_limit("rpm<=30000,when=start|cooling")
    lim = LimitSet([run_only, start_or_cool], "warn")
    assert lim.check(1.0, rec(1.0, 4, 800, 20000)) == {}               # preheat: EGT not limited
    assert lim.check(2.0, rec(2.0, 11, 800, 90000)) == {"limit": [run_only.text]}   # running: it is
    assert lim.check(3.0, rec(3.0, 12, 300, 35000)) == {"limit": [start_or_cool.text]}
    assert lim.check(4.0, rec(4.0, 1, 900, 0)) == {}                     # standby: neither


@pytest.mark.parametrize("text,needle", [
    ("egt_c<=700,when=flying", "when='flying' is no engine state"),
    ("egt_c<=700,when=running,when=start", "when= given twice"),
    ("thrust<=20", "unknown field 'thrust'"),
])
def test_bad_limits_are_refused_naming_them(text, needle):
    with pytest.raises(ExpressionError) as e:
        read_limits([text])
    assert needle in str(e.value)


def test_a_limit_on_a_sensor_or_corrected_value_is_tested_on_the_records_values():
    lim = LimitSet(read_limits(["load_n<=200,warn=150"], fields=None), "exit")
    assert lim.check(1.0, {"id": 2, "power_voltage_v": 12.0}, {"load_n": 120.0}) == {}
    assert lim.check(1.1, {"id": 3}, {"load_n": 160.0}) == {"warnings": ["load_n<=200,warn=150"]}
    assert lim.check(1.2, {"id": 3}, {"load_n": None}) == {}             # no reading: nothing said
    assert lim.check(1.3, {"id": 4}, {"load_n": 210.0}) == {"limit": ["load_n<=200,warn=150"]}
    assert lim.tripped.value == 210.0 and "load_n" not in FIELDS
