"""zk report: a profile run rendered to PNG, SVG, PDF and self-contained HTML, from its CSV and from its
raw log; skipped plots named; matplotlib optional; the terminal view."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys

import pytest

pytest.importorskip("matplotlib")

from zkzap.io import report as R   # noqa: E402

SIM = "sim://zk?speed=20"
ALL_PANELS = ["Engine speed", "Exhaust gas temperature", "Thrust", "Throttle", "Fuel flow", "Voltages"]


def _profile(d, name, url, extra=()):
    from click.testing import CliRunner

    from zkzap.commands import root, run as run_cli

    sched = d / "stand.csv"
    sched.write_text("0,0,run\n20,40\n28,80\n36,0,standby\n40,0,standby\n")    # model seconds
    files = {k: str(d / f"{name}-{n}") for k, n in (("tel", "tel.csv"), ("raw", "raw.bin"), ("steps", "steps.csv"),
                                                   ("summary", "summary.json"))}
    with CliRunner().isolation():
        code = run_cli(root, "zkzap", ["zk", "profile", str(sched), "-p", url, "-o", files["tel"], "--raw-log",
                                       files["raw"], "--settle", "4", "--steps-csv", files["steps"],
                                       "--summary-json", files["summary"], *extra])
    assert code == 0
    files["dir"] = d
    return files


@pytest.fixture(scope="module")
def other(tmp_path_factory):
    """A second run, of an engine with less thrust and a lower redline, for comparisons."""
    return _profile(tmp_path_factory.mktemp("other"), "b", SIM + "&max_thrust=11&max_rpm=150000")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One short profile run with every output a report reads."""
    from click.testing import CliRunner

    from zkzap.commands import root, run as run_cli

    d = tmp_path_factory.mktemp("run")
    sched = d / "stand.csv"
    sched.write_text("0,0,run\n20,40\n28,80\n36,0,standby\n40,0,standby\n")    # model seconds
    files = {k: str(d / n) for k, n in (("tel", "tel.csv"), ("raw", "raw.bin"), ("steps", "steps.csv"),
                                        ("summary", "summary.json"))}
    with CliRunner().isolation():
        code = run_cli(root, "zkzap", ["zk", "profile", str(sched), "-p", SIM, "-o", files["tel"], "--raw-log",
                                       files["raw"], "--settle", "4", "--steps-csv", files["steps"],
                                       "--summary-json", files["summary"], "--limit", "egt_c<=600",
                                       "--on-limit", "warn"])
    import json

    violated = any(x["verdict"] == "violated" for x in json.loads(open(files["summary"]).read())["limits"])
    assert code == (5 if violated else 0)             # --on-limit warn: the run goes on, its status says so
    files["dir"] = d
    return files


def test_png_report_with_every_plot(cli, run):
    out = run["dir"] / "report.png"
    r = cli("zk", "report", run["tel"], "--steps", run["steps"], "--summary", run["summary"], "-o", str(out),
            "--title", "K-100 acceptance", "--meta", "engine=K-100", "--meta", "serial=1234")
    assert r.exit_code == 0 and r.stdout == "" and "skipped" not in r.stderr, r
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 50_000
    panels, step_plots, skipped = R.plan(R.load_run(run["tel"]), R.load_steps(run["steps"]))
    assert [p[0] for p in panels] == ALL_PANELS and skipped == []
    assert [p[0] for p in step_plots] == ["Thrust vs rpm", "EGT vs rpm", "TSFC vs thrust"]
    assert ("target_throttle_pct", "target") in panels[3][2]


def test_html_report_is_one_self_contained_file(cli, run):
    out = run["dir"] / "report.html"
    r = cli("zk", "report", run["tel"], "--steps", run["steps"], "--summary", run["summary"], "-o", str(out),
            "--meta", "engine=K-100")
    assert r.exit_code == 0, r
    html = out.read_text()
    for marker in ('id="summary"', 'id="time-histories"', 'id="steady-state"', 'id="steps"', "<svg"):
        assert marker in html
    assert "Time histories: " + ", ".join(ALL_PANELS) in html
    assert "Thrust vs rpm, EGT vs rpm, TSFC vs thrust" in html
    assert "limit violated: egt_c&lt;=600" in html and "K-100" in html
    assert "src=\"http" not in html and "<link" not in html and "<script" not in html
    assert html.count("<svg") == 2


