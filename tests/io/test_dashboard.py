"""The live ZK dashboard, rendered to string consoles (no terminal needed)."""

from __future__ import annotations

import io
import threading

import pytest
from rich.console import Console

from zkzap.codec import zk
from zkzap.io import dashboard as dmod
from zkzap.io.dashboard import Dashboard, History, bar, fmt, sparkline, state_style


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def health(**kw):
    h = {"frames": 0, "frames_per_s": 0.0, "crc_errors": 0, "skipped": 0, "stale": False,
         "protocol_version": 4, "version_source": "frame"}
    h.update(kw)
    return h


def running_snapshot(**kw):
    snap = {k: None for k in zk.STATUS_KEYS}
    snap.update(time_s=0.0, rpm=120000, max_rpm=160000, idle_rpm=35000, egt_c=652, engine_state=11,
                engine_state_name="running", error_code=0, error_name="none", sw_state=2, sw_state_name="run",
                throttle_pct=50, thrust_kg=12.3, current_a=2.1, fuel_flow_l_min=0.25, fuel_used_l=1.2,
                power_voltage_v=12.4, radio_voltage_v=5.0, pump_voltage_v=3.2, ecu_temp_c=35)
    snap.update(kw)
    return snap


def text_of(dash, width=100, color=False):
    out = io.StringIO()
    console = Console(file=out, width=width, force_terminal=color, color_system="truecolor" if color else None,
                      legacy_windows=False)
    console.print(dash.render())
    return out.getvalue()


def test_running_engine_shows_what_a_pilot_reads():
    clock = FakeClock()
    d = Dashboard(None, "ZK ECU  /dev/ttyUSB0", clock=clock)
    d.update(running_snapshot(), health(frames=250, frames_per_s=50.0))
    clock.t += 0.4
    text = text_of(d)
    for expected in ("ZK ECU  /dev/ttyUSB0", "RUNNING", "none", "120,000 rpm", "75 %", "160,000 rpm",
                     "652 °C", "50%", "12.3 kg", "0.25 L/min", "1.2 L", "12.4 V", "5.0 V", "3.2 V",
                     "2.1 A", "35 °C", "35,000 rpm", "50.0 frames/s", "250 frames", "CRC errors 0",
                     "protocol v4 (from the ECU)", "last frame 0.4 s ago"):
        assert expected in text, expected
    assert "STALE" not in text
    # 12 of 16 gauge cells for 75 % of max rpm, 8 for 50 % throttle
    assert "█" * 12 + "░" * 4 in text
    assert "█" * 8 + "░" * 8 in text


def test_fits_an_80_column_terminal():
    d = Dashboard(None, "ZK ECU  /dev/ttyUSB0")
    snap = running_snapshot(error_code=14, error_name="starter-controller-overheat")
    for i in range(100):
        d.update(dict(snap, time_s=i * 0.5, rpm=40000 + i * 1000), health(frames=i + 1))
    lines = text_of(d, width=80).splitlines()
    assert max(len(line) for line in lines) <= 80
    assert all("…" not in line for line in lines)   # nothing truncated


def test_unseen_values_are_dashes_not_zeros():
    d = Dashboard(None, "ZK")
    text = text_of(d)
    assert "RPM" in text and "—" in text
    assert " 0 rpm" not in text and "0 °C" not in text
    assert "last frame never" in text
    assert "0 frames" in text


def test_error_and_stale_link_are_spelled_out_and_coloured():
    clock = FakeClock()
    d = Dashboard(None, "ZK", clock=clock)
    d.update(running_snapshot(engine_state=12, engine_state_name="cooling", error_code=13,
                              error_name="loss-of-control-signal"),
             health(frames=10, frames_per_s=0.0, crc_errors=3, skipped=17, stale=True, version_source="default"))
    clock.t += 2.5
    plain = text_of(d)
    assert "COOLING" in plain
    assert "loss-of-control-signal (13)" in plain
    assert "STALE: no status frames for 2.5 s" in plain
    assert "CRC errors 3" in plain and "skipped 17 B" in plain
    assert "assumed until status ID 6" in plain
    assert "\x1b[" not in plain
    coloured = text_of(d, color=True)
    assert "\x1b[" in coloured
    # the error cell is white on red (background 41 / truecolor red background)
    line = next(ln for ln in coloured.splitlines() if "loss-of-control-signal" in ln)
    assert "41" in line or "48;2;128;0;0" in line


def test_age_of_last_frame_counts_while_nothing_arrives():
    clock = FakeClock()
    d = Dashboard(None, "ZK", clock=clock)
    d.update(running_snapshot(), health(frames=5))
    clock.t += 1.0
    d.update(running_snapshot(), health(frames=5))     # same count: no new frame
    clock.t += 2.0
    assert "last frame 3.0 s ago" in text_of(d)
    d.update(running_snapshot(), health(frames=6))
    assert "last frame 0.0 s ago" in text_of(d)


@pytest.mark.parametrize("name,style", [
    ("running", "bold green"), ("running-min-throttle", "bold green"), ("running-pump-limit", "bold yellow"),
    ("stop", "bold"), ("cooling", "bold cyan"), ("standby", "bold cyan"), ("ignition", "bold yellow"),
    ("preheat", "bold yellow"), ("test-pump", "bold magenta"), ("undocumented-25", "bold red"), (None, "dim"),
])
def test_state_styles(name, style):
    assert state_style(name) == style


