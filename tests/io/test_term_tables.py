"""Tables that fit the terminal: no value is cut, whatever the width; wide tables wrap their
text, and leave out their lowest-priority columns (named under the table) before they would cut
one; ``zk logbook`` at 80 columns read from a real terminal."""

from __future__ import annotations

import io
import re

import pytest
from hypothesis import given, settings, strategies as st

from zkzap.io.term import TEXT_MIN, _WHOLE, column_layout, fitted_table

number = st.one_of(st.integers(-10**7, 10**7).map(str),
                   st.floats(-1e6, 1e6, allow_nan=False).map(lambda v: f"{v:.3f}"),
                   st.just("2026-01-02 10:00:00"), st.just("-"))
word = st.text("abcdefghij_-/", min_size=1, max_size=30)
text = st.lists(word, min_size=1, max_size=5).map(" ".join)


def render(table, width):
    from rich.console import Console

    buf = io.StringIO()
    Console(file=buf, width=width, color_system=None, legacy_windows=False).print(table)
    return buf.getvalue().splitlines()


@settings(max_examples=60, deadline=None)
@given(kinds=st.lists(st.booleans(), min_size=1, max_size=12), n=st.integers(1, 6), width=st.integers(40, 160),
       data=st.data())
def test_no_value_is_cut_at_any_width(kinds, n, width, data):
    headings = [f"col {i}" for i in range(len(kinds))]
    rows = [[data.draw(number if k else text) for k in kinds] for _ in range(n)]
    style, keep, widths = column_layout(headings, rows, width)
    lines = render(fitted_table(headings, rows, width), width)
    assert all(len(line) <= width for line in lines), "\n".join(lines)
    assert "…" not in "\n".join(lines)
    flat = " ".join(lines)
    for i in keep:
        for r in rows:
            for w in r[i].split():
                if re.fullmatch(_WHOLE, w) or len(w) <= TEXT_MIN:
                    assert w in flat, (w, "\n".join(lines))            # a number, a time, a name: on one line
    left_out = [headings[i] for i in range(len(headings)) if i not in keep]
    if left_out:
        assert f"left out at {width} columns: {', '.join(left_out)}" in " ".join(x.strip() for x in lines)
    if widths is None:
        assert style == "boxed" and keep == list(range(len(headings)))


def test_the_lowest_priority_goes_first_and_a_fitting_table_is_untouched():
    headings = ["a", "b", "c", "d"]
    rows = [["1" * 20, "2" * 20, "3" * 20, "4" * 20]]
    assert column_layout(headings, rows, 200) == ("boxed", [0, 1, 2, 3], None)
    style, keep, _ = column_layout(headings, rows, 70, priority=[0, -1, 0, 0])
    assert keep == [0, 2, 3]                     # b, the lowest, left out; then the last of equal ones
    assert column_layout(headings, rows, 50, priority=[0, -1, 0, 0])[1] == [0, 2]


def test_logbook_at_80_columns_in_a_terminal(tmp_path):
    from tmuxterm import have_tmux, run_in_terminal, zk

    if not have_tmux():
        pytest.skip("tmux is not installed (apt-get install tmux); it is the terminal this test reads")
    from zkzap.api import logbook as lb

    db = str(tmp_path / "k100.db")
    runs = [("K100-1234", "zk profile stand.csv", "completed", 2460.4, 2100.7, 112345, 745.5, 0.1 + 0.2),
            ("K100-1234", "zk monitor --duration 60", "duration", 61.2, 0.0, 3400, 21.0, 0.0),
            ("P400-SN99812", "zk send --for 30 throttle 50", "aborted: limit egt_c 850 > 800", 4460.0, 3901.2,
             151234, 851.0, 12.3456),
            (None, "zk profile /very/long/path/to/the/schedules/endurance-cycle-2026.csv", "interrupted", 10.0,
             0.0, 0, 20.0, None)]
    for i, (eng, cmd, out, dur, running, rpm, egt, fuel) in enumerate(runs):
        lb.record(db, {"started": f"2026-01-0{i + 1}T10:00:00Z", "ended": f"2026-01-0{i + 1}T11:00:00Z",
                       "duration_s": dur, "running_s": running, "starts": i, "max_rpm": rpm, "max_egt_c": egt,
                       "fuel_used_l": fuel, "errors": ["egt-high"] if i == 2 else [],
                       "limits_violated": ["egt_c<=800"] if i == 2 else [], "command": cmd, "port": "/dev/ttyUSB0",
                       "schedule": None, "files": [], "outcome": out, "exit_status": 0, "engine": eng})
    status, lines = run_in_terminal(zk("logbook", db), width=80)
    screen = "\n".join(lines)
    assert status == 0, screen
    assert all(len(line) <= 80 for line in lines) and "…" not in screen, screen
    body = [ln for ln in lines if re.match(r"\d+ +2026-", ln)]
    assert [ln.split()[0] for ln in body] == ["1", "2", "3", "4"], screen
    for value in ("2026-01-03", "10:00:00", "3901", "151234", "851", "P400-SN99812", "K100-1234"):
        assert re.search(rf"(?<![\w.]){re.escape(value)}(?![\w.])", screen), (value, screen)
    assert "aborted:" in screen and "interrupted" in screen   # the outcome wraps, never cut
    # the lowest priorities left out, named: the session's time and the command (fuel too, beside
    # a 12-character engine name)
    assert re.search(r"left out at 80 columns: time s, (fuel L, )?command", " ".join(x.strip() for x in lines)), \
        screen
    totals = " ".join(x.strip() for x in lines[lines.index(next(x for x in lines if x.startswith("totals:"))):])
    assert "12.646 L fuel" in totals.replace("\u00a0", " ") and "max rpm 151234" in totals.replace("\u00a0", " ")
    # the totals alone: a row per figure, whole at 80 columns
    status, lines = run_in_terminal(zk("logbook", db, "--totals"), width=80)
    screen = "\n".join(lines)
    assert status == 0 and "left out" not in screen and all(len(x) <= 80 for x in lines), screen
    assert re.search(r"│ fuel_used_l +│ 12.646 +│", screen) and re.search(r"│ max_rpm +│ 151234 +│", screen), screen
    # at 160 columns every column is there, boxed as before
    status, wide = run_in_terminal(zk("logbook", db), width=160)
    wide = "\n".join(wide)
    assert status == 0 and "left out" not in wide and "┃ command" in wide and "│ 12.346 │" in wide, wide
    assert "0.30000000000000004" not in wide and "│ 0.3 " in wide       # the fuel counter's difference, rounded
