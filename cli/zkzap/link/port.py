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


def open_port(url: str, baud: int, *, timeout=None, write_timeout=None, stop_bits: int = 1, capture=None):
    """A pyserial port for ``url`` at ``baud`` (8 data bits, no parity, ``stop_bits`` 1 or 2),
    opened exclusively where the OS allows; recorded to a pcapng capture when one was asked for
    (``capture`` = (path, protocol), else the one named by :func:`zkzap.link.capture.request`).
    A ``url`` that is no string or a ``baud`` that is no positive integer is an InvalidValue."""
    if not isinstance(url, str):
        raise InvalidValue(f"port: {url!r} is not a device path or URL", port=url)
    if isinstance(baud, bool) or not isinstance(baud, int) or baud <= 0:
        raise InvalidValue(f"baud: {baud!r} is not a baud rate (a positive integer)", baud=baud)
    _check_url(url)
    import serial

    if stop_bits not in STOP_BITS:
        raise UsageError(f"stop-bits: {stop_bits!r}; allowed 1, 2")
    if _HANDLERS not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(_HANDLERS)
    try:
        port = serial.serial_for_url(url, baudrate=baud, timeout=timeout, write_timeout=write_timeout,
                                     exclusive=True, stopbits=stop_bits)
        _no_delay(port)
        return _tap(port, url, baud, capture)
    except InvalidValue:
        raise                        # a sim:// URL's option, named by the simulator
    except ValueError as e:
        raise UsageError(f"port: {url}: {e}") from None
    except (serial.SerialException, OSError) as e:
        text = str(e)
        if "could not open port" in text or "No such file" in text or "Errno" in text:
            raise PortError(f"port {url}: cannot open: {_short(e)}") from None
        raise PortError(f"port {url}: {_short(e)}") from None


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
def _tap(port, url, baud, capture):
    import sys

    if not capture and "zkzap.link.capture" not in sys.modules:
        return port                      # no capture asked for (nothing imported the module)
    from .capture import tap

    try:
        return tap(port, url, baud, capture)
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
    ``port URL failed: REASON`` (the OS's reason without its ``[Errno N]`` prefix)."""
    import re

    text = re.sub(r"\[Errno \d+\] ", "", str(e)) or type(e).__name__
    return PortError(f"port {url} failed: {text}")


def _short(e) -> str:
    import re

    text = e.strerror if isinstance(e, OSError) and isinstance(e.strerror, str) and e.strerror else str(e)
    m = re.search(r"\((\d+), '([^']*)'\)", text)    # pyserial: "Could not configure port: (25, '...')"
    if m:
        return text[:m.start()] + m.group(2)
    if "[Errno" in text:            # "Could not open port X: [Errno 111] Connection refused"
        return text[text.rindex("[Errno"):].split("] ", 1)[-1]
    return text