@pytest.mark.parametrize("ext,magic", [("svg", b"<?xml"), ("pdf", b"%PDF")])
def test_svg_and_pdf_from_the_raw_log(cli, run, ext, magic):
    out = run["dir"] / f"raw.{ext}"
    r = cli("zk", "report", run["raw"], "-o", str(out))
    assert r.exit_code == 0, r
    assert out.read_bytes()[:len(magic)] == magic
    panels, _, skipped = R.plan(R.load_run(run["raw"]))
    assert [p[0] for p in panels] == ALL_PANELS
    assert "skipped steady-state plots" in r.stderr and skipped[0].startswith("steady-state plots")


def test_a_pcapng_capture_is_a_run_with_its_own_times(cli, run, tmp_path):
    cap = tmp_path / "run.pcapng"
    r = cli("zk", "monitor", "-p", SIM, "--duration", "20", "-f", "jsonl", "-o", str(tmp_path / "m.jsonl"),
            "--capture", str(cap))
    assert r.exit_code == 0, r
    loaded = R.load_run(str(cap))
    assert len(loaded.t) > 100 and loaded.t[0] == 0.0 and loaded.t[-1] > 0.5      # the capture's real times
    out = tmp_path / "cap.png"
    r = cli("zk", "report", str(cap), "-o", str(out))
    assert r.exit_code == 0, r
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_missing_columns_say_which_plots_were_skipped(cli, run, tmp_path):
    tel = tmp_path / "ids1.jsonl"
    import csv

    with open(run["tel"], encoding="utf-8") as f:
        rows = [{k: row[k] for k in ("t", "rpm", "egt_c", "engine_state_name")} for row in csv.DictReader(f)]
    tel.write_text("".join(json.dumps(r) + "\n" for r in rows))
    out = tmp_path / "r.png"
    r = cli("zk", "report", str(tel), "-o", str(out))
    assert r.exit_code == 0 and out.exists()
    assert f"skipped thrust: {tel} has no column thrust_kg" in r.stderr
    assert "skipped voltages" in r.stderr and "skipped engine speed" not in r.stderr


def test_terminal_view(cli, run):
    r = cli("zk", "report", run["tel"], "--terminal")
    assert r.exit_code == 0 and "Engine speed — rpm" in r.stdout and "Voltages" in r.stdout and "█" in r.stdout


@pytest.mark.parametrize("width", [100, 80])
def test_terminal_comparison_overlays_runs_and_fits_its_table(run, other, width):
    """Two runs on a real terminal: one panel per quantity with both runs overlaid (each in its
    mark), and their steps side by side with every value whole."""
    from tmuxterm import have_tmux, run_in_terminal, zk

    if not have_tmux():
        pytest.skip("tmux is not installed (apt-get install tmux); it is the terminal this test reads")
    status, lines = run_in_terminal(zk("report", run["tel"], other["tel"], "--steps", run["steps"], "--steps",
                                       other["steps"], "--label", "serial-1", "--label", "serial-2",
                                       "--terminal"), width=width, height=200)
    screen = "\n".join(lines)
    assert status == 0, screen
    assert all(len(line) <= width for line in lines) and "…" not in screen, screen
    assert screen.count("Engine speed — rpm") == 1 and screen.count("Thrust — thrust (kgf)") == 1, screen
    assert "#1 • serial-1" in screen and "#2 × serial-2" in screen
    chart = screen[screen.index("Engine speed"):screen.index("Exhaust gas")]
    assert "•" in chart and "×" in chart                 # both runs drawn on the one panel
    table = screen[screen.index("Steps side by side"):]
    assert re.search(r"step\s+.\s+target\s+.\s+quantity\s+.\s+#1\s+.\s+#2\s+.\s+Δ #2", table), table
    runs = [R.load_run(p) for p in (run["tel"], other["tel"])]
    for x, p in zip(runs, (run["steps"], other["steps"])):
        x.steps = R.load_steps(p)
    for n, target, quantities in R.compared_steps(runs):
        for label, values, diffs in quantities:
            for v in values + [d.split()[0] for d in diffs]:
                assert re.search(rf"(?<![\w.]){re.escape(v)}(?![\w.])", table), (label, v, table)
    assert R.UNSETTLED_NOTE in " ".join(x.strip(" │") for x in lines)


