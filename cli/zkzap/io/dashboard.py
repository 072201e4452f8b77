"""A live terminal view of a ZK ECU, for a person watching the engine (``zk monitor`` on a terminal).

Usage::

    with Dashboard(sys.stdout, "ZK ECU on /dev/ttyUSB0") as dash:
        for ...:
            dash.update(snapshot, health)

``snapshot`` holds the latest value of every status key (:data:`zkzap.codec.zk.STATUS_KEYS`,
None until seen) plus ``time_s`` (seconds since the start of monitoring); ``health`` holds
``frames``, ``frames_per_s``, ``crc_errors``, ``skipped``, ``stale``, ``protocol_version`` and
``version_source`` (and ``limits``, ``bridges``, ``alarms``: the stand's alarm list, newest
first, as :meth:`zkzap.api.alarms.Alarms.to_list` gives it). With ``duration`` (a session's planned length) the time left is shown too. :meth:`Dashboard.update` only records the values (cheap enough for every
frame at 100 Hz); the screen is redrawn by rich's refresh thread a few times a second, so the
"last frame ... ago" age keeps counting when frames stop arriving.

Colour follows :func:`zkzap.io.term.color_enabled` (NO_COLOR, FORCE_COLOR, terminal or not);
every state is also spelled out in words, so nothing depends on colour. rich is imported only
when a dashboard is built.
"""

from __future__ import annotations

import threading
import time
from collections import deque

from ..codec import zk

#: Units of the status keys, from the codec's table (nothing retyped here).
UNITS = {f.key: f.unit for s in zk.STATUS for f in s.fields}

SPARK = "▁▂▃▄▅▆▇█"
BAR_FULL, BAR_EMPTY = "█", "░"
MISSING = "—"
#: How the protocol version shown was learnt (``ZkDecoder.version_source``).
VERSION_SOURCES = {"frame": "from the ECU", "given": "as given", "default": "assumed until status ID 6"}


def state_style(name) -> str:
    """A rich style for an engine state name (the appendix names of the codec)."""
    if not name:
        return "dim"
    if name == "running-pump-limit":
        return "bold yellow"
    if name.startswith("running"):
        return "bold green"
    if name in ("stop",):
        return "bold"
    if name in ("standby", "cooling"):
        return "bold cyan"
    if name.startswith("test-") or name in ("fuel-exhaust-air",):
        return "bold magenta"
    if name.startswith("undocumented"):
        return "bold red"
    # ignition, preheat, fuel ramp, learning, restart: the engine is changing state
    return "bold yellow"


def error_style(code) -> str:
    if code is None:
        return "dim"
    return "green" if code == 0 else "bold white on red"


