"""The live view shows limit violations (red) and warning bands (yellow) from the limit set."""

from __future__ import annotations

import io

from rich.console import Console

from zkzap.api import limits as L
from zkzap.io.dashboard import Dashboard


def test_dashboard_shows_violated_and_warning_limits():
    lims = L.LimitSet([L.parse("egt_c<=850", L.FIELDS), L.parse("rpm<=165000,warn=150000", L.FIELDS)], "warn")
    lims.check(3.0, {"id": 1, "rpm": 155000, "egt_c": 861})
    console = Console(file=io.StringIO(), width=110, color_system="truecolor", force_terminal=True)
    d = Dashboard(None, "profile stand.csv on sim://zk", console=console)
    d.update({"rpm": 155000, "egt_c": 861, "engine_state_name": "running", "time_s": 3.0},
             {"frames": 60, "frames_per_s": 20.0, "limits": lims.dashboard_lines()})
    console.print(d.render())
    out = console.file.getvalue()
    assert "egt_c<=850 violated at 3.0 s, extreme 861" in out
    assert "rpm<=165000,warn=150000: in the warning band, extreme 155000" in out
    assert "\x1b[1;97;41m" in out or "41m" in out          # white on red


def test_dashboard_lists_the_alarms_latched_and_acknowledged():
    from zkzap.api.alarms import Alarms

    a = Alarms()
    a.trip("interrupted", "interrupted; sent standby, throttle 0", t=4.0)
    a.acknowledge("bench")
    a.trip("hung-start", "hung start: the ECU has been starting for 90 s without reaching a running state", t=95.0)
    a.raise_alarm("warning", "limit egt_c<=850,warn=800 in its warning band", level="warning")
    console = Console(file=io.StringIO(), width=140, color_system=None, force_terminal=True)
    d = Dashboard(None, "zk send on sim://zk", console=console)
    d.update({"rpm": 0, "time_s": 96.0}, {"frames": 60, "frames_per_s": 20.0, "alarms": a.to_list()})
    console.print(d.render())
    out = console.file.getvalue()
    assert "Alarm" in out and "LATCHED  hung start: the ECU has been starting for 90 s" in out
    assert "acknowledged by bench  interrupted; sent standby" in out
    assert out.index("hung start") < out.index("interrupted;")          # newest first
    assert "warning band" not in out                                    # warnings have their own lines
