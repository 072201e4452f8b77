"""Range first, then conversion: whatever number meets a field of either table (a float of
1e308, an integer of 400 digits, a string of either, a list), the answer is a raw value in the
field's range or one FieldValueError naming the field — never an OverflowError or TypeError.

Every field of ``CONTROL`` and ``STATUS`` is drawn, and the whole API (``encode_control``,
``encode_status``) and the command line (every ``zk send`` command's field) are tried with the
values that used to overflow."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zkzap.codec import zk
from zkzap.codec.fields import FieldValueError

CONTEXT = {"version": zk.DEFAULT_PROTOCOL_VERSION, "rpm_factor": 3}
FIELDS = [(f"control {c.name}", f) for c in zk.CONTROL for f in c.fields] + \
         [(f"status {s.name}", f) for s in zk.STATUS for f in s.fields]
HUGE = [1e308, -1e308, 10 ** 400, -(10 ** 400), 10 ** 5000, 2 ** 64, 1.7976931348623157e308, "1e308",
        "1" + "0" * 400, "0x" + "f" * 300, "9" * 5000]
HUGE_IDS = ["1e308", "-1e308", "10**400", "-10**400", "10**5000", "2**64", "max float", "'1e308'", "'1' 400 zeros",
            "'0x' 300 f", "'9' x 5000"]

numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(), st.integers(min_value=-(10 ** 500), max_value=10 ** 500),
    st.sampled_from(HUGE),
    st.from_regex(r"\A-?[0-9]{1,500}(\.[0-9]{0,20})?(e-?[0-9]{1,4})?\Z"),
    st.text(max_size=20), st.lists(st.integers(), max_size=2), st.none(), st.booleans())


def _check(field, value):
    try:
        raw, note = field.to_raw(value, CONTEXT)
    except FieldValueError as e:
        message = str(e)
        assert message.startswith(field.label + ":"), message
        assert "\n" not in message and len(message) < 200 + len(field.describe_range(CONTEXT)), message
        return None
    assert isinstance(raw, int) and field.lo <= raw <= field.hi
    return raw


def test_the_walk_covers_both_tables():
    assert {f.key for _, f in FIELDS} >= {"throttle_pct", "ignition_voltage_v", "target_rpm", "pressure_hpa",
                                          "rpm", "egt_c", "fuel_flow_l_min"}


@pytest.mark.parametrize("where,field", FIELDS, ids=[f"{w} {f.key}" for w, f in FIELDS])
@settings(max_examples=60, deadline=None)
@given(value=numbers)
def test_every_field_gives_its_range_or_a_field_error(where, field, value):
    _check(field, value)


@pytest.mark.parametrize("where,field", FIELDS, ids=[f"{w} {f.key}" for w, f in FIELDS])
def test_huge_finite_values_are_out_of_range(where, field):
    for value in HUGE:
        if field.names is not None and isinstance(value, str):
            continue                                  # a name that is no name: refused as such
        with pytest.raises(FieldValueError, match="out of range|not a number|not an integer"):
            field.to_raw(value, CONTEXT)


@pytest.mark.parametrize("value", HUGE, ids=HUGE_IDS)
@pytest.mark.parametrize("command", [c for c in zk.CONTROL if c.fields], ids=lambda c: c.name)
def test_encode_control_refuses_huge_values_by_field(command, value):
    params = {p.key: 2 for p in command.params}
    for f in command.fields:
        with pytest.raises(FieldValueError, match=f"^{f.label}: "):
            zk.encode_control(command.name, **params, **{f.key: value})
    for p in command.params:
        with pytest.raises(FieldValueError, match=f"^{p.label}: "):
            zk.encode_control(command.name, **{p.key: value})


@pytest.mark.parametrize("value", HUGE[:4], ids=HUGE_IDS[:4])
@pytest.mark.parametrize("status", zk.STATUS, ids=lambda s: s.name)
def test_encode_status_refuses_huge_values_by_field(status, value):
    for f in status.fields:
        with pytest.raises(FieldValueError, match=f"^{f.label}: "):
            zk.encode_status(status.id, **{f.key: value})


def _send_args():
    """Every zk send command with a field on its command line, its other arguments, and how the
    field is given."""
    rows = []
    for c in zk.CONTROL:
        extra = [x for p in c.params for x in (p.cli, "2")]
        for f in c.fields:
            if f.cli is None or f.names is not None:
                continue
            others = [x for g in c.fields if g is not f and g.cli and g.cli.startswith("--") and g.names
                      for x in (g.cli, next(iter(g.names.values())))]
            rows.append((c.name, f, extra + others))
    return rows


SEND = _send_args()


def test_every_numeric_field_of_zk_send_is_tried():
    assert {name for name, _, _ in SEND} >= {"control", "ignition-voltage", "accel-curve", "rpm", "pressure", "mode"}


@pytest.mark.parametrize("value", ["1e308", "-1e308", "1" + "0" * 400, "1e400"], ids=["1e308", "-1e308", "400 digits", "1e400"])
@pytest.mark.parametrize("name,field,extra", SEND, ids=[f"{n} {f.key}" for n, f, _ in SEND])
def test_zk_send_says_a_huge_value_is_out_of_range(cli, name, field, extra, value):
    given_as = [field.cli, value] if field.cli.startswith("--") else ["--", value]
    r = cli("zk", "send", name, "-n", *extra, *given_as)
    assert r.exit_code == 2, r
    assert r.stdout == "" and "Traceback" not in r.stderr, r
    assert "out of range" in r.stderr or "not an integer" in r.stderr, r
    assert len(r.stderr) < 400, r


@pytest.mark.parametrize("row", ["0,1e308,run", "0,-1e308", "0,rpm=1e308,run", "0," + "9" * 400 + ",run",
                                 "0,rpm=" + "9" * 400])
def test_a_schedule_row_with_a_huge_target_is_out_of_range(row):
    from zkzap.api.schedule import Schedule, ScheduleError

    with pytest.raises(ScheduleError, match=r"^s:1: (throttle|rpm)\S*: .* is out of range") as e:
        Schedule.parse(row + "\n", name="s")
    assert len(str(e.value)) < 200