def _without(monkeypatch, package):
    """``package`` made unimportable, as when its extra is not installed."""
    for name in list(sys.modules):
        if name == package or name.startswith(package + "."):
            monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, package, None)


def test_without_matplotlib_names_the_extra(cli, run, monkeypatch):
    _without(monkeypatch, "matplotlib")
    out = run["dir"] / "none.png"
    r = cli("zk", "report", run["tel"], "-o", str(out))
    assert r.exit_code == 2 and "pip install 'zkzap[plot]'" in r.stderr and not out.exists()
    assert cli("zk", "report", run["tel"], "--terminal").exit_code == 0


def test_interactive_without_plotly_names_the_extra(cli, run, monkeypatch):
    _without(monkeypatch, "plotly")
    out = run["dir"] / "none.html"
    r = cli("zk", "report", run["tel"], "-o", str(out), "--interactive")
    assert r.exit_code == 2 and "pip install 'zkzap[interactive]'" in r.stderr and not out.exists(), r
    assert r.stdout == ""
    r = cli("zk", "report", run["tel"], "-o", str(run["dir"] / "x.png"), "--interactive")
    assert r.exit_code == 2 and "interactive: an HTML report" in r.stderr
    assert cli("zk", "report", run["tel"], "--terminal", "--interactive").exit_code == 2


def test_interactive_page_thins_a_long_series_keeping_its_peaks():
    pytest.importorskip("plotly")
    from zkzap.io.report_interactive import thin

    t = [i * 0.01 for i in range(100_000)]
    v = [math.sin(x) + (5.0 if i == 54_321 else 0.0) for i, x in enumerate(t)]
    xs, ys, cut = thin(t, v, limit=2_000)
    assert cut and len(xs) <= 2_000 and xs == sorted(xs)
    assert max(ys) == max(v) and min(ys) == min(v) and xs[ys.index(max(ys))] == t[54_321]
    assert thin(t[:10], [1.0, math.nan] * 5)[1:] == ([1.0, None] * 5, False)


def test_other_commands_never_import_plotting_or_sqlite(tmp_path):
    cli_dir = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "cli")
    sched = tmp_path / "s.csv"
    sched.write_text("0,10,run\n5,0,standby\n")
    code = ("import sys; from zkzap import commands; sys.argv=['zk','monitor','--sim','--count','3','-f','jsonl'];"
            "import atexit; atexit.register(lambda: print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('matplotlib','numpy','sqlite3','plotext')), file=sys.stderr)); commands.zk_main()")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       env=dict(os.environ, PYTHONPATH=cli_dir))
    assert p.returncode == 0, p.stderr
    assert p.stderr.strip().splitlines()[-1] == "[]"


def test_two_runs_compared_aligned_at_a_step(cli, run, other):
    out = run["dir"] / "cmp.html"
    r = cli("zk", "report", run["tel"], other["tel"], "--steps", run["steps"], "--steps", other["steps"],
            "--summary", run["summary"], "--summary", other["summary"], "--label", "serial 1", "--label", "serial 2",
            "--align", "step:1", "-o", str(out))
    assert r.exit_code == 0 and "skipped" not in r.stderr, r
    html = out.read_text()
    assert "Runs compared: serial 1, serial 2" in html and 'id="step-comparison"' in html
    assert "rpm — serial 1" in html and "rpm — serial 2" in html                  # the legend names each run
    assert html.count("<svg") == 2 and "Δ serial 2" in html
    runs = [R.load_run(p) for p in (run["tel"], other["tel"])]
    for x, p in zip(runs, (run["steps"], other["steps"])):
        x.steps = R.load_steps(p)
    R.align(runs, "step:1")
    assert [x.offset for x in runs] == [20.0, 20.0]
    header, rows = R.step_comparison(runs)
    i, j = header.index(f"thrust kgf {runs[0].label}"), header.index(f"thrust kgf {runs[1].label}")
    a, b = float(rows[1][i].rstrip("*")), float(rows[1][j].rstrip("*"))
    assert rows[1][j + 1].startswith(f"{b - a:+.2f} (")                          # the difference, and how much
    if all(x.steps[1].get("settled") == "true" for x in runs):
        assert b < a                             # 80 %: the weaker engine gives less thrust (when both settled)
    png = run["dir"] / "cmp.png"
    r = cli("zk", "report", run["tel"], other["tel"], "--summary", run["summary"], "--summary", other["summary"],
            "--align", "running", "-o", str(png))
    assert r.exit_code == 0 and png.read_bytes()[:4] == b"\x89PNG", r            # the summaries' steps serve