def test_every_engine_state_has_a_style_and_renders():
    d = Dashboard(None, "ZK")
    for code, name in zk.ENGINE_STATES.items():
        d.update(running_snapshot(engine_state=code, engine_state_name=name), health())
        assert name.upper() in text_of(d, width=120)


def test_sparkline_scales_between_min_and_max():
    assert sparkline([0, 7, 14]) == "▁▅█"
    assert sparkline([0, 100]) == "▁█"
    assert sparkline([5, 5, 5]) == "▄▄▄"          # flat: mid height
    assert sparkline([None, 1, 2]) == " ▁█"
    assert sparkline([]) == ""
    assert sparkline([None]) == ""
    assert sparkline(range(100), width=10) == sparkline(range(90, 100))


def test_bar_and_fmt():
    assert bar(0.5, 10) == "█████░░░░░"
    assert bar(1.7, 4) == "████" and bar(-1, 4) == "░░░░" and bar(None, 2) == "░░"
    assert fmt(None, "V") == "—"
    assert fmt(12.4, "V") == "12.4 V"
    assert fmt(50, "%") == "50%"
    assert fmt(120000, "rpm", thousands=True) == "120,000 rpm"
    assert fmt(True) == "yes"


def test_history_keeps_one_point_per_interval_of_model_time():
    h = History(points=4, interval=0.5)
    for i in range(100):                 # 100 frames within the first 0.5 s: one point, the latest
        h.add(i * 0.004, i)
    assert list(h.values) == [99]
    for t, v in ((0.5, 1), (1.0, 2), (1.6, 3), (2.0, 4), (2.4, 5)):
        h.add(t, v)
    assert list(h.values) == [1, 2, 3, 5]     # maxlen 4; 2.0 and 2.4 share a slot
    h.add(3.0, None)                          # unseen values leave no point
    assert list(h.values) == [1, 2, 3, 5]
    assert h.span_s == 2.0


def test_units_come_from_the_codec_table():
    for s in zk.STATUS:
        for f in s.fields:
            assert dmod.UNITS[f.key] == f.unit


def test_context_manager_on_a_pipe_prints_the_final_view_once(monkeypatch):
    monkeypatch.delenv("FORCE_COLOR", raising=False)
    monkeypatch.setenv("NO_COLOR", "1")
    out = io.StringIO()
    with Dashboard(out, "ZK sim") as d:
        d.update(running_snapshot(), health(frames=1, frames_per_s=1.0))
    text = out.getvalue()
    assert text.count("ZK sim") == 1
    assert "RUNNING" in text and "120,000 rpm" in text
    assert "\x1b" not in text


def test_force_color_draws_live_with_escape_codes(monkeypatch):
    monkeypatch.delenv("NO_COLOR", raising=False)
    monkeypatch.setenv("FORCE_COLOR", "1")
    out = io.StringIO()
    with Dashboard(out, "ZK sim", refresh_per_second=50) as d:
        d.update(running_snapshot(), health(frames=1, frames_per_s=1.0))
        d.refresh()
    text = out.getvalue()
    assert "\x1b[?25l" in text             # cursor hidden while live ...
    assert "\x1b[?25h" in text             # ... and shown again at the end
    assert "\x1b[1;32mRUNNING" in text or "32m" in text


def test_no_color_wins_over_force_color(monkeypatch):
    monkeypatch.setenv("NO_COLOR", "1")
    monkeypatch.setenv("FORCE_COLOR", "1")
    out = io.StringIO()
    with Dashboard(out, "ZK sim") as d:
        d.update(running_snapshot(), health(frames=1))
    assert "RUNNING" in out.getvalue()
    assert "\x1b[" not in out.getvalue()


def test_updates_from_another_thread_while_rendering():
    d = Dashboard(None, "ZK")
    stop = threading.Event()
    errors = []

    def feed():
        i = 0
        while not stop.is_set():
            i += 1
            try:
                d.update(running_snapshot(time_s=i * 0.01, rpm=i * 10), health(frames=i))
            except Exception as e:  # pragma: no cover - the assertion below reports it
                errors.append(e)

    t = threading.Thread(target=feed)
    t.start()
    try:
        for _ in range(8):
            assert "RPM" in text_of(d)
    finally:
        stop.set()
        t.join()
    assert not errors
    assert len(d.rpm_history.values) > 1


def test_bridges_show_their_figures_under_the_link():
    d = Dashboard(None, "ZK")
    d.update(running_snapshot(), health(frames=5, bridges={
        "mavlink": {"submitted": 5, "dropped": 0},
        "mqtt": {"submitted": 10, "published": 8, "dropped": 2, "connected": False}}))
    text = text_of(d)
    assert "Bridge" in text and "mavlink: 5 records" in text
    assert "mqtt: 10 records, 8 published  dropped 2  broker away" in text
    d.update(running_snapshot(), health(frames=6))
    assert "Bridge" not in text_of(d)
@pytest.mark.parametrize("duration,t,expected", [
    (None, 12.34, "elapsed 12.3 s"),
    (15.0, 12.34, "elapsed 12.3 s of 15 s, 2.7 s left"),
    (15.0, 16.0, "elapsed 16.0 s of 15 s, 0.0 s left"),
])
def test_elapsed_and_remaining_time_of_a_timed_session(duration, t, expected):
    d = Dashboard(None, "zk send control run 40 % on sim://zk", clock=FakeClock(), duration=duration)
    d.update(running_snapshot(time_s=t), health(frames=10))
    text = text_of(d)
    assert expected in text
    if duration is None:
        assert "left" not in text
