"""The live view of ``zap watch``: one table per actuator, on a terminal (rich).

Each table lists the watched registers with their value in the register's unit, a sparkline of
the recent values, and a footer of link health: reads answered of asked, loss, the last round
trip, the age of the last good read, and error bits (red). The header shows the achieved poll
rate beside the asked one and the wire limit.
"""

from __future__ import annotations

import time

from .dashboard import sparkline

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


class WatchView:
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
        parts = [head]
        now = time.monotonic()
        period = max(0.5, STALE_POLLS / (w.achieved or 1.0))
        for ident in w.ids:
            h = w.health[ident]
            row = w.latest.get(ident) or {}
            table = Table(title=f"ID {ident}", title_justify="left", header_style="bold", expand=False)
            table.add_column("register")
            table.add_column("value", justify="right")
            table.add_column("trend")
            for reg in w.shown:
                raw = row.get(reg.name)
                style = None
                if reg.name == "moving" and raw:
                    style = "yellow"
                table.add_row(reg.name, Text(value_text(reg, raw), style=style),
                              Text(sparkline(w.history[ident][reg.name], 30), style="cyan"))
            errs = sorted(h.errors | set(row.get("errors") or []))
            age = None if h.last_ok is None else now - h.last_ok
            stale = age is None or age > period
            link = Text.assemble(
                ("link ", "bold"),
                (f"{h.answered}/{h.asked} answered", "green" if not h.failed else "yellow"),
                f", {h.loss * 100:.1f} % lost",
                f", rtt {h.last_rtt * 1000:.1f} ms" if h.last_rtt is not None else "",
                (f", last {h.last_status}", "red") if h.last_status not in (None, "ok") else "",
                ("  STALE" if stale else "", "bold white on red"),
                "  errors: ", (", ".join(errs) if errs else "none", "bold red" if errs else "green"))
            parts.append(Group(table, link))
        return Group(*parts)

    __rich__ = render

    def __enter__(self):
        import sys

        from rich.live import Live

        from .term import console_for

        if self.console is None:
            self.console = console_for(self.stream if self.stream is not None else sys.stdout)
        self._live = Live(get_renderable=self.render, console=self.console,
                          refresh_per_second=self.refresh_per_second, transient=False,
                          redirect_stdout=self.console.file is sys.stdout, redirect_stderr=True)
        self._live.__enter__()
        return self

    def __exit__(self, *exc):
        live, self._live = self._live, None
        if live is not None:
            live.__exit__(*exc)
        return False