def test_limits_and_step_windows_on_the_plots(cli, run, tmp_path):
    lim = tmp_path / "engine.limits"
    lim.write_text("ecu_temp_c <= 85, warn=70\nrpm <= 165000\n")
    out = tmp_path / "lim.svg"
    title = "K-100 #1234 acceptance run on stand 4 with the revised start schedule and the new fuel nozzles " * 2
    r = cli("zk", "report", run["tel"], "--steps", run["steps"], "--summary", run["summary"], "--limits", str(lim),
            "-o", str(out), "--title", title)
    assert r.exit_code == 0 and r.stderr == "", r
    svg = out.read_text()
    for text in ("limit ecu_temp_c &lt;= 85, warn=70", "warning &lt;= 70", "limit &lt;= 165000",
                 "limit egt_c&lt;=600", "averaging window", "settling"):
        assert text in svg, text
    loaded = R.load_run(run["tel"], extra=["ecu_temp_c"])
    panels, _, _ = R.plan(loaded, R.load_steps(run["steps"]), limits=[("ecu_temp_c<=85", "ecu_temp_c", "<=", 85, 70)])
    assert panels[-1][0] == "ecu_temp_c"                     # a limited field without a panel gets one
    steps = R.load_steps(run["steps"])
    assert [s["target"] for s in steps] == ["40 %", "80 %"]   # no start-up, no standby rows


def test_a_run_on_stdin(sh, run, tmp_path):
    out = tmp_path / "stdin.png"
    with open(run["tel"], "rb") as f:
        data = f.read()
    r = sh("zk", "report", "-", "-o", str(out), input=data.decode())
    assert r.exit_code == 0 and out.read_bytes()[:4] == b"\x89PNG", r
    r = sh("zk", "report", "-", "--terminal", input="not a run\n")
    assert r.exit_code == 2 and "run: stdin: expected the CSV" in r.stderr


def test_runs_aligned_at_start_keep_their_session_time_and_first_at_their_first_record():
    from zkzap.io import report as R

    early, late = R.Run("early"), R.Run("late")
    for t in (0.5, 1.0, 1.5):
        early.add({"t": t, "rpm": 1000})
    for t in (4.0, 4.5):
        late.add({"t": t, "rpm": 1000})
    R.align([early, late], "start")
    assert (early.offset, late.offset) == (0.0, 0.0)
    R.align([early, late], "first")
    assert (early.offset, late.offset) == (0.5, 4.0)


def test_an_aborted_run_draws_its_targets_and_windows_until_the_trip_only():
    """The rundown after a trip is recorded; the schedule's targets stop where it tripped."""
    from zkzap.io import report as R

    run = R.Run("tripped")
    for k in range(40):                                        # the run, then its rundown to t=20
        t = k * 0.5
        if t == 10.0:
            run.add({"time": "", "t": 10.0, "kind": "trip", "trip": "limit violated; sent standby, throttle 0"})
        run.add({"t": t, "kind": "status", "id": 1, "rpm": 50000 if t < 10 else 20000})
    run.add({"t": 19.9, "trip": "rundown 9.9 s: the engine at rest (state standby)"})     # a CSV row's trip column
    assert run.trip_t == 10.0 and len(run.t) == 40 and R._sent_until(run) == 10.0
    untripped = R.Run("whole")
    untripped.add({"t": 3.0, "kind": "status", "id": 1, "rpm": 1})
    assert R._sent_until(untripped) == 3.0