def sparkline(values, width=None) -> str:
    """``[1, 5, 3]`` -> ``"▁█▄"``: one character per value, scaled between the window's min and max.
    None values (not yet seen) are blanks; a flat series is drawn at mid height."""
    vals = list(values)
    if width is not None and len(vals) > width:
        vals = vals[-width:]
    present = [v for v in vals if v is not None]
    if not present:
        return ""
    lo, hi = min(present), max(present)
    out = []
    top = len(SPARK) - 1
    for v in vals:
        if v is None:
            out.append(" ")
        elif hi == lo:
            out.append(SPARK[top // 2])
        else:
            out.append(SPARK[round((v - lo) / (hi - lo) * top)])
    return "".join(out)


def bar(fraction, width=20) -> str:
    """A text gauge, ``fraction`` 0..1 (clamped)."""
    fraction = 0.0 if fraction is None else min(max(fraction, 0.0), 1.0)
    n = round(fraction * width)
    return BAR_FULL * n + BAR_EMPTY * (width - n)


def fmt(value, unit="", thousands=False) -> str:
    """A value with its unit, or a dash when it has not been seen (or the ECU lacks it)."""
    if value is None:
        return MISSING
    if isinstance(value, bool):
        text = "yes" if value else "no"
    elif thousands and isinstance(value, (int, float)):
        text = f"{value:,}"
    else:
        text = str(value)
    if not unit:
        return text
    return f"{text}{unit}" if unit == "%" else f"{text} {unit}"


class LiveView:
    """What a live view on a terminal shares: rich's Live around :meth:`render` (which the view
    defines, with ``stream``, ``console`` and ``refresh_per_second``) while the view is entered."""

    def __enter__(self):
        import sys

        from rich.live import Live

        from .term import console_for

        if self.console is None:
            self.console = console_for(self.stream if self.stream is not None else sys.stdout)
        self._live = Live(get_renderable=self.render, console=self.console,
                          refresh_per_second=self.refresh_per_second, transient=False,
                          redirect_stdout=self.console.file is sys.stdout, redirect_stderr=True)
        from .term import live_view

        live_view(True)                   # a progress bar of an input stands aside
        self._live.__enter__()
        return self

    def __exit__(self, *exc):
        live, self._live = self._live, None
        if live is not None:
            from .term import live_view

            live.__exit__(*exc)
            live_view(False)
        return False

    def note(self, text: str) -> None:
        """A message for the person above the live view (rich moves the view down; a line written
        to the terminal beside it would be drawn over by the next refresh). Not live: stderr."""
        live = getattr(self, "_live", None)
        if live is None:
            import sys

            sys.stderr.write(text + "\n")
            sys.stderr.flush()
            return
        from rich.text import Text

        live.console.print(Text(text, style="yellow" if text.startswith(("warning", "note: limit")) else ""),
                           soft_wrap=True)


class History:
    """The last ``points`` samples of one value, one per ``interval`` seconds of ``time_s``:
    within an interval the latest value wins, so the line does not depend on the frame rate."""

    def __init__(self, points=40, interval=0.5):
        self.interval = interval
        self.values = deque(maxlen=points)
        self._slot = None

    def add(self, t, value):
        if value is None:
            return
        slot = int(t // self.interval)
        if slot == self._slot and self.values:
            self.values[-1] = value
        else:
            self.values.append(value)
            self._slot = slot

    @property
    def span_s(self) -> float:
        return self.values.maxlen * self.interval


class Dashboard(LiveView):
    """A rich Live view of the engine and the link; a context manager.

    ``stream`` is where the view is drawn (a terminal; anything else gets the final view once,
    when the dashboard closes). ``title`` heads the panel (say, the port). ``console`` overrides
    the rich Console (tests render to a string console); ``clock`` is the wall clock used for the
    age of the last frame.
    """

    def __init__(self, stream=None, title="ZK ECU", *, console=None, history_points=40,
                 history_interval=0.5, refresh_per_second=4.0, clock=time.monotonic, duration=None):
        self.stream = stream
        self.title = title
        #: The session's planned length in seconds (--for, a schedule, --duration): the view then
        #: shows the time remaining besides the time elapsed.
        self.duration = duration
        self.console = console
        self.refresh_per_second = refresh_per_second
        self.clock = clock
        self.snapshot = {k: None for k in zk.STATUS_KEYS}
        self.health = {"frames": 0, "frames_per_s": 0.0, "crc_errors": 0, "skipped": 0, "stale": False,
                       "protocol_version": None, "version_source": None}
        self.rpm_history = History(history_points, history_interval)
        self.egt_history = History(history_points, history_interval)
        self._lock = threading.Lock()
        self._last_frame_at = None
        self._t0 = clock()
        self._live = None

    # --- data in ---------------------------------------------------------------------------
    def update(self, snapshot: dict, health: dict) -> None:
        """Record the latest snapshot and link health; the next refresh draws them."""
        now = self.clock()
        with self._lock:
            if health.get("frames", 0) != self.health.get("frames", 0):
                self._last_frame_at = now
            self.snapshot = dict(snapshot)
            self.health = dict(health)
            t = snapshot.get("time_s")
            if t is None:
                t = now - self._t0
            self.rpm_history.add(t, snapshot.get("rpm"))
            self.egt_history.add(t, snapshot.get("egt_c"))

    # --- drawing ---------------------------------------------------------------------------
    def render(self):
        """The whole view as one rich renderable (a Panel)."""
        from rich.console import Group
        from rich.panel import Panel
        from rich.table import Table
        from rich.text import Text

        with self._lock:
            s = dict(self.snapshot)
            h = dict(self.health)
            rpm_hist = list(self.rpm_history.values)
            egt_hist = list(self.egt_history.values)
            span = self.rpm_history.span_s
            age = None if self._last_frame_at is None else self.clock() - self._last_frame_at

        def val(key, thousands=False, style=None):
            v = s.get(key)
            return Text(fmt(v, UNITS.get(key, ""), thousands), style="dim" if v is None else (style or ""))

        g = Table.grid(padding=(0, 2))
        g.add_column(style="bold", no_wrap=True)
        g.add_column(no_wrap=True, min_width=16)
        g.add_column(style="bold", no_wrap=True)
        g.add_column(no_wrap=True, min_width=16)

        name = s.get("engine_state_name")
        state = Text(name.upper() if name else MISSING, style=state_style(name))
        err = s.get("error_code")
        if err:
            err_text = Text(f" {s.get('error_name')} ({err}) ", style=error_style(err))
        else:
            err_text = Text(s.get("error_name") or MISSING, style=error_style(err))
        g.add_row("State", state, "Host", val("sw_state_name"))
        g.add_row("Error", err_text, "ECU temp", val("ecu_temp_c"))

        rpm_cell = val("rpm", thousands=True, style="bold")
        rpm, max_rpm = s.get("rpm"), s.get("max_rpm")
        if rpm is not None and max_rpm:
            rpm_cell.append(f"  {bar(rpm / max_rpm, 16)} {rpm / max_rpm * 100:.0f} %", style="cyan")
        g.add_row("RPM", rpm_cell, "Max rpm", val("max_rpm", thousands=True))
        g.add_row("EGT", val("egt_c", style="bold"), "Idle rpm", val("idle_rpm", thousands=True))
        thr_cell = val("throttle_pct", style="bold")
        if s.get("throttle_pct") is not None:
            thr_cell.append(f"  {bar(s['throttle_pct'] / 100, 16)}", style="cyan")
        g.add_row("Throttle", thr_cell, "Pressure", val("pressure_pa", thousands=True))
        g.add_row("Thrust", val("thrust_kg", style="bold"), "Current", val("current_a"))
        g.add_row("Fuel flow", val("fuel_flow_l_min", style="bold"), "Fuel used", val("fuel_used_l", style="bold"))
        g.add_row("Battery", val("power_voltage_v"), "Receiver", val("radio_voltage_v"))
        g.add_row("Pump", val("pump_voltage_v"), "Ignition", val("ignition_pump_voltage_v"))
        g.add_row("Pump rpm", val("fuel_pump_rpm", thousands=True), "Prop rpm", val("prop_rpm", thousands=True))

        trends = Table.grid(padding=(0, 2))
        trends.add_column(style="bold", no_wrap=True)
        trends.add_column(no_wrap=True)
        trends.add_column(no_wrap=True, style="dim")
        for label, hist, key in (("RPM", rpm_hist, "rpm"), ("EGT", egt_hist, "egt_c")):
            present = [v for v in hist if v is not None]
            if present:
                rng = f"{fmt(min(present), thousands=True)}..{fmt(max(present), UNITS[key], thousands=True)}"
                trends.add_row(f"{label} {span:g} s", Text(sparkline(hist), style="cyan"), rng)
            else:
                trends.add_row(f"{label} {span:g} s", Text(MISSING, style="dim"), "")

        stale = bool(h.get("stale"))
        link = Table.grid(padding=(0, 2))
        link.add_column(style="bold", no_wrap=True)
        link.add_column()
        rate = Text(f"{h.get('frames_per_s') or 0:.1f} frames/s", style="bold red" if stale else "bold")
        rate.append(f"  {h.get('frames') or 0:,} frames", style="")
        crc = h.get("crc_errors") or 0
        rate.append(f"  CRC errors {crc}", style="bold yellow" if crc else "")
        skipped = h.get("skipped") or 0
        rate.append(f"  skipped {skipped:,} B", style="yellow" if skipped else "")
        link.add_row("Link", rate)
        info = Text()
        version = h.get("protocol_version")
        if version is not None:
            source = h.get("version_source")
            info.append(f"protocol v{version}")
            if source:
                info.append(f" ({VERSION_SOURCES.get(source, source)})",
                            style="dim" if source == "frame" else "yellow")
            info.append("  ")
        info.append("last frame " + ("never" if age is None else f"{age:.1f} s ago"),
                    style="bold red" if stale or age is None else "dim")
        link.add_row("", info)
        for line in h.get("limits") or ():          # limit events: (level, text), newest state
            link.add_row("Limit" if line[0] == "violated" else "Warn",
                         Text(line[1], style="bold white on red" if line[0] == "violated" else "bold yellow"))
        for i, a in enumerate(a for a in (h.get("alarms") or ()) if a["level"] == "alarm"):
            # the stand's alarm list (newest first): latched until acknowledged
            state = "LATCHED" if a["latched"] else f"acknowledged by {a['acked_by']}"
            line = Text(f"{a['time'][11:19]}  {state}  ", style="bold white on red" if a["latched"] else "dim")
            line.append(a["text"], style="bold red" if a["latched"] else "")
            link.add_row("Alarm" if i == 0 else "", line)
        for name, b in (h.get("bridges") or {}).items():
            line = Text(f"{name}: {b.get('submitted', 0):,} records")
            if "published" in b:
                line.append(f", {b['published']:,} published")
            dropped = b.get("dropped") or 0
            line.append(f"  dropped {dropped:,}", style="bold yellow" if dropped else "")
            if b.get("connected") is False:
                line.append("  broker away", style="bold red")
            link.add_row("Bridge" if name == next(iter(h["bridges"])) else "", line)
        elapsed = s.get("time_s")
        if elapsed is not None:
            when = Text(f"elapsed {elapsed:.1f} s", style="bold")
            if self.duration:
                left = max(self.duration - elapsed, 0.0)
                when.append(f" of {self.duration:g} s, {left:.1f} s left", style="")
            link.add_row("Time", when)

        subtitle = None
        if stale:
            subtitle = Text(" STALE: no status frames " + ("yet " if age is None else f"for {age:.1f} s "),
                            style="bold white on red")
        return Panel(Group(g, Text(""), trends, Text(""), link), title=Text(f" {self.title} ", style="bold"),
                     title_align="left", subtitle=subtitle, subtitle_align="left",
                     border_style="red" if stale else "blue", expand=False)

    __rich__ = render


    def refresh(self) -> None:
        """Redraw now (the refresh thread also redraws a few times a second)."""
        if self._live is not None:
            self._live.refresh()
