"""Text inputs named on the command line or in the API: a file, or ``-`` for standard input."""

from __future__ import annotations

from ..errors import UsageError


def read_text(path, what: str, expected: str = "") -> tuple:
    """``(text, name)`` of the UTF-8 file ``path`` (a byte-order mark is dropped) or of standard
    input (``-``; its name is ``stdin``). A file that cannot be read, or is not UTF-8, is a
    UsageError naming ``what`` (``schedule``, ``limits``, ``batch``) and, when given, what
    was ``expected`` in it."""
    if str(path) == "-":
        import sys

        if sys.stdin is None:
            raise UsageError(f"{what}: no standard input")
        return sys.stdin.read(), "stdin"
    try:
        with open(path, encoding="utf-8-sig") as f:
            return f.read(), str(path)
    except OSError as e:
        raise UsageError(f"{what}: cannot read {path}: {e.strerror}") from None
    except UnicodeDecodeError:
        more = f" (expected {expected})" if expected else ""
        raise UsageError(f"{what}: {path} is not UTF-8 text{more}") from None
