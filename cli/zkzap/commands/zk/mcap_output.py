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


def open_mcap(output, append, snapshot, inputs=None):
    """(binary stream, writer, snapshot=False) for an MCAP log on ``output`` ('-'/None: stdout);
    a file is checked now and opened by the first record (:class:`zkzap.outfile.LazyOutput`)."""
    check_mcap(output, append, snapshot)
    from ...io.mcap import McapWriter

    if not output or output == "-":
        stream = sys.stdout.buffer
    else:
        from ...outfile import LazyOutput, OutFile, refuse_same_files

        refuse_same_files({"--output": output}, inputs)
        stream = LazyOutput(OutFile(output, binary=True).check())
    return stream, McapWriter(stream), False
