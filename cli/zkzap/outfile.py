"""Every file zkzap writes goes through here: records, raw logs, captures, MCAP logs, reports,
summaries, backups, state files, steps, so that no run loses what it did not mean to replace.

- :func:`refuse_same_files`: an output that is also an input (``zk decode x.pcapng -o
  x.pcapng``, through a symlink or a second name too: files are compared, not names) or two
  outputs naming one file is refused before anything is opened.
- :class:`OutFile`, a file written as the run goes (records, raw bytes): :meth:`~OutFile.check`
  runs before the port opens (a directory, a missing directory, no permission; with
  ``--append`` whether the existing file can be continued: the same CSV header, JSON Lines, a
  JSON array); :meth:`~OutFile.open` happens only when the first record is ready
  (:class:`LazyOutput` opens it on the first write), so an output that received no record is
  left exactly as it was — a header is not a record. A regular file is written in place (a
  symlink's target); a device or FIFO is written through.
- :func:`write_whole` / :func:`replacing`, a file written whole (a summary, a backup, a report,
  a state file): onto a regular file atomically (a temporary file beside the target — the
  symlink's target, never the link — renamed over it, with the replaced file's mode); a device
  or a FIFO is written through (``/dev/full``: exit 7), never replaced by a regular file.

Opening a file is an effect: while a batch checks its lines (:mod:`zkzap.checking`) the command
stops there.
"""

from __future__ import annotations

import contextlib
import os
import stat
import sys

from . import checking
from .errors import OutputError, UsageError

_TAIL = 64


def identity(path):
    """(device, inode) of the file ``path`` names (through symlinks; ``-``: stdin when it is a
    regular file), or None."""
    try:
        st = os.stat(path) if path != "-" else os.fstat(sys.stdin.fileno())
    except (OSError, ValueError, AttributeError, TypeError):
        return None
    if path == "-" and not stat.S_ISREG(st.st_mode):
        return None                     # a pipe or a terminal is never one of our files
    return st.st_dev, st.st_ino


def _same(a, b) -> bool:
    """Whether two paths name one file: the same inode (any names, symlinks, hard links), or,
    for a file that does not exist yet, the same resolved path."""
    ia, ib = identity(a), identity(b)
    if ia is not None and ib is not None:
        return ia == ib
    if "-" in (a, b):
        return False
    return os.path.realpath(a) == os.path.realpath(b)


def _kind(path):
    """``"new"``, ``"regular"``, or ``"stream"`` (a device, FIFO or socket: written through)."""
    try:
        st = os.stat(path)
    except OSError:
        return "new"
    return "regular" if stat.S_ISREG(st.st_mode) else "dir" if stat.S_ISDIR(st.st_mode) else "stream"


def _paths(value):
    return [value] if isinstance(value, str) else [p for p in (value or ()) if p]


def device_of(path):
    """What ``path`` is on the machine, through symlinks: ``("dev", rdev)`` for a device node
    (two nodes of one device are one), else ``(st_dev, st_ino)``; None when it does not exist.
    ``-`` is stdout here (an output)."""
    try:
        st = os.fstat(sys.stdout.fileno()) if path == "-" else os.stat(path)
    except (OSError, ValueError, AttributeError, TypeError):
        return None
    if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode):
        return ("dev", st.st_rdev)
    return st.st_dev, st.st_ino


def port_path(url):
    """The file a port URL opens (``/dev/ttyUSB0``; ``spy:///dev/ttyUSB0``'s device), or None
    for a URL that opens none (``socket://``, ``sim://``, ``rfc2217://``)."""
    if not isinstance(url, str) or not url:
        return None
    if "://" not in url:
        return url
    scheme, _, rest = url.partition("://")
    if scheme.lower() == "spy":
        return rest.split("?", 1)[0] or None
    return None


def refuse_port_outputs(outputs: dict, ports) -> None:
    """Raise :class:`UsageError` when one of ``outputs`` (option -> path; ``-``: stdout) is the
    device (or file) one of ``ports`` (port URLs) opens: records, a capture or MAVLink written
    into the control line. Devices are compared, not names (a symlink to the port, another node
    of the same device)."""
    devices = [(url, device_of(p)) for url in ports for p in [port_path(url)] if p is not None]
    devices = [(url, d) for url, d in devices if d is not None]
    if not devices:
        return
    for opt, value in outputs.items():
        for path in _paths(value):
            d = device_of(path)
            for url, port in devices:
                if d is not None and d == port:
                    what = "stdout is" if path == "-" else f"{opt.lstrip('-')}: {path} is"
                    raise UsageError(f"{what} the port ({url}): what is written there would go onto the line")


