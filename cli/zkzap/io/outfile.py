"""Output files named on the command line (``-o``, ``--raw-log``, ``--summary-json``), handled so
that no run loses data it did not mean to replace.

- :func:`refuse_same_files`: an output that is also an input (``zk decode --binary x.bin -o
  x.bin``), or two outputs naming one file (``-o log --raw-log log``), is refused before
  anything is opened.
- :class:`OutFile`: :meth:`~OutFile.check` runs before the port opens (a directory, a missing
  directory, no permission; with ``--append`` whether the existing file can be continued: the
  same CSV header, JSON Lines, or a JSON array); :meth:`~OutFile.open` truncates or appends
  only when the first data is ready, so a run that fails to start leaves an existing file
  as it was. Appending starts on a new line after a cut last line, continues a JSON array
  (the writer is told with ``header=False``), and never writes a second CSV header.
- :func:`write_atomic`: a whole small file (a summary) through a temporary file and a rename.
"""

from __future__ import annotations

import os
import sys

from ..errors import OutputError, UsageError

_TAIL = 64


def _identity(path):
    """(device, inode) of an existing file, or None."""
    try:
        st = os.stat(path) if path != "-" else os.fstat(sys.stdin.fileno())
    except (OSError, ValueError, AttributeError):
        return None
    import stat

    if path == "-" and not stat.S_ISREG(st.st_mode):
        return None                     # a pipe or a terminal is never one of our files
    return st.st_dev, st.st_ino


def refuse_same_files(outputs: dict, inputs: dict = None) -> None:
    """Raise :class:`UsageError` when two of ``outputs`` (option -> path) name one file, or an
    output is one of ``inputs`` (option -> path or list of paths; ``-`` is stdin)."""
    outs = [(opt, p) for opt, p in outputs.items() if p and p != "-"]
    ins = []
    for opt, paths in (inputs or {}).items():
        for p in ([paths] if isinstance(paths, str) else list(paths or ())):
            if p:
                ins.append((opt, p))

    def same(a, b):
        if a != "-" and b != "-" and os.path.realpath(a) == os.path.realpath(b):
            return True
        ia, ib = _identity(a), _identity(b)
        return ia is not None and ia == ib

    for i, (opt, path) in enumerate(outs):
        for opt2, path2 in outs[i + 1:]:
            if same(path, path2):
                raise UsageError(f"{opt.lstrip('-')}: {path} is also given to {opt2}; two outputs need two files")
        for opt2, path2 in ins:
            if same(path, path2):
                where = "stdin" if path2 == "-" else path2
                raise UsageError(f"{opt.lstrip('-')}: {path} is also the input ({opt2} {where}); writing it would "
                                 f"destroy what is being read")


