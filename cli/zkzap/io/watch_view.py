"""The live view of ``zap watch``: one section per actuator in one table, on a terminal (rich).

Each actuator's section lists the watched registers with their value in the register's unit
and a sparkline of the recent values, beside its link health (reads answered of asked, loss,
the last round trip, STALE when no read succeeded lately) and its error bits (red). The header shows the achieved poll
rate beside the asked one and the wire limit.
"""

from __future__ import annotations

import time

from .dashboard import LiveView, sparkline

#: A read older than this many poll periods (at least 0.5 s) is shown as stale.
STALE_POLLS = 3


def value_text(reg, raw) -> str:
    if raw is None:
        return "-"
    if reg.scale != 1:
        return f"{reg.physical(raw):g} {reg.unit}"
    if reg.choices and raw in reg.choices:
        return f"{raw} ({reg.choices[raw]})"
    return f"{raw} {reg.unit}".rstrip()


class WatchView(LiveView):
    """A rich Live view of a :class:`zkzap.api.watch.Watcher`; a context manager."""

    refresh_per_second = 8

    def __init__(self, watcher, stream=None, *, console=None, asked=None):
        self.watcher = watcher
        self.stream = stream
        self.console = console
        self.asked = asked
        self._live = None

    def render(self):
        from rich.console import Group
        from rich.table import Table
        from rich.text import Text

        w = self.watcher
        try:
            limit = w.limit()
        except ZeroDivisionError:
            limit = 0.0
        asked = f"{self.asked:g} Hz asked" if self.asked else "as fast as the line allows"
        head = Text.assemble(("mightyZAP watch", "bold"),
                             f"  {w.polls} polls in {w.elapsed:.1f} s: ",
                             (f"{w.achieved:.1f} polls/s", "bold cyan"),
                             f" ({asked}; wire limit {limit:.1f}/s at {w.bus.baud} baud)")
        table = Table(header_style="bold", expand=False, show_edge=True)
        for name, justify in (("id", "left"), ("register", "left"), ("value", "right"), ("trend", "left"),
                              ("link", "left")):
            table.add_column(name, justify=justify, no_wrap=True)
        width = self.console.width if self.console is not None else 100
        spark = max(5, min(24, width - 70))
        now = time.monotonic()
        period = max(0.5, STALE_POLLS / (w.achieved or 1.0))
        for ident in w.ids:
            h = w.health[ident]
            row = w.latest.get(ident) or {}
            errs = sorted(h.errors | set(row.get("errors") or []))
            age = None if h.last_ok is None else now - h.last_ok
            stale = age is None or age > period
            link = [Text.assemble((f"{h.answered}/{h.asked} ok", "green" if not h.failed else "yellow"),
                                  f", {h.loss * 100:.1f}% lost"),
                    Text(" ").join(t for t in (
                        Text(f"rtt {h.last_rtt * 1000:.1f} ms") if h.last_rtt is not None else None,
                        Text(f"last {h.last_status}", style="red") if h.last_status not in (None, "ok") else None,
                        Text("STALE", style="bold white on red") if stale else None) if t is not None),
                    Text.assemble("errors ", (", ".join(errs) if errs else "none",
                                              "bold red" if errs else "green"))]
            lines = max(len(w.shown), len(link))
            for n in range(lines):
                reg = w.shown[n] if n < len(w.shown) else None
                raw = row.get(reg.name) if reg is not None else None
                style = "yellow" if reg is not None and reg.name == "moving" and raw else None
                text = value_text(reg, raw) if reg is not None else ""
                mm = row.get(f"{reg.name}_mm") if reg is not None else None
                if mm is not None:
                    text += f" ({mm:g} mm)"           # the counts always, the millimetres beside them
                table.add_row(Text(f"ID {ident}", style="bold") if n == 0 else "",
                              reg.name if reg is not None else "",
                              Text(text, style=style) if reg is not None else "",
                              Text(sparkline(w.history[ident][reg.name], spark), style="cyan") if reg is not None
                              else "",
                              link[n] if n < len(link) else "", end_section=n == lines - 1)
        parts = [head, table]
        return Group(*parts)

    __rich__ = render



