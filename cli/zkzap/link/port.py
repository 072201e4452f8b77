"""Open a port by device path or URL, exclusively, with errors mapped to exit codes.

Any pyserial URL works (``socket://``, ``rfc2217://``, ``loop://``, ``spy://``,
``hwgrep://``), and ``sim://zk`` / ``sim://zap?ids=1,2`` run a built-in simulator in-process.
"""

from __future__ import annotations

from ..errors import InvalidValue, PortError, UsageError

_HANDLERS = "zkzap.link"


#: Stop bits a line may use (8 data bits, no parity): the ZK document allows 1 or 2.
STOP_BITS = (1, 2)


def bits_per_byte(stop_bits: int = 1) -> int:
    """Bits one byte takes on an 8N1/8N2 line: start + 8 data + stop bits."""
    return 9 + stop_bits


def wire_time(nbytes: int, baud: int, stop_bits: int = 1) -> float:
    """Seconds ``nbytes`` take on the line (start + 8 data + ``stop_bits`` stop bits)."""
    return nbytes * (9.0 + stop_bits) / baud


def byte_rate(baud: int, stop_bits: int = 1) -> float:
    """Bytes per second the line carries at most."""
    return baud / (9.0 + stop_bits)


def line_load(rate_hz: float, frame_bytes: int, baud: int, stop_bits: int = 1) -> float:
    """The fraction of the line that ``rate_hz`` frames of ``frame_bytes`` a second take (above 1:
    they do not fit)."""
    return rate_hz * wire_time(frame_bytes, baud, stop_bits)


def fit_note(what: str, rate_hz: float, frame_bytes: int, baud: int, stop_bits: int = 1):
    """A one-line note when ``rate_hz`` frames of ``frame_bytes`` bytes do not fit the line, else None."""
    if not baud or line_load(rate_hz, frame_bytes, baud, stop_bits) <= 1.0:
        return None
    need = rate_hz * frame_bytes * (9 + stop_bits)
    most = byte_rate(baud, stop_bits) / frame_bytes
    return (f"{what}: {rate_hz:g} frames/s of {frame_bytes} bytes need {need:,.0f} baud at 8N{stop_bits}; "
            f"{baud} baud carries at most {most:.1f} a second")


def open_port(url: str, baud: int, *, timeout=None, write_timeout=None, stop_bits: int = 1, capture=None,
              speaks=None):
    """A pyserial port for ``url`` at ``baud`` (8 data bits, no parity, ``stop_bits`` 1 or 2),
    opened exclusively where the OS allows; recorded to a pcapng capture when one was asked for
    (``capture`` = (path, protocol), else the one named by :func:`zkzap.link.capture.request`;
    ``speaks``: the link's protocol where it is not the capture's, ``modbus`` on a mightyZAP bus).
    A ``url`` that is no string or a ``baud`` that is no positive integer is an InvalidValue."""
    if not isinstance(url, str):
        raise InvalidValue(f"port: {url!r} is not a device path or URL", port=url)
    if isinstance(baud, bool) or not isinstance(baud, int) or baud <= 0:
        raise InvalidValue(f"baud: {baud!r} is not a baud rate (a positive integer)", baud=baud)
    _check_url(url)
    import serial

    if stop_bits not in STOP_BITS:
        raise UsageError(f"stop-bits: {stop_bits!r}; allowed 1, 2")
    from .. import checking

    checking.effect("port", url=url)
    if _HANDLERS not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(_HANDLERS)
    try:
        port = serial.serial_for_url(url, baudrate=baud, timeout=timeout, write_timeout=write_timeout,
                                     exclusive=True, stopbits=stop_bits)
        _no_delay(port)
        return _tap(port, url, baud, capture, speaks)
    except InvalidValue:
        raise                        # a sim:// URL's option, named by the simulator
    except ValueError as e:
        raise UsageError(f"port: {url}: {e}") from None
    except (serial.SerialException, OSError) as e:
        if _busy(e):
            raise in_use(url) from None
        text = str(e)
        if "could not open port" in text or "No such file" in text or "Errno" in text:
            raise PortError(f"port {url}: cannot open: {_short(e)}") from None
        raise PortError(f"port {url}: {_short(e)}") from None


