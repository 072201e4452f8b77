"""``-f mcap`` / ``-o FILE.mcap`` for the ZK logging commands: checks and opening (the MCAP
writer itself is :mod:`zkzap.io.mcap`, imported only here)."""

from __future__ import annotations

import sys

from ...errors import UsageError


def check_mcap(output, append, snapshot) -> None:
    """Refuse what an MCAP log cannot do, before anything is opened."""
    from ...io.bridges import require_extra
    from ...io.term import is_tty

    require_extra("mcap", "mcap", "format mcap")
    if append:
        raise UsageError("append: an MCAP file cannot be appended to; give a new -o FILE.mcap")
    if snapshot:
        raise UsageError("snapshot: not with mcap (each status ID has its own channel of whole frames)")
    if (not output or output == "-") and is_tty(sys.stdout):
        raise UsageError("format mcap: binary output; give -o FILE.mcap or redirect stdout")


def open_mcap(output, append, snapshot):
    """(binary stream, writer, snapshot=False) for an MCAP log on ``output`` ('-'/None: stdout)."""
    check_mcap(output, append, snapshot)
    from ...io.mcap import McapWriter

    if not output or output == "-":
        stream = sys.stdout.buffer
    else:
        try:
            stream = open(output, "wb")
        except OSError as e:
            raise UsageError(f"output: cannot open {output}: {e.strerror}") from None
    return stream, McapWriter(stream), False
