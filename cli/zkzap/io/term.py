"""Terminal manners: colour only on a terminal, NO_COLOR and FORCE_COLOR honoured.

rich is imported only by the functions that need it, never at module import.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading


def is_tty(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


def color_enabled(stream=None) -> bool:
    """NO_COLOR (any non-empty value) wins; then FORCE_COLOR; else colour only on a terminal."""
    if os.environ.get("NO_COLOR"):
        return False
    if os.environ.get("FORCE_COLOR"):
        return True
    return is_tty(stream if stream is not None else sys.stdout)


def console_for(stream=None, **kw):
    """A rich Console on ``stream`` that follows :func:`color_enabled`."""
    from rich.console import Console

    stream = stream if stream is not None else sys.stdout
    color = color_enabled(stream)
    return Console(file=stream, no_color=not color, force_terminal=color if os.environ.get("FORCE_COLOR") else None,
                   highlight=False, **kw)


def style(text: str, stream=None, **kw) -> str:
    """click.style, but only when colour is enabled for ``stream``."""
    if not color_enabled(stream):
        return text
    import click

    return click.style(text, **kw)


def fill(text: str, stream=None, indent: str = "  ") -> str:
    """``text`` wrapped at spaces to the width of the terminal ``stream`` is (continued lines
    indented), so that the terminal does not break a number in two; as it is elsewhere."""
    stream = stream if stream is not None else sys.stdout
    if not is_tty(stream):
        return text
    try:
        width = os.get_terminal_size(stream.fileno()).columns
    except (AttributeError, ValueError, OSError):
        return text
    import re
    import textwrap

    # a number keeps its unit on its line ("80 %", "745.5 °C")
    text = re.sub(r"(\d) (?=(?:%|°C|[LhsV]|rpm|kgf)(?:[^\w°]|$))", "\\1\u00a0", text)
    return "\n".join(textwrap.fill(line, width, subsequent_indent=indent, break_long_words=False,
                                    break_on_hyphens=False) for line in text.splitlines() or [""])


# --- tables that fit the terminal ----------------------------------------------------------------

#: A word no table breaks: a number (with a sign, a unit mark or a star), a time, an ISO timestamp.
_WHOLE = r"[-+±]?[\d.,:/%°]*\d[\d.,:/%°]*[*!]?|\d{4}-\d\d-\d\d(?:[T ][\d:.]+Z?)?"
#: A word of text longer than this (a path, a long command line) may be broken at this width, never cut;
#: shorter ones (names, JSON keys) stay whole.
TEXT_MIN = 20


def _words(text: str):
    return text.split() or [""]


def column_layout(headings, rows, width, priority=None):
    """How a table of ``headings`` and ``rows`` (strings) fits ``width`` terminal columns without
    cutting a value: ``(style, keep, widths)``. ``style`` is ``"boxed"`` (rich's default: every
    column 3 wide more, and one), ``"compact"`` (no box: 2 between columns) — the boxed one when
    every column fits its narrowest there; ``keep`` the indices of the columns shown (those of the
    lowest ``priority`` — of equal ones the last — are left out until the rest fit); ``widths``
    each kept column's width, None when the table fits as it is.

    A column is never narrower than its longest number or time (:data:`_WHOLE`) or its heading's
    longest word; text wraps at spaces, and only a word of text longer than :data:`TEXT_MIN` is
    broken (folded onto the next line, nothing lost)."""
    import re

    from rich.cells import cell_len               # the terminal's columns: a wide character takes two

    whole = re.compile(_WHOLE)
    n = len(headings)
    most, least = [], []
    for i, h in enumerate(headings):
        cells = [str(r[i]) for r in rows]
        most.append(max([cell_len(line) for c in [h, *cells] for line in c.splitlines() or [""]]))
        lo = max(cell_len(w) for w in _words(h))
        for c in cells:
            for w in _words(c):
                lo = max(lo, cell_len(w) if cell_len(w) <= TEXT_MIN or whole.fullmatch(w) else TEXT_MIN)
        least.append(lo)
    rank = list(priority) if priority is not None else [0] * n

    def need(cols, style, sizes):
        k = len(cols)
        return sum(sizes[i] for i in cols) + (3 * k + 1 if style == "boxed" else 2 * max(k - 1, 0))

    keep = list(range(n))
    if need(keep, "boxed", most) <= width:
        return "boxed", keep, None
    style = "boxed" if need(keep, "boxed", least) <= width else "compact"
    while len(keep) > 1 and need(keep, style, least) > width:
        keep.remove(min(keep, key=lambda i: (rank[i], -i)))
    if need(keep, style, most) <= width:
        return style, keep, [most[i] for i in keep]
    sizes = {i: least[i] for i in keep}
    spare = width - need(keep, style, least)
    want = {i: most[i] - least[i] for i in keep}
    total = sum(want.values())
    if spare > 0 and total:
        for i in keep:
            sizes[i] += min(want[i], spare * want[i] // total)
        left = spare - sum(sizes[i] - least[i] for i in keep)
        for i in sorted(keep, key=lambda i: -(most[i] - sizes[i])):
            if left <= 0:
                break
            if sizes[i] < most[i]:
                sizes[i] += 1
                left -= 1
    return style, keep, [sizes[i] for i in keep]


def fitted_table(headings, rows, width, *, title=None, caption=None, priority=None, header_style="bold",
                 sections=()):
    """A rich Table of ``headings`` and ``rows`` (strings) laid out by :func:`column_layout` for
    ``width`` columns: no value cut; the columns left out named in the caption. ``sections``:
    the indices of the rows that start a new group (a line is drawn above them)."""
    from rich import box
    from rich.table import Table

    style, keep, widths = column_layout(headings, rows, width, priority)
    dropped = [headings[i] for i in range(len(headings)) if i not in keep]
    notes = [caption] if caption else []
    if dropped:
        notes.append(f"left out at {width} columns: {', '.join(' '.join(h.split()) for h in dropped)} "
                     "(a wider terminal, or -f csv/json, shows them)")
    kw = {} if style == "boxed" else dict(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False,
                                                       padding=(0, 1, 0, 0))
    table = Table(title=title, title_justify="left", header_style=header_style, caption="; ".join(notes) or None,
                  caption_justify="left", **kw)
    for k, i in enumerate(keep):
        table.add_column(headings[i], overflow="fold", width=None if widths is None else widths[k])
    starts = set(sections)
    for j, r in enumerate(rows):
        if j in starts and j:
            table.add_section()
        table.add_row(*(str(r[i]) for i in keep))
    return table


# --- progress of a large input --------------------------------------------------------------------

#: An input file at least this large gets a progress bar while it is read (on a terminal).
PROGRESS_MIN = 32 << 20
#: Live views drawing on the terminal now (a progress bar stands aside for them).
_live = [0]
#: Progress watchers running (one at a time: the outermost command's).
_watching = [0]
#: A stream of unknown size (a pipe, stdin) gets its running count once this much was read.
STREAM_MIN = 4 << 20
#: A piece of work (:func:`working`) is shown once it has lasted this long (seconds).
WORK_AFTER_S = 0.5
#: The pieces of work under way (:class:`Work`), for the progress display.
_works: list = []


def live_view(on: bool) -> None:
    """A live view (the dashboard, a watch table) starts (``on``) or ends drawing on the terminal."""
    _live[0] += 1 if on else -1


class Work:
    """A long piece of work a progress display shows (:func:`working`): ``what`` it does now,
    ``done`` of ``total`` steps (None: not known)."""

    def __init__(self, what: str, total=None):
        import time

        self.what, self.total, self.done = what, total, 0
        self.started = time.monotonic()

    def step(self, what=None, n: int = 1) -> None:
        """``n`` steps more done; ``what``: what it does now."""
        self.done += n
        if what is not None:
            self.what = what


@contextlib.contextmanager
def working(what: str, total=None):
    """``with working("drawing run.png", total=8) as w: ... w.step("writing run.png")``: a piece
    of work the progress display of :func:`input_progress` shows on a terminal once it has lasted
    :data:`WORK_AFTER_S` (bar and steps); off a terminal it costs a list append."""
    w = Work(what, total)
    _works.append(w)
    try:
        yield w
    finally:
        _works.remove(w)


@contextlib.contextmanager
def input_progress(stream=None, minimum=None):
    """While inside: a progress bar on ``stream`` (stderr) for every regular input file of at
    least ``minimum`` bytes (:data:`PROGRESS_MIN`) being read (:func:`zkzap.infile.reading`):
    bytes read, speed and the time left; shown only while such a file is open and no live view
    draws, erased after. Nothing at all when ``stream`` is no terminal (no thread, no rich)."""
    stream = stream if stream is not None else sys.stderr
    if not is_tty(stream) or _watching[0]:          # a command inside another's (a batch line): one bar
        yield
        return
    _watching[0] += 1
    stop = threading.Event()
    worker = threading.Thread(target=_progress, args=(stream, stop, minimum or PROGRESS_MIN), daemon=True,
                              name="zkzap-input-progress")
    worker.start()
    try:
        yield
    finally:
        stop.set()
        worker.join(5)
        _watching[0] -= 1


def _shown(minimum):
    """What the progress display shows now: ``[(key, description, done, total, bytes)]``."""
    import time

    from ..infile import reading

    out = []
    for path, done, size in reading():
        if size is None:                       # a pipe, stdin: its running count, once it is large
            if done >= STREAM_MIN:
                out.append((("stream", path), f"reading {path}", done, None, True))
        elif size >= minimum:
            out.append((("file", path), f"reading {os.path.basename(path)}", done, size, True))
    now = time.monotonic()
    for w in list(_works):
        if now - w.started >= WORK_AFTER_S:
            out.append((("work", id(w)), w.what, w.done, w.total, False))
    return out


def _progress(stream, stop, minimum, interval=0.25):
    bar, tasks = None, {}
    try:
        while not stop.wait(interval):
            shown = _shown(minimum) if not _live[0] else []
            if not shown:
                if bar is not None:
                    bar.stop()
                    bar, tasks = None, {}
                continue
            if bar is None:
                from rich.progress import (BarColumn, DownloadColumn, Progress, ProgressColumn, TextColumn,
                                           TimeRemainingColumn, TransferSpeedColumn)

                class Count(ProgressColumn):
                    """Bytes (read of the size, or read so far) and their speed; or steps done."""

                    _bytes, _speed = DownloadColumn(), TransferSpeedColumn()

                    def render(self, task):
                        from rich.text import Text

                        if task.fields.get("bytes"):
                            if task.total is None:          # a pipe: how much so far, no size
                                from rich.filesize import decimal

                                read = Text(f"{decimal(int(task.completed))} read", style="progress.download")
                            else:
                                read = self._bytes.render(task)
                            return Text.assemble(read, " ", self._speed.render(task))
                        total = f"/{task.total:g}" if task.total is not None else ""
                        return Text(f"{task.completed:g}{total}", style="progress.download")

                # stderr's messages go above the bar; so do stdout's on a terminal (data in a pipe
                # is never touched)
                bar = Progress(TextColumn("{task.description}"), BarColumn(), Count(), TimeRemainingColumn(),
                               console=console_for(stream), transient=True, auto_refresh=False,
                               redirect_stderr=True, redirect_stdout=is_tty(sys.stdout))
                bar.start()
            keys = set()
            for key, what, done, total, is_bytes in shown:
                keys.add(key)
                if key not in tasks:
                    tasks[key] = bar.add_task(what, total=total, bytes=is_bytes)
                bar.update(tasks[key], completed=done, total=total, description=what)
            for key in [k for k in tasks if k not in keys]:
                bar.remove_task(tasks.pop(key))
            bar.refresh()
    finally:
        if bar is not None:
            bar.stop()
