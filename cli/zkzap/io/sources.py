"""Byte sources for decoding: hex arguments, hex text on stdin, binary files or stdin.

Each source yields byte chunks and never holds a whole capture in memory (hex text is read
line by line, binary input in 64 KiB blocks).
"""

from __future__ import annotations

import sys

from ..codec.hexfmt import iter_hex_stream, parse_hex
from ..errors import UsageError

CHUNK = 1 << 16


def binary_chunks(paths):
    """Chunks of each file in ``paths`` in turn; ``-`` (or no paths) is stdin."""
    for path in paths or ["-"]:
        if path == "-":
            stream = sys.stdin.buffer
            close = False
        else:
            try:
                stream = open(path, "rb")
            except OSError as e:
                raise UsageError(f"input: cannot read {path}: {e.strerror}") from None
            close = True
        try:
            while True:
                block = stream.read(CHUNK)
                if not block:
                    break
                yield block
        finally:
            if close:
                stream.close()


def hex_chunks(args):
    """(chunks, explicit): the bytes of hex arguments (explicit=True), or hex lines of stdin."""
    if args and list(args) != ["-"]:
        return [parse_hex(" ".join(args), what="hex input")], True
    if sys.stdin is None or sys.stdin.isatty() and not args:
        raise UsageError("input: none given; pass hex as arguments, pipe hex or bytes (--binary) to stdin")
    return iter_hex_stream(sys.stdin, what="stdin"), False


class DecodeStats:
    def __init__(self):
        self.records = 0


def run_decode(chunks, framer, decode, writer, *, frame_key="frame"):
    """Feed ``chunks`` through ``framer``; write ``decode(frame)`` records (with the frame's hex
    under ``frame_key``) to ``writer``. Returns the number of records written."""
    count = 0
    write = writer.write
    for chunk in chunks:
        for frame in framer.feed(chunk):
            rec = decode(frame)
            rec[frame_key] = frame.hex(" ").upper()
            write(rec)
            count += 1
    framer.flush()
    return count
