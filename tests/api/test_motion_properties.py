"""Properties of path plans, over random paths (Hypothesis): what every plan the line accepts
keeps, checked against the rows it came from."""

from __future__ import annotations

import io

from hypothesis import given, settings, strategies as st

from zkzap.api import motion
from zkzap.errors import UsageError
from zkzap.link.port import wire_time

IDS = st.lists(st.integers(1, 12), min_size=1, max_size=6, unique=True)


@st.composite
def paths(draw):
    ids = draw(IDS)
    n = draw(st.integers(1, 6))
    times = sorted(set(draw(st.lists(st.integers(0, 400), min_size=n, max_size=n))))
    rows = []
    for t in times:
        who = draw(st.lists(st.sampled_from(ids), min_size=1, max_size=len(ids), unique=True))
        for i in who:
            rows.append((t / 100, i, draw(st.integers(0, 4095))))
    return rows


def _text(rows):
    return "t,id,position\n" + "".join(f"{t:g},{i},{p}\n" for t, i, p in rows)


@settings(max_examples=60, deadline=None)
@given(paths(), st.sampled_from([9600, 57600, 115200]))
def test_a_plan_sends_every_row_at_its_time_or_is_refused(rows, baud):
    parsed = motion.read_path(io.StringIO(_text(rows)), name="p")
    try:
        plan = motion.plan(parsed, baud=baud)
    except UsageError as e:
        assert "cannot carry" in str(e)
        return
    sent = {(s.t, i): g for s in plan.steps for i, g in s.goals.items()}
    assert sent == {(t, i): p for t, i, p in rows}
    for a, b in zip(plan.steps, plan.steps[1:]):
        assert b.t > a.t and sum(wire_time(len(f), baud) for f in a.frames) <= b.t - a.t
        assert all(f[3] == 0xFE and f[5] == 0x73 for f in a.frames)      # Symmetric Store, broadcast


@settings(max_examples=60, deadline=None)
@given(paths(), st.sampled_from([10, 25, 50]))
def test_linear_interpolation_passes_through_every_row_and_never_leaves_its_segment(rows, rate):
    parsed = motion.read_path(io.StringIO(_text(rows)), name="p")
    plan = motion.plan(parsed, interpolate="linear", rate=rate)
    track = {}
    for t, i, p in rows:
        track.setdefault(i, []).append((t, p))
    held = {}
    for step in plan.steps:
        assert abs(step.t * rate - round(step.t * rate)) < 1e-6 or step.t == plan.duration
        for i, g in step.goals.items():
            pts = track[i]
            assert step.t >= pts[0][0] - 1e-9                       # nothing before its first row
            before = [p for p in pts if p[0] <= step.t + 1e-9][-1]
            after = next((p for p in pts if p[0] >= step.t - 1e-9), pts[-1])
            assert min(before[1], after[1]) <= g <= max(before[1], after[1])
            held[i] = g
    for i, pts in track.items():                                    # each ends at its last row
        assert held[i] == pts[-1][1]
    for a, b in zip(plan.steps, plan.steps[1:]):
        assert b.t > a.t


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 1000), st.integers(1, 253), st.integers(0, 4095)), min_size=1,
                max_size=20, unique_by=lambda r: (r[0], r[1])))
def test_what_teach_writes_play_reads_back(rows):
    rows = sorted(({"t": t / 10, "id": i, "position": p} for t, i, p in rows), key=lambda r: r["t"])
    for fmt in ("csv", "jsonl", "json"):
        buf = io.StringIO()
        motion.write_path(buf, rows, fmt=fmt)
        back = motion.read_path(io.StringIO(buf.getvalue()), name="p")
        assert sorted((r.t, r.ids, r.position) for r in back) == sorted((r["t"], (r["id"],), r["position"])
                                                                       for r in rows)
