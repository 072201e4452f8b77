"""Open a port by device path or URL, exclusively, with errors mapped to exit codes.

Any pyserial URL works (``socket://``, ``rfc2217://``, ``loop://``, ``spy://``,
``hwgrep://``), and ``sim://zk`` / ``sim://zap?ids=1,2`` run a built-in simulator in-process.
"""

from __future__ import annotations

from ..errors import PortError, UsageError

_HANDLERS = "zkzap.link"


def wire_time(nbytes: int, baud: int) -> float:
    """Seconds ``nbytes`` take on the line (start + 8 data + stop bits)."""
    return nbytes * 10.0 / baud


def open_port(url: str, baud: int, *, timeout=None, write_timeout=None):
    """A pyserial port for ``url`` at ``baud``, opened exclusively where the OS allows."""
    import serial

    if _HANDLERS not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(_HANDLERS)
    try:
        port = serial.serial_for_url(url, baudrate=baud, timeout=timeout, write_timeout=write_timeout,
                                     exclusive=True)
        _no_delay(port)
        return port
    except ValueError as e:
        raise UsageError(f"port: {url}: {e}") from None
    except (serial.SerialException, OSError) as e:
        text = str(e)
        if "could not open port" in text or "No such file" in text or "Errno" in text:
            raise PortError(f"port {url}: cannot open: {_short(e)}") from None
        raise PortError(f"port {url}: {_short(e)}") from None


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
    text = str(e)
    if isinstance(e, OSError) and e.strerror:
        return e.strerror
    return text.split(": ", 1)[-1] if text.startswith("[Errno") else text
