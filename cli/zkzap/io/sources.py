"""Byte sources for decoding: hex arguments, hex text on stdin, binary files or stdin.

Each source yields byte chunks and never holds a whole capture in memory (hex text is read
line by line, binary input in 64 KiB blocks).
"""

from __future__ import annotations

import gc
import os
import sys

from ..codec.hexfmt import HexError, HexSkips, iter_hex_stream, parse_hex
from ..errors import UsageError
from ..infile import open_input

CHUNK = 1 << 16


def binary_chunks(paths):
    """Chunks of each file in ``paths`` in turn; ``-`` (or no paths) is stdin. Every file is
    checked before the first chunk is read, so an unreadable one is an error before any output."""
    paths = list(paths or ["-"])
    for path in paths:
        if path != "-":
            try:
                open_input(path).close()
            except OSError as e:
                raise UsageError(f"input: cannot read {path}: {e.strerror}") from None
    return _binary_chunks(paths)


def _binary_chunks(paths):
    for path in paths:
        if path == "-":
            stream = sys.stdin.buffer
            close = False
        else:
            try:
                stream = open_input(path)
            except OSError as e:
                raise UsageError(f"input: cannot read {path}: {e.strerror}") from None
            close = True
        # read1: a live pipe (cat /dev/ttyUSB0 | ...) is decoded as its bytes arrive
        read = getattr(stream, "read1", stream.read)
        try:
            while True:
                try:
                    block = read(CHUNK)
                except OSError as e:      # /proc/self/mem, a vanished network file, a directory on stdin
                    raise UsageError(f"input: cannot read {'stdin' if path == '-' else path}: "
                                     f"{e.strerror or e}") from None
                if not block:
                    break
                yield block
        finally:
            if close:
                stream.close()


def hex_chunks(args):
    """(chunks, explicit): the bytes of hex arguments (explicit=True), or hex lines of stdin or
    of the text files the arguments name (``zap decode dump.hex``: arguments that are not hex
    but every one an existing file; raw bytes in one are refused with a pointer to --binary)."""
    if args and list(args) != ["-"]:
        try:
            return [parse_hex(" ".join(args), what="hex input")], True
        except HexError as e:
            if not all(a != "-" and os.path.isfile(a) for a in args):
                named = [a for a in args if ("." in a or os.sep in a) and not os.path.exists(a)]
                if named:
                    raise HexError(f"{e} (nor a file: {named[0]} does not exist)") from None
                raise
        return HexText(list(args)), False
    if sys.stdin is None or sys.stdin.isatty() and not args:
        raise UsageError("input: none given; pass hex as arguments, pipe hex or bytes (--binary) to stdin")
    return HexText(), False


class HexText:
    """The bytes of hex text, line by line: stdin, or the text files ``paths`` in turn. Bytes
    that are not UTF-8 are read as what they are (binary input, refused or, once a stream has
    given bytes, a damaged line skipped), never as a decoding error that would end the stream:
    :meth:`note` counts the lines skipped. ``strict``: every line that is not hex is an error."""

    def __init__(self, paths=None, strict: bool = False):
        self.paths = paths
        self.what = "stdin"              # the input the first skipped line came from
        self.skipped = None if strict else HexSkips()
        self._started = None

    def start(self) -> None:
        """Read up to the first bytes now: text refused at its first line is refused before
        any output is opened (no CSV header, no ``[`` on stdout). Iterating yields them first."""
        it = self._chunks()
        first = next(it, None)
        self._started = ([] if first is None else [first], it)

    def __iter__(self):
        if self._started is None:
            yield from self._chunks()
            return
        first, it = self._started
        self._started = None
        yield from first
        yield from it

    def _chunks(self):
        if self.paths is None:
            yield from self._stdin()
        else:
            for path in self.paths:
                yield from self._file(path)

    def _stdin(self):
        import io

        raw = getattr(sys.stdin, "buffer", None)
        stream = sys.stdin if raw is None else io.TextIOWrapper(raw, encoding="utf-8", errors="surrogateescape")
        try:
            yield from iter_hex_stream(stream, what="stdin", skipped=self.skipped)
        finally:
            if raw is not None:
                stream.detach()           # leave stdin's buffer open for whoever owns it

    def _file(self, path):
        try:
            stream = open(path, encoding="utf-8", errors="surrogateescape", newline=None)
        except OSError as e:
            raise UsageError(f"input: cannot read {path}: {e.strerror}") from None
        before = self.skipped.lines if self.skipped is not None else 0
        with stream:
            try:
                yield from iter_hex_stream(stream, what=path, skipped=self.skipped)
            except HexError as e:
                if "binary input" in str(e):
                    raise HexError(f"{path}: raw bytes, not hex text: give --binary to decode them "
                                   f"({' '.join(['--binary', *self.paths])})", path=path) from None
                raise
        if self.skipped is not None and not before and self.skipped.lines:
            self.what = path

    def note(self):
        text = self.skipped.note() if self.skipped is not None else None
        return f"{self.what}: {text}" if text else None