def open_within(within: float, url: str, baud: int, **kw):
    """:func:`open_port`, given up after ``within`` real seconds with a PortError ("no answer
    within ...") when the open has not ended by then: a TCP connect to a host or server that does
    not answer hangs for pyserial's 5 s, a USB device being re-enumerated can block in open().
    The attempt goes on in its own thread; a port it opens after it was given up is closed."""
    import threading

    done = threading.Event()
    lock = threading.Lock()
    state = {"abandoned": False}

    def attempt():
        try:
            state["port"] = open_port(url, baud, **kw)
        except BaseException as e:  # noqa: BLE001 - handed to the caller as it is
            state["error"] = e
        with lock:
            if state["abandoned"] and "port" in state:
                close_port(state["port"])
            done.set()

    threading.Thread(target=attempt, name="zkzap-open", daemon=True).start()
    done.wait(max(0.0, within))
    with lock:
        if not done.is_set():
            state["abandoned"] = True
            raise PortError(f"port {url}: cannot open: no answer within {within:.2g} s", url=url)
    if "error" in state:
        raise state["error"]
    return state["port"]


def _busy(e) -> bool:
    """Whether an open failed because another program holds the device (its exclusive lock,
    which pyserial reports as "Resource temporarily unavailable", or the tty's own TIOCEXCL)."""
    import errno

    return getattr(e, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EBUSY) \
        or "exclusively lock" in str(e)


def in_use(url: str) -> PortError:
    """The PortError of a device another program holds, naming the programs where the OS tells
    (``holders``: [(pid, command)])."""
    found = holders(url)
    by = ", ".join(f"{cmd} (PID {pid})" for pid, cmd in found)
    return PortError(f"port {url}: in use by another program" + (f": {by}" if by else ""), busy=True,
                     holders=found, url=url)


def holders(device: str) -> list:
    """``[(pid, command line)]`` of the other processes holding ``device``: the holder of its
    lock (``/proc/locks``), else every process that has it open, as far as ``/proc`` shows this
    user (Linux; an empty list elsewhere, or when nothing can be seen). Best effort, for
    messages only."""
    import os
    import stat

    try:
        st = os.stat(device)
    except OSError:
        return []
    locked = _lock_holders(st)
    if locked:
        return [(pid, _command(pid)) for pid in locked]
    char = stat.S_ISCHR(st.st_mode)
    want = st.st_rdev if char else (st.st_dev, st.st_ino)
    me = os.getpid()
    out = []
    try:
        pids = [int(p) for p in os.listdir("/proc") if p.isdigit()]
    except OSError:
        return []
    for pid in sorted(pids):
        if pid == me:
            continue
        fd_dir = f"/proc/{pid}/fd"
        try:
            fds = os.listdir(fd_dir)
        except OSError:
            continue                    # another user's process, or gone
        for fd in fds:
            try:
                fst = os.stat(os.path.join(fd_dir, fd))
            except OSError:
                continue
            if (fst.st_rdev if char and stat.S_ISCHR(fst.st_mode) else (fst.st_dev, fst.st_ino)) == want:
                out.append((pid, _command(pid)))
                break
    return out


def _lock_holders(st) -> list:
    """PIDs holding a lock on the file of ``st`` (``/proc/locks``: ``... PID MAJ:MIN:INODE ...``)."""
    import os

    key = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    pids = []
    try:
        with open("/proc/locks", encoding="ascii", errors="replace") as f:
            for line in f:
                words = line.split()
                if key in words and "->" not in words:
                    pid = words[words.index(key) - 1]
                    if pid.isdigit() and int(pid) != os.getpid() and int(pid) not in pids:
                        pids.append(int(pid))
    except (OSError, ValueError):
        return []
    return pids


def _command(pid: int) -> str:
    """A process's command line, shortened: ``zk monitor -p /dev/ttyUSB0`` (not the interpreter)."""
    import os

    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            words = f.read(4096).decode("utf-8", "replace").split("\0")
    except OSError:
        words = []
    words = [w for w in words if w]
    if not words:
        return "?"
    words[0] = os.path.basename(words[0])
    if words[0].startswith("python") and len(words) > 1 and not words[1].startswith("-"):
        words = [os.path.basename(words[1])] + words[2:]
    text = " ".join(words)
    return text if len(text) <= 80 else text[:77] + "..."