def refuse_same_files(outputs: dict, inputs: dict = None) -> None:
    """Raise :class:`UsageError` when two of ``outputs`` (option -> path) name one file, or an
    output is one of ``inputs`` (option -> path or list of paths; ``-`` is stdin). Files are
    compared (:func:`identity`), not names."""
    outs = [(opt, p) for opt, value in outputs.items() for p in _paths(value) if p != "-"]
    ins = [(opt, p) for opt, value in (inputs or {}).items() for p in _paths(value)]
    for i, (opt, path) in enumerate(outs):
        if _kind(path) == "stream":
            continue                    # /dev/null twice, a FIFO: nothing to destroy
        for opt2, path2 in outs[i + 1:]:
            if _same(path, path2):
                raise UsageError(f"{opt.lstrip('-')}: {path} is also given to {opt2}; two outputs need two files")
        for opt2, path2 in ins:
            if _same(path, path2):
                where = "stdin" if path2 == "-" else path2
                raise UsageError(f"{opt.lstrip('-')}: {path} is also the input ({opt2} {where}); writing it would "
                                 f"destroy what is being read")


def _kernel_file(path) -> bool:
    """Whether ``path`` (or, when it does not exist, its directory) is on /proc or /sys: files of
    the kernel's interfaces, which take a value the kernel parses, not an output."""
    try:
        st = os.stat(path if os.path.exists(path) else os.path.dirname(os.path.abspath(path)) or ".")
    except OSError:
        return False
    for root in ("/proc", "/sys"):
        try:
            if os.stat(root).st_dev == st.st_dev and os.path.ismount(root):
                return True
        except OSError:
            continue
    return False