def start(chunks) -> None:
    """Read a hex source up to its first bytes before the output opens (see :meth:`HexText.start`)."""
    if isinstance(chunks, HexText):
        chunks.start()


def hex_note(chunks):
    """The note on the damaged lines a hex stream skipped, or None."""
    return chunks.note() if isinstance(chunks, HexText) else None


def hex_file_inputs(args) -> bool:
    """Whether the decoders read ``args`` as hex text files (see :func:`hex_chunks`)."""
    if not args or list(args) == ["-"] or not all(os.path.isfile(a) for a in args):
        return False
    try:
        parse_hex(" ".join(args), what="hex input")
    except HexError:
        return True
    return False


class _CollectorPaused:
    """The cyclic garbage collector paused while a decode loop runs: the loop allocates
    millions of short-lived objects that reference counting frees (it makes no cycles), and
    the collector's passes over them cost several percent of the run for nothing."""

    def __enter__(self):
        self.was = gc.isenabled()
        gc.disable()
        return self

    def __exit__(self, *exc):
        if self.was:
            gc.enable()
        return False


def run_decode(chunks, framer, decode, writer, *, frame_key="frame"):
    """Feed ``chunks`` through ``framer``; write ``decode(frame)`` records (with the frame's hex
    under ``frame_key``) to ``writer``, one block per chunk. Returns the number of records."""
    count = 0
    with _CollectorPaused():
        for chunk in chunks:
            count += _records(framer.feed(chunk), decode, writer, frame_key)
        return count + _records(framer.flush(), decode, writer, frame_key)


def _records(frames, decode, writer, frame_key):
    if not frames:
        return 0
    recs = []
    for frame in frames:
        rec = decode(frame)
        rec[frame_key] = frame.hex(" ").upper()
        recs.append(rec)
    writer.write_many(recs)
    return len(recs)


def run_text_decode(chunks, framer, lines, writer, after=None):
    """Like :func:`run_decode` for the text formats: ``lines.encode_all(frames)`` renders the
    records (see :class:`zkzap.io.zk_lines.ZkLines`) and ``writer.write_lines`` writes each block.
    ``after()`` runs after each block. Returns the number of records written."""
    count = 0
    write_lines = writer.write_lines
    if hasattr(framer, "feed_lines"):
        # framing and rendering in one pass: a repeated frame in step is one memo look-up
        feed = lambda chunk: framer.feed_lines(chunk, lines)  # noqa: E731
        flush = lambda: framer.flush_lines(lines)  # noqa: E731
    else:
        feed = lambda chunk: lines.encode_all(framer.feed(chunk))  # noqa: E731
        flush = lambda: lines.encode_all(framer.flush())  # noqa: E731
    with _CollectorPaused():
        for chunk in chunks:
            out = feed(chunk)
            if out:
                count += len(out)
                write_lines(out)
                if after is not None:
                    after()
        out = flush()
        if out:
            count += len(out)
            write_lines(out)
            if after is not None:
                after()
    return count