#: URL schemes that need HOST:PORT (pyserial's own check fails with a TypeError's text).
_NETWORK = ("socket", "rfc2217")


def _check_url(url: str) -> None:
    """Refuse a network URL without HOST:PORT before pyserial sees it (exit 2, one line)."""
    scheme, sep, rest = url.partition("://")
    if not sep or scheme.lower() not in _NETWORK:
        return
    from urllib.parse import urlsplit

    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError:
        port = None
        parts = None
    if parts is None or not parts.hostname or port is None:
        raise UsageError(f"port: {url}: expected {scheme}://HOST:PORT (a host name or address and a port "
                         f"number 0..65535)")
def _tap(port, url, baud, capture, speaks=None):
    import sys

    if not capture and "zkzap.link.capture" not in sys.modules:
        return port                      # no capture asked for (nothing imported the module)
    from .capture import tap

    try:
        return tap(port, url, baud, capture, speaks=speaks)
    except BaseException:
        close_port(port)
        raise


def _no_delay(port) -> None:
    """Send small frames at once on a socket:// port (pyserial leaves Nagle's algorithm on: a
    command that gets no reply would hold the next one back until a delayed ACK, ~40 ms)."""
    sock = getattr(port, "_socket", None)
    if sock is None:
        return
    try:
        import socket

        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    except (OSError, AttributeError):
        pass


def close_port(port) -> None:
    """Close ``port``; a socket:// port without pyserial's 0.3 s pause "for quick reconnects"
    (a simulator or ser2net-style server takes the next client at once). Never raises: closing
    a vanished port must not mask the error that ended its use."""
    sock = getattr(port, "_socket", None)
    try:
        if sock is not None and getattr(port, "is_open", False):
            import socket

            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()
            port._socket = None
            port.is_open = False
        else:
            port.close()
    except Exception:  # noqa: BLE001 - serial.SerialException, OSError from a vanished device
        pass


def sim_url(kind: str, **options) -> str:
    """``sim://KIND?k=v&...`` for the in-process simulator."""
    from urllib.parse import urlencode

    query = urlencode({k: v for k, v in options.items() if v is not None})
    return f"sim://{kind}" + (f"?{query}" if query else "")


def port_failed(url: str, e) -> PortError:
    """The one wording of a port that failed or vanished in use, for every protocol:
    ``port URL failed: REASON`` — the OS's reason in words, without pyserial's ``[Errno N]``
    prefix or a Python tuple (``(5, 'Input/output error')``, as termios errors print)."""
    return PortError(f"port {url} failed: {reason(e)}", url=url)


#: pyserial's words for a device that went away under a read, and plainer ones.
_VANISHED = ("device reports readiness to read but returned no data",
             "the device went away (it reports data to read but returns none: unplugged, or another program "
             "reads it)")


def reason(e, os_part: bool = False) -> str:
    """What went wrong, in the OS's words: ``Input/output error`` for ``OSError(5, ...)`` and
    ``termios.error(5, 'Input/output error')``, ``read failed: Input/output error`` for
    pyserial's ``read failed: [Errno 5] Input/output error`` (``os_part``: only the OS's part
    of such a text)."""
    import re

    if isinstance(e, OSError) and isinstance(e.strerror, str) and e.strerror and not e.strerror.startswith("["):
        text = e.strerror
    else:
        args = getattr(e, "args", ())
        if len(args) >= 2 and isinstance(args[0], int) and isinstance(args[1], str):
            text = args[1]                              # termios.error, select.error: (errno, text)
        elif len(args) == 1 and isinstance(args[0], BaseException):
            return reason(args[0])
        else:
            text = str(e)
    m = None
    for m in re.finditer(r"\[Errno \d+\] ", text):
        pass
    if m is not None:                   # "could not open port X: [Errno 2] No such file ..."
        text = text[m.end():] if os_part else text[:m.start()] + text[m.end():]
    # an error's tuple inside pyserial's text: "(5, 'Input/output error')", "PermissionError(13, '...', ...)"
    text = re.sub(r"(?:\b\w+)?\((\d+), '([^']*)'[^)]*\)", r"\2", text)
    if text.startswith(_VANISHED[0]):
        text = _VANISHED[1]
    return text or type(e).__name__


def _short(e) -> str:
    return reason(e, os_part=True)
