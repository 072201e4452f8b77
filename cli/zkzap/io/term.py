"""Terminal manners: colour only on a terminal, NO_COLOR and FORCE_COLOR honoured.

rich is imported only by the functions that need it, never at module import.
"""

from __future__ import annotations

import os
import sys


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
