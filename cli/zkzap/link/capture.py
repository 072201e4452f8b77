"""``--capture FILE.pcapng``: a tap on the port object, so every command that opens a port
records what crossed it (see :mod:`zkzap.link.pcapng` for the format); :class:`CaptureFrames`
reads a capture back as frames.

:func:`request` names the capture a command asked for (the shared port options call it);
:func:`zkzap.link.port.open_port` then wraps the port it opens in a :class:`TappedPort`, which
writes every chunk read (inbound, device -> host) and written (outbound, host -> device) with
a microsecond timestamp. Several ports opened by one command share one file (one interface
each). Packets are written by a thread of their own (:mod:`zkzap.offload`), never by the
read or write that made them. A failed capture write (disk full) raises
:class:`~zkzap.errors.OutputError` from the next read or write, after cutting the file back to
its last whole block.
"""

from __future__ import annotations

from ..codec.framing import RtuFramer, ZapFramer, ZkFramer
from .clock import wall_now
from .pcapng import INBOUND, OUTBOUND, UNKNOWN, Reader, Writer

_requested = None      # (path, protocol) named by the command being run
_writer = None         # the Writer of that capture, opened with the first port
_lane = None           # the thread that writes its packets (zkzap.offload): never the port's caller


_kept = 0              # >0: commands run inside another (a batch's lines) leave the capture be


class keep:
    """Within: a command run inside another one (a line of a batch, which has no ``--capture``
    of its own) neither replaces nor ends the capture the outer command asked for."""

    def __enter__(self):
        global _kept
        _kept += 1
        return self

    def __exit__(self, *exc):
        global _kept
        _kept -= 1
        return False


def kept() -> bool:
    """Whether a :class:`keep` block runs."""
    return _kept > 0


def request(path, protocol: str) -> None:
    """Capture the ports this process opens from now on to ``path`` (None: stop asking);
    ``protocol`` ('zk'/'zap') selects the link type."""
    global _requested
    finish()
    if path:
        from ..outfile import check_path

        check_path(path, "capture")        # a bad path is an error before any port opens
    _requested = (path, protocol) if path else None


def requested():
    return _requested


def writer_for(path, protocol):
    """The shared Writer for ``path`` (checked by :func:`request`; opened by the first packet)."""
    global _writer
    if _writer is None or _writer.path != path:
        if _writer is not None:
            finish()
        _writer = Writer(path)
    return _writer


def lane():
    """The :class:`~zkzap.offload.Lane` the capture's packets are written in (None: no capture
    open)."""
    return _lane


def finish() -> None:
    """Close the capture file once its queued packets are written, and raise what writing
    them raised (:class:`~zkzap.errors.OutputError`). A capture that takes nothing for
    :data:`zkzap.offload.DRAIN_S` is left as it is (abandoned) and raises
    :class:`~zkzap.offload.Stalled`, unless that was said already."""
    global _writer, _lane
    if _writer is not None:
        w, lane_, _writer, _lane = _writer, _lane, None, None
        if lane_ is None:
            w.close()
        elif not lane_.finish(w.close):
            if not lane_.told:
                lane_.told = True
                raise lane_.stalled()
        else:
            lane_.check()


def tap(port, url: str, baud=None, capture=None, direction=None, speaks=None):
    """Wrap ``port`` when a capture is asked for (``capture``: (path, protocol), else the one
    :func:`request` named). ``direction`` fixes the direction of everything read (a sniffer's
    receive-only port on one side of a link); by default reads are inbound, writes outbound.
    ``speaks``: the protocol the port speaks when it is not the one the command asked the
    capture for (``modbus`` on a mightyZAP bus: the interface's link type says so)."""
    capture = capture if capture is not None else _requested
    if not capture:
        return port
    if speaks is not None:
        capture = (capture[0], speaks)
    global _lane
    from ..offload import Lane, Proxy

    path, protocol = capture
    w = writer_for(path, protocol)
    if_id = w.interface(protocol, url, baud)
    if _lane is None:
        _lane = Lane(f"--capture {path}")
    # packets are written off the port's path: a capture that stalls (a FIFO nobody reads) never
    # holds up a read or a control frame; its failure is raised by the next read or write
    return TappedPort(port, Proxy(w, _lane, ("packet",)), if_id, INBOUND if direction is None else direction)