def test_the_png_header_wraps_long_values_and_cuts_none(run, other, tmp_path):
    """A comparison's header with long file names, a long --meta value and long summary values:
    every value is in its cell whole (wrapped to its column, not cut), and every cell's text is
    drawn inside its cell and its figure."""
    import shutil

    long_a = tmp_path / ("stand-2026-12-03-K100-1234-morning-session-after-the-rebuild-" + "x" * 40 + "-run-01.csv")
    long_b = tmp_path / "stand-2026-12-03-K100-1234-afternoon-session-after-nozzle-change-run-02.csv"
    shutil.copy(run["tel"], long_a)
    shutil.copy(other["tel"], long_b)
    runs = [R.load_run(str(p)) for p in (long_a, long_b)]
    for x, s in zip(runs, (run["summary"], other["summary"])):
        x.summary = R.load_summary(s)
        x.summary["states"] = x.summary["states"] * 3          # a long value of the summary's own
    meta = [("operator", "J. Example, test cell 3, witnessed by the customer representative of the overhaul "
                         "shop on the second day of the acceptance tests")]
    rows = R.header_rows(runs, meta)
    fig = R.figure_all(runs, [], [], [], "Runs compared", meta)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    fig.set_dpi(110)
    canvas.draw()                                              # lays the figure out, as savefig does
    renderer = canvas.get_renderer()
    fig_box = fig.bbox
    table = fig.axes[0].tables[0]
    cells = table.get_celld()
    labels = [""] + [f"#{k + 1} {r.label}" for k, r in enumerate(runs)]
    for (i, j), cell in cells.items():
        want = labels[j] if i == 0 else rows[i - 1][j]
        got = cell.get_text().get_text()
        # every character there (the wrap breaks lines at spaces, which it drops, or after separators)
        assert "".join(got.split()) == "".join(str(want).split()), (got, want)
        text_box = cell.get_text().get_window_extent(renderer)
        cell_box = cell.get_window_extent(renderer)
        assert text_box.x0 >= cell_box.x0 - 1 and text_box.x1 <= cell_box.x1 + 1, (got, text_box, cell_box)
        assert text_box.y0 >= cell_box.y0 - 1 and text_box.y1 <= cell_box.y1 + 1, (got, text_box, cell_box)
        assert fig_box.x0 <= text_box.x0 and text_box.x1 <= fig_box.x1
    assert cells[(1, 1)].get_text().get_text().count("\n") >= 1              # the meta value wrapped
    assert cells[(0, 1)].get_text().get_text().count("\n") >= 1              # the long file name too


def test_a_long_series_is_drawn_decimated_keeping_its_peaks_and_gaps():
    """Drawing a million-record history: each pixel column's minimum and maximum, in time order
    (every peak and dip stays, a gap stays a gap); the numbers never come from it."""
    import numpy as np

    n = 1_000_000
    t = np.arange(n) * 0.01
    v = np.sin(t / 50.0) * 100.0
    v[123_457] = 1e4                       # a one-record spike
    v[765_431] = -1e4                      # and a dip
    v[400_000:420_000] = np.nan            # a gap of 200 s (longer than a bin)
    xs, ys = R.decimate(t, v)
    assert len(xs) <= 2 * R.DRAW_BINS + R.DRAW_BINS and np.all(np.diff(xs) > 0)
    assert np.nanmax(ys) == 1e4 and xs[np.nanargmax(ys)] == t[123_457]
    assert np.nanmin(ys) == -1e4 and xs[np.nanargmin(ys)] == t[765_431]
    gap = np.isnan(ys)
    assert gap.any() and np.all((xs[gap] >= t[400_000]) & (xs[gap] < t[420_000]))
    # every point drawn is one of the series' own
    assert np.array_equal(ys[~gap], v[np.searchsorted(t, xs[~gap])])
    short_t, short_v = R.decimate(t[:1000], v[:1000])
    assert len(short_t) == 1000                              # a short series is drawn whole
