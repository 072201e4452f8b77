"""The interactive HTML report (``zk report RUN -o report.html --interactive``): the report's
time histories and steady-state plots as plotly figures — zoom and pan (the time histories share
one time axis: zooming one zooms all), and a readout of every line at the cursor's time — on the
page of the static HTML report (title, summary, step tables).

plotly is an optional extra (``pip install 'zkzap[interactive]'``), imported only here. The page
is one self-contained file: plotly.js is inlined (about 4.8 MB), so it opens offline, as a test
sheet's attachment must. A series longer than :data:`MAX_POINTS` is thinned to the minimum and
maximum of each of :data:`MAX_POINTS` / 2 time bins (no peak is lost), and the page says so.
"""

from __future__ import annotations

from ..errors import UsageError
from . import report as R

MISSING_EXTRA = "zk report --interactive needs plotly: pip install 'zkzap[interactive]'"
#: The points a line of the page holds at most (a longer series keeps each bin's extremes).
MAX_POINTS = 20_000
#: Each time-history panel's height on the page (px).
PANEL_PX = 210
_CONFIG = {"displaylogo": False, "scrollZoom": True, "responsive": True,
           "toImageButtonOptions": {"format": "png", "scale": 2}}


def require():
    """The plotly modules (``graph_objects``, ``subplots``); a UsageError naming the extra without them."""
    try:
        import plotly.graph_objects as go
        from plotly.subplots import make_subplots
    except ImportError:
        raise UsageError(MISSING_EXTRA) from None
    return go, make_subplots