class TappedPort:
    """A pyserial port whose reads and writes are recorded; everything else is the port's."""

    __slots__ = ("_port", "_writer", "_if", "_rx_dir")

    def __init__(self, port, writer, if_id, rx_dir=INBOUND):
        object.__setattr__(self, "_port", port)
        object.__setattr__(self, "_writer", writer)
        object.__setattr__(self, "_if", if_id)
        object.__setattr__(self, "_rx_dir", rx_dir)

    def read(self, size=1):
        data = self._port.read(size)
        if data:
            self._writer.packet(self._if, wall_now(), bytes(data), self._rx_dir)
        return data

    def write(self, data):
        ts = wall_now()
        n = self._port.write(data)
        sent = bytes(data) if n is None else bytes(data)[:n]
        self._writer.packet(self._if, ts, sent, OUTBOUND)
        return n

    def __getattr__(self, name):
        return getattr(self._port, name)

    def __setattr__(self, name, value):
        setattr(self._port, name, value)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._port.close()


__all__ = ["request", "requested", "finish", "tap", "TappedPort", "INBOUND", "OUTBOUND", "UNKNOWN"]


class CaptureFrames:
    """``(ts, direction, frame)`` for every whole frame of the capture at ``path``, in order.

    ``accept`` (ZK only): ``both``, ``status`` or ``control``; a ZK stream of known direction
    takes only its own kind (host -> ECU: control frames, ECU -> host: status frames).
    Afterwards: :attr:`truncated`, :attr:`frames`, :attr:`bad`, :attr:`skipped`, :attr:`t0`, and
    :meth:`reading_note` on what the capture held that could not be read.
    """

    def __init__(self, path: str, protocol: str, accept: str = "both"):
        self.path = path
        self.protocol = protocol
        self.accept = accept
        self.reader = Reader(path, protocol)
        self.framers = {}
        self.t0 = None
        self.truncated = False

    def _framer(self, key, direction):
        f = self.framers.get(key)
        if f is None:
            if self.protocol == "zap":
                f = ZapFramer()
            elif self.protocol == "modbus":
                f = RtuFramer()
            elif direction == OUTBOUND:
                f = ZkFramer("control") if self.accept != "status" else None
            elif direction == INBOUND:
                f = ZkFramer("status") if self.accept != "control" else None
            else:
                f = ZkFramer(self.accept)
            self.framers[key] = f
        return f

    def __iter__(self):
        for ts, direction, frames in self.chunks():
            for frame in frames:
                yield ts, direction, frame

    def chunks(self):
        """``(ts, direction, [frames])`` per chunk that completed any frame (then the frames
        the framers still held at the end)."""
        last = {}
        try:
            for pkt in self.reader:
                if self.t0 is None:
                    self.t0 = pkt.ts
                key = (pkt.interface, pkt.direction)
                framer = self._framer(key, pkt.direction)
                last[key] = pkt.ts
                if framer is None:
                    continue
                frames = framer.feed(pkt.data)
                if frames:
                    yield pkt.ts, pkt.direction, frames
            self.truncated = self.reader.truncated
            for key, framer in self.framers.items():
                if framer is not None:
                    frames = framer.flush()
                    if frames:
                        yield last[key], key[1], frames
        finally:
            self.reader.close()

    def _sum(self, attr):
        return sum(getattr(f, attr) for f in self.framers.values() if f is not None)

    @property
    def frames(self):
        return self._sum("frames")

    @property
    def bad(self):
        return self._sum("bad")

    @property
    def skipped(self):
        return self._sum("skipped")

    def reading_note(self) -> str | None:
        """One line on what the capture held that was not read (a truncated end, a damaged or
        malformed block), or None when it was all whole."""
        problems = self.reader.problems()
        return f"{self.path}: {'; '.join(problems)}" if problems else None