class OutFile:
    """An output file, checked early and opened late. ``fmt`` (csv, json, jsonl, table, or
    None for bytes) and ``columns`` (the CSV header) decide what ``--append`` may continue."""

    def __init__(self, path, *, append=False, fmt=None, columns=None, binary=False, what="output"):
        self.path = path
        self.append = append
        self.fmt = fmt
        self.columns = list(columns) if columns is not None else None
        self.binary = binary
        self.what = what
        self.stream = None
        self.had = False            # appending to existing content: no second header
        self._cut = 0               # bytes to drop from the end (a JSON array's closing bracket)
        self._newline = False       # the existing content ends in a cut line
        self._checked = False

    # --- before anything starts -----------------------------------------------------------
    def check(self) -> "OutFile":
        path, what = self.path, self.what
        if os.path.isdir(path):
            raise UsageError(f"{what}: cannot open {path}: Is a directory")
        parent = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(parent):
            raise UsageError(f"{what}: cannot open {path}: no such directory {parent}")
        if os.path.exists(path):
            if not os.access(path, os.W_OK):
                raise UsageError(f"{what}: cannot open {path}: Permission denied")
        elif not os.access(parent, os.W_OK | os.X_OK):
            raise UsageError(f"{what}: cannot open {path}: permission denied in {parent}")
        if self.append and os.path.isfile(path) and os.path.getsize(path) > 0:
            self.had = True
            self._check_append()
        self._checked = True
        return self

    def _check_append(self):
        path, what = self.path, self.what
        try:
            with open(path, "rb") as f:
                first = f.readline(1 << 16)
                size = f.seek(0, os.SEEK_END)
                f.seek(max(0, size - _TAIL))
                tail = f.read()
        except OSError as e:
            raise UsageError(f"{what}: cannot read {path} to append to it: {e.strerror}") from None
        if self.binary:
            return
        self._newline = not tail.endswith(b"\n")
        head = first.lstrip()[:1]
        if self.fmt == "csv":
            header = first.rstrip(b"\r\n").decode("utf-8", "replace")
            if self.columns is not None and header != ",".join(self.columns):
                shown = header if len(header) <= 60 else header[:57] + "..."
                raise UsageError(
                    f"append: {path} has other CSV columns ({shown}); this run writes {len(self.columns)} "
                    f"columns ({','.join(self.columns[:4])},...): use the options of the run that wrote it "
                    f"(--ids, --snapshot/--frames, --accept, --raw), or another file")
        elif self.fmt == "jsonl":
            if head != b"{":
                raise UsageError(f"append: {path} is not JSON Lines (it starts {first[:20]!r}); "
                                 f"append to a file of the same format")
        elif self.fmt == "json":
            if head != b"[":
                raise UsageError(f"append: {path} is not a JSON array (it starts {first[:20]!r}); "
                                 f"append to a file of the same format")
            body = tail.rstrip()
            if body.endswith(b"]"):
                self._cut = len(tail) - len(body) + 1       # the closing bracket and what follows
                rest = body[:-1].rstrip()
                if rest.endswith(b"[") and size <= _TAIL:
                    self._cut, self.had = size, False       # "[]": start the array afresh
                self._newline = False
            elif body.endswith(b"}"):
                self._newline = False                      # an array a killed run left open
            else:
                raise UsageError(f"append: {path} does not end in a whole JSON record; "
                                 f"append to a whole JSON array (or use jsonl)")
        elif self.fmt == "table":
            pass

    # --- when the first data is ready ----------------------------------------------------
    def open(self):
        if not self._checked:
            self.check()
        path = self.path
        try:
            if self._cut:
                with open(path, "rb+") as f:
                    f.truncate(max(0, f.seek(0, os.SEEK_END) - self._cut))
            if self.binary:
                self.stream = open(path, "ab" if self.append else "wb")
            else:
                self.stream = open(path, "a" if self.append else "w", encoding="utf-8", newline="")
                if self._newline:
                    self.stream.write("\n")
                    self.stream.flush()
        except OSError as e:
            raise OutputError(f"{self.what}: cannot write {path}: {e.strerror}") from None
        return self.stream

    # --- a byte sink (a raw log) opened by its first write -------------------------------
    def write(self, data) -> None:
        if self.stream is None:
            self.open()
        try:
            self.stream.write(data)
        except OSError as e:
            self._fail(e)

    def flush(self) -> None:
        if self.stream is None:
            return
        try:
            self.stream.flush()
        except OSError as e:
            self._fail(e)

    def _fail(self, e):
        try:
            # what could not be written is dropped, so closing does not fail again
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self.stream.fileno())
            os.close(null)
        except (OSError, ValueError):
            pass
        raise OutputError(f"{self.what}: cannot write {self.path}: {e.strerror or e}") from None

    def close(self) -> None:
        if self.stream is not None and not self.stream.closed:
            try:
                self.stream.close()
            except OSError:
                pass


def write_atomic(path, text: str, what="output") -> None:
    """Write ``text`` to ``path`` whole or not at all (a temporary file beside it, renamed)."""
    import tempfile

    directory = os.path.dirname(os.path.abspath(path))
    fd = None
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=".", suffix=".tmp", dir=directory)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            fd = None
            f.write(text)
        try:
            os.chmod(tmp, 0o666 & ~_umask())
        except OSError:
            pass
        os.replace(tmp, path)
        tmp = None
    except OSError as e:
        raise OutputError(f"{what}: cannot write {path}: {e.strerror or e}") from None
    finally:
        if fd is not None:
            os.close(fd)
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