def thin(t, v, limit=MAX_POINTS):
    """``(t, v, thinned)``: the series as lists (None for NaN), or — longer than ``limit`` — the
    minimum and maximum of each of ``limit / 2`` equal time bins, in time order (a line through
    them draws every peak the full series has; :func:`zkzap.io.report.decimate`)."""
    if len(t) <= limit:
        return list(t), [None if x != x else x for x in v], False
    xs, ys = R.decimate(t, v, max(limit // 2, 1))
    return xs.tolist(), [None if y != y else y for y in ys.tolist()], True


def _unit_of(label):
    """The unit in a panel's axis label: ``EGT (°C)`` -> ``°C``; ``rpm`` -> ``rpm``."""
    return label[label.rindex("(") + 1:-1] if label.endswith(")") and "(" in label else label


def _histories(go, runs, panels, limits):
    """The time histories: a panel per quantity, stacked on ONE time axis (zoom one, zoom all;
    the readout at the cursor lists every panel's lines at that time)."""
    many = len(runs) > 1
    ref = runs[0]
    n = len(panels)
    gap = min(0.05, 0.3 / max(n, 1))
    size = (1.0 - gap * (n - 1)) / n
    domains = [(1.0 - (i + 1) * size - i * gap, 1.0 - i * size - i * gap) for i in range(n)]
    fig = go.Figure()
    layout = {}
    thinned = []
    times = [[x - run.offset for x in run.t] for run in runs]

    def yref(i):
        return "y" if i == 0 else f"y{i + 1}"

    for i, (title, unit, lines) in enumerate(panels):
        axis = {"domain": [max(domains[i][0], 0.0), domains[i][1]], "title": {"text": unit, "font": {"size": 11}}}
        layout["yaxis" if i == 0 else f"yaxis{i + 1}"] = axis
        fig.add_annotation(text=f"<b>{title}</b>", x=0, xref="paper", xanchor="left", y=domains[i][1],
                           yref="paper", yanchor="bottom", showarrow=False, font={"size": 12})
        show = f"%{{y:.6~g}} {_unit_of(unit)}"
        for k, run in enumerate(runs):
            targets = R._targets(run.steps) if run.steps else {}
            for j, (c, label) in enumerate(lines):
                name = f"{label} — {run.label}" if many else label
                if c in targets:
                    if many and k:
                        continue                     # the reference run's targets
                    xs, ys = R.target_line(run, targets[c])
                    fig.add_trace(go.Scatter(x=xs, y=[None if y != y else y for y in ys], name=label, mode="lines",
                                             line={"color": "black", "dash": "dash", "width": 1}, yaxis=yref(i),
                                             legendgroup=title, legendgrouptitle_text=title, hovertemplate=show))
                elif c in run.present:
                    xs, ys, cut = thin(times[k], run.series[c])
                    if cut:
                        thinned.append(f"{name} ({len(times[k])} points)")
                    line = {"width": 1.4}
                    if many:
                        line["color"] = R.RUN_COLOURS[k % len(R.RUN_COLOURS)]
                        if j:
                            line["dash"] = ("dot", "dashdot", "dash")[(j - 1) % 3]
                    fig.add_trace(go.Scatter(x=xs, y=ys, name=name, mode="lines", line=line, yaxis=yref(i),
                                             legendgroup=title, legendgrouptitle_text=title, hovertemplate=show))
        fields = {c for c, _ in lines}
        for text, field, op, threshold, warn in limits:
            if field not in fields:
                continue
            up = warn is None or threshold >= warn
            for level, colour, dash, what, above in ((threshold, R.LIMIT_COLOUR, "solid", "limit", up),
                                                     (warn, R.WARN_COLOUR, "dash", "warn", not up)):
                if level is None:
                    continue
                fig.add_shape(type="line", xref="x domain", x0=0, x1=1, yref=yref(i), y0=level, y1=level,
                              line={"color": colour, "width": 1, "dash": dash})
                fig.add_annotation(text=f"{what} {op} {level:g}", xref="x domain", x=1, xanchor="right",
                                   yref=yref(i), y=level, yanchor="bottom" if above else "top", showarrow=False,
                                   font={"size": 10, "color": colour})
    t_end = ref.t[-1] if len(ref.t) else 0.0
    keys = {}                                        # the shades' legend: {name: colour}

    def shade(x0, x1, colour, opacity):
        for i in range(n):
            fig.add_shape(type="rect", xref="x", x0=x0, x1=x1, yref=f"{yref(i)} domain", y0=0, y1=1,
                          fillcolor=colour, opacity=opacity, layer="below", line_width=0)

    if not many:
        for t0, t1, group, colour in R.state_spans(ref, t_end):
            keys.setdefault(f"state: {group}", colour)
            shade(t0, t1, colour, 1.0)
    for step, a, w0, w1, ok in R.step_windows(ref) if ref.steps else ():
        if w0 > a:                                   # the settle time: hatched on paper, grey here
            keys.setdefault("settling", R.SETTLING_COLOUR)
            shade(a, w0, R.SETTLING_COLOUR, 0.35)
        if w1 > w0:
            colour = R.WINDOW_COLOURS[0 if ok else 1]
            keys.setdefault("averaging window" if ok else "averaging window (not settled)", colour)
            shade(w0, w1, colour, 0.55)
        fig.add_annotation(x=(a + max(w1, a)) / 2, xref="x", y=1.0, yref="y domain", text=f"<b>{step}"
                           f"{'' if ok else '*'}</b>", showarrow=False, yanchor="bottom",
                           font={"size": 11, "color": "#34495e" if ok else "#a61c00"})
    for k, run in enumerate(runs):
        for text, et in R._limit_times(run, run.summary):
            who = f" ({run.label})" if many else ""
            fig.add_shape(type="line", xref="x", x0=et - run.offset, x1=et - run.offset, yref="paper", y0=0, y1=1,
                          line={"color": "red", "width": 1.2})
            fig.add_annotation(x=et - run.offset, xref="x", y=0, yref="y domain", text=f"limit violated: {text}{who}",
                               showarrow=False, textangle=-90, xanchor="right", yanchor="bottom",
                               font={"size": 10, "color": "red"})
    for name, colour in keys.items():                # a shade is no trace: a key for it in the legend
        fig.add_trace(go.Scatter(x=[None], y=[None], mode="markers", name=name, hoverinfo="skip",
                                 marker={"symbol": "square", "size": 12, "color": colour}, legendgroup="shades",
                                 legendgrouptitle_text="Shading"))
    what = {"start": "the start", "running": "the engine's first running state"}
    aligned = getattr(ref, "aligned", "start")
    xaxis = {"title": {"text": "time since " + what.get(aligned, f"the start of {aligned.replace(':', ' ')}")
                       + " (s)"}, "anchor": yref(n - 1), "showspikes": True, "spikemode": "across",
             "spikesnap": "cursor", "spikethickness": 1, "spikedash": "solid", "spikecolor": "#777"}
    starts = [min(run.t) - run.offset for run in runs if len(run.t)]
    ends = [run.t[-1] - run.offset for run in runs if len(run.t)]
    if ends and max(ends) > min(starts):
        xaxis["range"] = [min(min(starts), 0.0), max(ends)]       # the plots stop where the runs did
    fig.update_layout(xaxis=xaxis, **layout, height=PANEL_PX * n + 120, hovermode="x unified",
                      hoversubplots="axis", template="plotly_white", margin={"l": 70, "r": 20, "t": 30, "b": 50},
                      legend={"groupclick": "toggleitem"})
    return fig, thinned


def _steady(go, make_subplots, step_plots):
    """The steady-state plots: settled steps joined, unsettled ones hollow; each point's step in its readout."""
    fig = make_subplots(rows=1, cols=len(step_plots), subplot_titles=[p[0] for p in step_plots],
                        horizontal_spacing=0.08)
    many = any(len(series) > 1 for *_, series in step_plots)
    for i, (title, xl, yl, series) in enumerate(step_plots, 1):
        for k, (name, pts) in enumerate(series):
            colour = R.RUN_COLOURS[k % len(R.RUN_COLOURS)]
            who = f" — {name}" if many else ""
            for ok in (True, False):
                sel = [p for p in pts if p[2] == ok]
                if not sel:
                    continue
                fig.add_trace(go.Scatter(
                    x=[p[0] for p in sel], y=[p[1] for p in sel], name=("settled steps" if ok else "never settled")
                    + who, mode="lines+markers" if ok else "markers", legendgroup=f"{name}{ok}", showlegend=i == 1,
                    marker={"color": colour if ok or many else "grey", "size": 8,
                            "symbol": "circle" if ok else "circle-open"}, line={"color": colour, "width": 1},
                    hovertemplate=f"{xl} %{{x:.6~g}}<br>{yl} %{{y:.6~g}}<extra>{name}</extra>"), row=1, col=i)
        fig.update_xaxes(title_text=xl, row=1, col=i)
        fig.update_yaxes(title_text=yl, row=1, col=i)
    fig.update_layout(height=380, template="plotly_white", hovermode="closest",
                      margin={"l": 70, "r": 20, "t": 40, "b": 50})
    return fig


def page(runs, panels, step_plots, limits, title, meta) -> str:
    """The interactive report of ``runs`` as one self-contained HTML page."""
    from html import escape

    go, make_subplots = require()
    figures = []
    js = True                                        # plotly.js once, inlined in the first figure
    if panels:
        fig, thinned = _histories(go, runs, panels, limits)
        note = ("<p class=\"note\">Thinned to each time bin's minimum and maximum (every peak kept): "
                + escape(", ".join(thinned)) + ".</p>") if thinned else ""
        figures.append("<figure id=\"time-histories\"><figcaption>Time histories: "
                       f"{escape(', '.join(p[0] for p in panels))} — drag to zoom, double-click to reset, the "
                       "readout follows the cursor</figcaption>"
                       + fig.to_html(full_html=False, include_plotlyjs=js, config=_CONFIG, div_id="histories-plot")
                       + note + "</figure>")
        js = False
    if step_plots:
        fig = _steady(go, make_subplots, step_plots)
        figures.append("<figure id=\"steady-state\"><figcaption>Steady state (step means): "
                       f"{escape(', '.join(p[0] for p in step_plots))}</figcaption>"
                       + fig.to_html(full_html=False, include_plotlyjs=js, config=_CONFIG, div_id="steady-plot")
                       + "</figure>")
    return R.html_page(runs, title, meta, figures, head="<style>.note{color:#555;font-size:0.85em}</style>")
