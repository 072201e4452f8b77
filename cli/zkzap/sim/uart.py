"""What a UART receiver makes of bytes sent at other line settings.

A simulator that knows both ends' settings (on a pty the host's termios settings, behind
``sim://`` the port's) passes its output through :func:`reframe`, so a host listening at
another baud rate or stop-bit setting sees what a real one would: misframed garbage, not clean
frames. The model, for 8 data bits and no parity:

- the sender's bytes in one chunk go out back to back (start bit 0, 8 data bits LSB first,
  ``stop_bits`` 1s), the line idles high before and after;
- the receiver hunts for a falling edge, samples the middle of each of its own bit times
  (start, 8 data, then EVERY stop bit it expects: a strict receiver), and delivers the data
  bits; a start bit that is no longer low is a glitch and is skipped; a stop bit sampled low
  is a framing error, and the byte is delivered as ``0x00`` (what a POSIX tty does without
  ``IGNPAR``/``PARMRK``, pyserial's raw mode);
- a receiver that expects fewer stop bits than the sender uses reads the frames cleanly (the
  extra stop bits are idle line to it). One expecting more stop bits than the sender sends
  gets framing errors on back-to-back bytes: that is how a 1- and a 2-stop-bit device are
  told apart. Real UARTs differ here (many check only the first stop bit); the strict model is
  documented in the manual (docs/how-to/zk-line.md).
"""

from __future__ import annotations

DATA_BITS = 8


def _bits(data: bytes, stop_bits: int) -> list:
    out = []
    for b in data:
        out.append(0)
        out.extend((b >> i) & 1 for i in range(DATA_BITS))
        out.extend([1] * stop_bits)
    return out


def reframe(data: bytes, tx_baud: int, tx_stop: int, rx_baud: int, rx_stop: int) -> bytes:
    """The bytes a receiver at ``rx_baud``/``rx_stop`` reads from ``data`` sent at
    ``tx_baud``/``tx_stop`` (one burst, back to back). Same baud and no more stop bits
    expected than sent: ``data`` unchanged."""
    if not data:
        return b""
    if tx_baud == rx_baud and rx_stop <= tx_stop:
        return bytes(data)
    bits = _bits(data, tx_stop)
    n = len(bits)
    tx_bit = 1.0 / tx_baud
    rx_bit = 1.0 / rx_baud
    frame_bits = 1 + DATA_BITS + rx_stop

    def level(t):
        k = int(t / tx_bit + 1e-9)
        return bits[k] if 0 <= k < n else 1

    out = bytearray()
    k = 0                                  # next tx bit boundary to look at for a falling edge
    while True:
        # the next falling edge at or after boundary k: a 0 bit after a 1 (or after idle)
        while k < n and not (bits[k] == 0 and (k == 0 or bits[k - 1] == 1)):
            k += 1
        if k >= n:
            break
        edge = k * tx_bit
        if level(edge + 0.5 * rx_bit) != 0:
            k += 1                         # a glitch shorter than half a receiver bit
            continue
        value = 0
        for j in range(DATA_BITS):
            value |= level(edge + (1.5 + j) * rx_bit) << j
        framing = any(level(edge + (1.5 + DATA_BITS + s) * rx_bit) == 0 for s in range(rx_stop))
        out.append(0 if framing else value)
        # hunt again from the last sample on
        resume = edge + (frame_bits - 0.5) * rx_bit
        k = max(k + 1, int(resume / tx_bit + 1e-9) + 1)
    return bytes(out)


class Line:
    """A device's line settings: ``baud`` (None: whatever the host uses) and ``stop_bits``."""

    __slots__ = ("baud", "stop_bits")

    def __init__(self, baud=None, stop_bits=1):
        self.baud = baud
        self.stop_bits = stop_bits

    def to_host(self, data: bytes, host_baud, host_stop) -> bytes:
        """``data`` as a host at ``host_baud``/``host_stop`` receives it (unknown host settings:
        as sent)."""
        if host_baud is None:
            return data
        return reframe(data, self.baud or host_baud, self.stop_bits, host_baud, host_stop or 1)

    def from_host(self, data: bytes, host_baud, host_stop) -> bytes:
        """``data`` the host sent, as this device's receiver reads it."""
        if host_baud is None or self.baud is None and (host_stop or 1) >= self.stop_bits:
            return data
        return reframe(data, host_baud, host_stop or 1, self.baud or host_baud, self.stop_bits)
