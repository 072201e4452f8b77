"""api.selfcheck against the bus simulator: a healthy actuator, a blocked rod, low supply,
an overload; the original goal is restored every time."""

import pytest

from zkzap.api.selfcheck import check_actuator
from zkzap.link.zap_bus import open_bus


@pytest.fixture
def bus():
    b = open_bus("sim://zap?ids=1,2,3&speed=4", 57600)
    yield b
    b.close()


def verdicts(rows):
    return {r["check"]: r["verdict"] for r in rows}


def test_healthy_actuator_passes_and_goal_is_restored(bus):
    a = bus.port.device.actuator(1)
    a.set("present-position", 1500)
    a.set("goal-position", 1500)
    rows = check_actuator(bus, 1)
    assert verdicts(rows) == {"echo": "pass", "identity": "pass", "voltage": "pass", "errors": "pass",
                              "stroke": "pass", "force": "pass", "restore": "pass", "verdict": "pass"}
    stroke = next(r for r in rows if r["check"] == "stroke")
    assert stroke["limit"] == "0..3686" and stroke["value"] > 0
    assert a.get("goal-position") == 1500 and a.get("present-position") == 1500
    assert a.get("force-on-off") == 1


def test_blocked_rod_is_a_stall_by_current(bus):
    a = bus.port.device.actuator(2)
    a.set("present-position", 100)
    bus.port.device.inject(2, "stuck")
    rows = check_actuator(bus, 2, move_timeout=5)
    v = verdicts(rows)
    assert v["stroke"] == "fail" and v["verdict"] == "fail"
    detail = next(r["detail"] for r in rows if r["check"] == "stroke")
    assert "stalled at 100" in detail and "current 800 mA at the goal current" in detail


def test_low_supply_fails_voltage_and_reports_error_bits(bus):
    bus.port.device.inject(3, "voltage", 5.0)
    rows = check_actuator(bus, 3, move=False)
    v = verdicts(rows)
    assert v["voltage"] == "fail" and v["errors"] == "error" and v["verdict"] == "error"
    assert v["stroke"] == "skipped"
    volt = next(r for r in rows if r["check"] == "voltage")
    assert volt["value"] == 5.0 and volt["limit"] == "7..13 V"


def test_silent_actuator(bus):
    rows = check_actuator(bus, 9)
    assert verdicts(rows)["echo"] == "fail" and verdicts(rows)["verdict"] == "fail"
    assert verdicts(rows)["stroke"] == "skipped"
