"""Conditions on record fields: strict parsing, evaluation, warning bands."""

import pytest

from zkzap.api import expr
from zkzap.errors import USAGE

FIELDS = {"egt_c", "rpm", "power_voltage_v", "error_code", "moving"}


@pytest.mark.parametrize("text, value, verdict", [
    ("egt_c<=850,warn=800", 700, "ok"),
    ("egt_c<=850,warn=800", 820, "warn"),
    ("egt_c<=850,warn=800", 851, "violated"),
    ("power_voltage_v >= 7.2", 7.2, "ok"),
    ("power_voltage_v>=7.2,warn=7.6", 7.4, "warn"),
    ("power_voltage_v>=7.2", 7.1, "violated"),
    ("error_code==0", 0, "ok"),
    ("error_code==0", 8, "violated"),
    ("rpm<165000", 165000, "violated"),
    ("moving==false", 0, "ok"),
    ("rpm!=0x10", 16, "violated"),
    ("egt_c<=850", None, None),
])
def test_check(text, value, verdict):
    assert expr.parse(text, FIELDS).check(value) == verdict


@pytest.mark.parametrize("text, needle", [
    ("egt<=850", "unknown field 'egt'; did you mean egt_c"),
    ("egt_c=<850", "expected FIELD OP NUMBER"),
    ("egt_c<=nan", "not a finite number"),
    ("egt_c<=inf", "not a finite number"),
    ("egt_c<=hot", "'hot' is not a number"),
    ("egt_c<=850,warn=900", "must be below the limit"),
    ("power_voltage_v>=7.2,warn=7", "must be above the limit"),
    ("error_code==0,warn=1", "needs one of"),
    ("egt_c<=850,alarm=3", "is not warn=NUMBER"),
    ("", "expected FIELD OP NUMBER"),
])
def test_bad(text, needle):
    with pytest.raises(expr.ExpressionError) as e:
        expr.parse(text, FIELDS, where="--limit")
    assert needle in str(e.value) and str(e.value).startswith("--limit: ")
    assert e.value.code == USAGE


def test_lines_name_file_and_line():
    conds = expr.parse_lines("\ufeff# stand 3\negt_c<=850,warn=800\n\nrpm<=165000  # redline\n", FIELDS,
                             name="j.limits")
    assert [c.text for c in conds] == ["egt_c<=850,warn=800", "rpm<=165000"]
    with pytest.raises(expr.ExpressionError, match=r"^j.limits:3: "):
        expr.parse_lines("rpm<=1\n\nbogus>1\n", FIELDS, name="j.limits")


def test_worse_tracks_the_extreme():
    c = expr.parse("egt_c<=850", FIELDS)
    assert c.worse(c.worse(None, 700), 900) == 900
    c = expr.parse("power_voltage_v>=7", FIELDS)
    assert c.worse(7.5, 6.9) == 6.9


def test_hyphenated_field_names_are_accepted_when_the_key_uses_underscores():
    assert expr.parse("egt-c<=850", FIELDS).field == "egt_c"
    assert expr.parse("present-position>=3", {"present-position"}).field == "present-position"
