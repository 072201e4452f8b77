"""Open a port by device path or URL, exclusively, with errors mapped to exit codes.

Any pyserial URL works (``socket://``, ``rfc2217://``, ``loop://``, ``spy://``,
``hwgrep://``), and ``sim://zk`` / ``sim://zap?ids=1,2`` run a built-in simulator in-process.
"""

from __future__ import annotations

from ..errors import PortError, UsageError

_HANDLERS = "zkzap.link"


def byte_time(baud: int) -> float:
    """Seconds one byte takes on the wire (start + 8 data + stop bits)."""
    return 10.0 / baud


def open_port(url: str, baud: int, *, timeout=None, write_timeout=None):
    """A pyserial port for ``url`` at ``baud``, opened exclusively where the OS allows."""
    import serial

    if _HANDLERS not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(_HANDLERS)
    try:
        return serial.serial_for_url(url, baudrate=baud, timeout=timeout, write_timeout=write_timeout,
                                     exclusive=True)
    except ValueError as e:
        raise UsageError(f"port: {url}: {e}") from None
    except (serial.SerialException, OSError) as e:
        text = str(e)
        if "could not open port" in text or "No such file" in text or "Errno" in text:
            raise PortError(f"port {url}: cannot open: {_short(e)}") from None
        raise PortError(f"port {url}: {_short(e)}") from None


def sim_url(kind: str, **options) -> str:
    """``sim://KIND?k=v&...`` for the in-process simulator."""
    from urllib.parse import urlencode

    query = urlencode({k: v for k, v in options.items() if v is not None})
    return f"sim://{kind}" + (f"?{query}" if query else "")


def _short(e) -> str:
    text = str(e)
    if isinstance(e, OSError) and e.strerror:
        return e.strerror
    return text.split(": ", 1)[-1] if text.startswith("[Errno") else text
