"""Every input file zkzap reads by name is opened here, so that one it cannot open twice is read
once.

A regular file can be opened as often as a reader likes: a peek at its first bytes (is it a
pcapng capture? text or bytes?) and then the reading itself. A named pipe, a process
substitution (``<(cat run.csv)``: ``/dev/fd/63``, a pipe) or a character device cannot: a second
``open()`` of a FIFO waits for a second writer, a pipe's bytes go to whoever read them first, and
the peeked bytes were lost. :func:`open_input` gives every reader of such an input its own view
of the same stream, from its first byte: what the stream gave is kept for the later views up to
:data:`HEAD` bytes (what a peek reads), and the view that reads on past that reads the stream
itself, as it comes — so a live pipe is still decoded as its bytes arrive, in constant memory.
A view that would need bytes another view already took beyond :data:`HEAD` is an ``OSError``
naming it (no reader of zkzap does that).

:func:`reading` tells how far each regular file opened here has been read (for a progress
display). :func:`is_input` says whether a path names something to read (a file, a FIFO, a device: not a
directory, not missing) — never ``os.path.isfile``, which says no to a pipe.
"""

from __future__ import annotations

import io
import os
import stat
import weakref

#: The bytes of a stream kept for its later readers (a peek and a capture's first blocks).
HEAD = 1 << 16

_shared: dict = {}


def is_input(path) -> bool:
    """Whether ``path`` names something that can be read: not missing and not a directory."""
    try:
        return not stat.S_ISDIR(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


def regular(path) -> bool:
    """Whether ``path`` is a regular file (which may be opened and read again)."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


def open_input(path):
    """``path`` opened for reading bytes (a buffered binary stream); see the module's text. An
    ``OSError`` as from :func:`open`."""
    if regular(path) or not is_input(path):
        f = open(path, "rb")              # a regular file, or open's own error (missing, a directory)
        _track(f, path)
        return f
    st = os.stat(path)
    key = (st.st_dev, st.st_ino, st.st_rdev)
    shared = _shared.get(key)
    if shared is None or shared.closed:
        shared = _shared[key] = _Shared(open(path, "rb", buffering=0), str(path))
    return io.BufferedReader(_View(shared), buffer_size=1 << 16)


#: The regular files :func:`open_input` opened: (a weak reference to the stream, path, size).
_open: list = []


def _track(f, path) -> None:
    try:
        size = os.fstat(f.fileno()).st_size
    except OSError:
        return
    _open[:] = [x for x in _open if (s := x[0]()) is not None and not s.closed]
    _open.append((weakref.ref(f), str(path), size))


#: The streams of unknown size being read (pipes, FIFOs, devices, stdin): weak references to
#: objects with ``name``, ``taken`` (bytes read so far) and ``being_read``.
_streams: list = []


def _track_stream(obj) -> None:
    _streams[:] = [x for x in _streams if (s := x()) is not None and not s.closed]
    _streams.append(weakref.ref(obj))


#: Paths shown under another name by :func:`reading` (a temporary copy of stdin: ``stdin``).
_names: dict = {}


def shown_as(path, name: str) -> None:
    """:func:`reading` names ``path`` ``name`` (None: its own name again)."""
    if name is None:
        _names.pop(str(path), None)
    else:
        _names[str(path)] = name


def reading() -> list:
    """``[(path, bytes read, size)]`` of the inputs open for reading now, for a progress
    display: the regular files (bytes read: the file's offset, a buffer ahead of its reader at
    most) and the streams of unknown size (pipes, FIFOs, stdin: size None); safe to call from
    another thread."""
    out = []
    for ref in list(_streams):
        s = ref()
        if s is not None and s.being_read:
            out.append((s.name, s.taken, None))
    for ref, path, size in list(_open):
        f = ref()
        if f is None or f.closed:
            continue
        try:
            pos = os.lseek(f.fileno(), 0, os.SEEK_CUR)
        except (OSError, ValueError):
            continue
        out.append((_names.get(path, path), min(pos, size), size))
    return out


class _Shared:
    """One stream read once, its first :data:`HEAD` bytes kept for every view."""

    def __init__(self, raw, name):
        self.raw, self.name = raw, name
        self.head = bytearray()
        self.taken = 0                    # bytes of the stream read so far (beyond head: not kept)
        self.views = 0
        self.closed = False
        self.ended = False                # the stream gave its end: nothing more is read from it
        _track_stream(self)

    def read_at(self, pos: int, n: int) -> bytes:
        if pos < len(self.head):
            return bytes(self.head[pos:pos + n])
        if pos != self.taken:
            raise OSError(f"{self.name}: a stream read once, and its bytes at {pos} were read by another reader")
        if self.ended:
            return b""
        block = self.raw.read(n)
        if not block and n:
            self.ended = True             # its end: no longer an input being read
        if block:
            if self.taken < HEAD and len(self.head) == self.taken:
                self.head += block[:HEAD - len(self.head)]
            self.taken += len(block)
        return block or b""

    @property
    def being_read(self) -> bool:
        """Open, not at its end, and a reader has it open (a peeked and closed one is not)."""
        return not self.closed and not self.ended and self.views > 0

    def release(self):
        self.views -= 1
        if self.views <= 0 and self.taken > HEAD:
            self.close()                  # nothing later can read it from its start

    def close(self):
        if not self.closed:
            self.closed = True
            self.raw.close()


class _View(io.RawIOBase):
    """One reader's view of a :class:`_Shared` stream, from its first byte."""

    def __init__(self, shared):
        super().__init__()
        self._s = shared
        self._pos = 0
        shared.views += 1

    def readable(self):
        return True

    def seekable(self):
        return True

    def fileno(self):
        return self._s.raw.fileno()

    def readinto(self, b):
        data = self._s.read_at(self._pos, len(b))
        b[:len(data)] = data
        self._pos += len(data)
        return len(data)

    def tell(self):
        return self._pos

    def seek(self, pos, whence=0):
        if whence == 1:
            pos += self._pos
        if whence == 2 or pos < 0 or (pos != self._pos and pos > len(self._s.head)):
            raise io.UnsupportedOperation(f"{self._s.name}: a stream is read once, in order")
        self._pos = pos
        return pos

    def close(self):
        if not self.closed:
            self._s.release()
        super().close()


class _Counting(io.RawIOBase):
    """A stream read through, its bytes counted (``taken``) for :func:`reading`."""

    def __init__(self, raw, name):
        super().__init__()
        self._raw, self.name, self.taken = raw, name, 0
        _track_stream(self)

    @property
    def being_read(self) -> bool:
        return not self.closed

    def readable(self):
        return True

    def readinto(self, b):
        data = self._raw.read(len(b))
        n = len(data)
        b[:n] = data
        self.taken += n
        return n


def counted(stream, name: str = "stdin"):
    """``stream`` (binary, read once: stdin) read through a counter of its bytes, so that a
    progress display can say how much of it was read (:func:`reading`, size unknown)."""
    return io.BufferedReader(_Counting(stream, name), buffer_size=1 << 16)