def _refuse_unwritable(path, what):
    """Refuse (exit 2) what no output can be: a symlink loop (or a path the system cannot
    resolve), a socket, a file of /proc or /sys."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        st = None
    except OSError as e:              # ELOOP, ENAMETOOLONG, ENOTDIR...
        raise UsageError(f"{what}: cannot open {path}: {e.strerror or e}") from None
    if st is not None and stat.S_ISSOCK(st.st_mode):
        raise UsageError(f"{what}: cannot open {path}: it is a socket (an output is a file, a device or a FIFO)")
    if (st is None or stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)) and _kernel_file(path):
        raise UsageError(f"{what}: cannot open {path}: a file of the kernel's /proc or /sys, not an output")


def check_path(path, what="output") -> str:
    """Refuse (exit 2) an output path that cannot be written: a directory, a missing directory,
    no permission, a symlink loop, a socket, a file of /proc or /sys. Returns its kind (``new``,
    ``regular``, ``stream``)."""
    _refuse_unwritable(path, what)
    kind = _kind(path)
    if kind == "dir":
        raise UsageError(f"{what}: cannot open {path}: Is a directory")
    if kind == "new":
        parent = os.path.dirname(os.path.abspath(os.path.realpath(path)))
        if not os.path.isdir(parent):
            raise UsageError(f"{what}: cannot open {path}: no such directory {parent}")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise UsageError(f"{what}: cannot open {path}: permission denied in {parent}")
    elif not os.access(path, os.W_OK):
        raise UsageError(f"{what}: cannot open {path}: Permission denied")
    return kind


def check_state(path, what="state") -> str:
    """A state file is read and rewritten whole: refuse (exit 2) what cannot be (a device, a
    FIFO, a directory, a path it cannot write); returns its kind (``new`` or ``regular``)."""
    kind = check_path(path, what)
    if kind == "stream":
        raise UsageError(f"{what}: {path} is not a regular file; a state file is read and rewritten whole")
    return kind


class OutFile:
    """An output file written as the run goes, checked early and opened late. ``fmt`` (csv,
    json, jsonl, table, or None) and ``columns`` (the CSV header) decide what ``--append`` may
    continue; ``binary`` for bytes (a raw log, an MCAP log)."""

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
        self.kind = None

    # --- before anything starts -----------------------------------------------------------
    def check(self) -> "OutFile":
        self.kind = check_path(self.path, self.what)
        if self.append and self.kind == "regular" and os.path.getsize(self.path) > 0:
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

    # --- when the first data is ready ----------------------------------------------------
    def open(self):
        if not self._checked:
            self.check()
        checking.effect("file", path=self.path)
        path = self.path
        try:
            if self._cut:
                with open(path, "rb+") as f:
                    f.truncate(max(0, f.seek(0, os.SEEK_END) - self._cut))
            mode = ("a" if self.append else "w") + ("b" if self.binary else "")
            if self.binary:
                self.stream = open(path, mode)
            else:
                self.stream = open(path, mode, encoding="utf-8", newline="")
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


class LazyOutput:
    """The stream of an :class:`OutFile` that opens (creates, truncates, cuts) it on the first
    write: a writer given it writes its header with its first record, and a run that wrote no
    record leaves the file exactly as it was. ``lazy`` tells the writers so."""

    lazy = True

    def __init__(self, out: OutFile):
        self.out = out
        self.name = out.path
        self.encoding = None if out.binary else "utf-8"
        self.errors = "strict"

    @property
    def opened(self) -> bool:
        """Whether the first write happened (the file is open)."""
        return self.out.stream is not None

    def _stream(self):
        return self.out.stream if self.out.stream is not None else self.out.open()

    def write(self, data):
        return self._stream().write(data)

    def fileno(self):
        return self._stream().fileno()

    def tell(self):
        return self._stream().tell()

    def seek(self, *args):
        return self._stream().seek(*args)

    def seekable(self) -> bool:
        return self._stream().seekable()

    def writable(self) -> bool:
        return True

    def flush(self):
        if self.out.stream is not None:
            self.out.stream.flush()

    @property
    def buffer(self):
        return self._stream().buffer

    @property
    def closed(self) -> bool:
        return self.out.stream is not None and self.out.stream.closed

    def isatty(self) -> bool:
        return False

    def close(self):
        self.out.close()


def lazy_stream(stream) -> bool:
    """Whether ``stream`` is a :class:`LazyOutput` no record has opened yet."""
    return getattr(stream, "lazy", False) and not stream.opened


def check_link(path, what="link") -> None:
    """Refuse (exit 2) a symlink path that would replace something else: only a missing path or
    an existing symlink may become the new symlink (never a file, a device or a directory)."""
    if os.path.lexists(path) and not os.path.islink(path):
        raise UsageError(f"{what}: {path} exists and is not a symlink; give a new path (only a symlink is "
                         f"replaced)")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise UsageError(f"{what}: cannot make {path}: no such directory {parent}")


def make_link(target, path) -> None:
    """Make ``path`` a symlink to ``target``, replacing an old symlink there (nothing else)."""
    check_link(path)
    checking.effect("file", path=path)
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    os.symlink(target, path)


# --- whole files ---------------------------------------------------------------------------

def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def replacing(path, *, what="output", suffix=".tmp"):
    """``with replacing(path) as tmp:`` write the whole new file to the path ``tmp`` (a writer
    that takes a file name: matplotlib, a database); when the block ends well it replaces
    ``path`` as :func:`write_whole` does. A failure leaves ``path`` as it was."""
    checking.effect("file", path=path)
    kind = check_path(path, what)
    target = os.path.realpath(path) if kind != "stream" else path
    directory = os.path.dirname(os.path.abspath(target)) if kind != "stream" else None
    import tempfile

    fd, tmp = tempfile.mkstemp(prefix=".zkzap-", suffix=suffix, dir=directory)
    os.close(fd)
    try:
        yield tmp
        if kind == "stream":
            with open(tmp, "rb") as src:
                _through(path, src.read(), what)
        else:
            _commit(tmp, target, kind)
            tmp = None
    except OSError as e:
        raise OutputError(f"{what}: cannot write {path}: {e.strerror or e}") from None
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def write_whole(path, data, *, what="output") -> None:
    """Write ``data`` (str: UTF-8, or bytes) to ``path`` whole or not at all: a regular file
    (or a symlink's target) is replaced atomically, keeping its mode (and, as root, its owner);
    a device or FIFO is written through. Exit 7 (:class:`OutputError`) when it cannot be."""
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    if _kind(path) == "stream":
        checking.effect("file", path=path)
        check_path(path, what)
        _through(path, raw, what)
        return
    with replacing(path, what=what) as tmp:
        with open(tmp, "wb") as f:
            f.write(raw)


#: The old name of :func:`write_whole`, for a text.
def write_atomic(path, text: str, what="output") -> None:
    write_whole(path, text, what=what)


def _through(path, raw, what):
    """Write ``raw`` to a device or FIFO as it is (no temporary file, no rename)."""
    try:
        with open(path, "wb") as f:
            f.write(raw)
            f.flush()
    except OSError as e:
        raise OutputError(f"{what}: cannot write {path}: {e.strerror or e}") from None


def _commit(tmp, target, kind):
    """Give ``tmp`` the replaced file's mode and owner (or the umask's mode), then rename it
    over ``target``."""
    try:
        if kind == "regular":
            st = os.stat(target)
            os.chmod(tmp, stat.S_IMODE(st.st_mode))
            if hasattr(os, "chown") and (st.st_uid, st.st_gid) != (os.geteuid(), os.getegid()):
                try:
                    os.chown(tmp, st.st_uid, st.st_gid)
                except OSError:
                    pass            # not ours to give away: the mode is kept all the same
        else:
            os.chmod(tmp, 0o666 & ~_umask())
    except OSError:
        pass
    os.replace(tmp, target)
