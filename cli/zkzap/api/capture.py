"""Reading zkzap's pcapng captures back: frames with their capture time and direction, and the
records ``zk decode`` / ``zap decode`` / ``zk monitor --replay`` make of them.

Chunks are cut into frames by one framer per interface and direction (a frame split across
two reads is whole again; the two directions never mix). A frame's time is the time of the
chunk that completed it. Records carry ``time`` (ISO 8601 UTC), ``t`` (seconds since the
capture's first chunk), ``dir`` (``h2d`` host -> device, ``d2h`` device -> host, null when the
capture could not tell: a sniffer on a half-duplex line) and, for mightyZAP feedback,
``latency_ms`` since the request it answers.
"""

from __future__ import annotations

from ..codec import zap, zk
from ..infile import open_input
from ..link.capture import CaptureFrames
from ..link.clock import iso_utc  # noqa: F401 - the one rendering of a date, re-exported
from ..link.pcapng import INBOUND, OUTBOUND, Reader
from ..link.zk_sources import PacedReplay

#: Keys captures add in front of a record (and ``latency_ms`` after a mightyZAP one).
TIME_KEYS = ["time", "t", "dir"]


def direction_label(direction):
    """``h2d``, ``d2h`` or None (a capture that could not tell) for a captured chunk's direction."""
    return {INBOUND: "d2h", OUTBOUND: "h2d"}.get(direction)


def zk_records(frames: CaptureFrames, decoder: zk.ZkDecoder, decode=None):
    """Records of a ZK capture: ``time``, ``t``, ``dir``, then the decoded frame (``decode``:
    a function of the frame, default ``decoder.decode``) and its ``frame`` hex."""
    decode = decode or decoder.decode
    for ts, direction, frame in frames:
        rec = {"time": iso_utc(ts), "t": round(ts - frames.t0, 6), "dir": direction_label(direction)}
        rec.update(decode(frame))
        rec["frame"] = frame.hex(" ").upper()
        yield rec


class ZapPairing:
    """Pairs mightyZAP feedback with the request it answers, for latencies, under the bus's
    timing policy (:class:`zkzap.link.zap_timing.Pairing`): a command (not the echo a
    half-duplex adapter returns) opens a request to its ID, the next feedback from that ID
    closes it, whatever was sent meanwhile. A capture does not say what window its host used,
    so none is assumed: a reply later than the default window still gets its latency."""

    def __init__(self):
        from ..link.zap_timing import Pairing

        self.pairing = Pairing(window=float("inf"), margin=0.0)

    def command(self, ident, ts, direction):
        if direction != INBOUND and ident != zap.BROADCAST:
            self.pairing.command(ident, ts)

    def feedback(self, ident, ts):
        got = self.pairing.feedback(ident, ts)
        return None if got is None or got[2] is None else round(got[2] * 1000.0, 3)


def zap_records(frames: CaptureFrames, decoder: zap.ZapDecoder | None = None, decode=None):
    """Records of a mightyZAP capture: ``time``, ``t``, ``dir``, the decoded packet, its
    ``frame`` hex and, for feedback, ``latency_ms`` (null when no request was seen, or when the
    request and its reply carry one time stamp: not known)."""
    decoder = decoder or zap.ZapDecoder()
    decode = decode or decoder.decode
    pairing = ZapPairing()
    for ts, direction, pkt in frames:
        rec = {"time": iso_utc(ts), "t": round(ts - frames.t0, 6), "dir": direction_label(direction)}
        rec.update(decode(pkt))
        rec["frame"] = pkt.hex(" ").upper()
        if rec["kind"] == "command":
            pairing.command(pkt[3], ts, direction)
        else:
            rec["latency_ms"] = pairing.feedback(pkt[3], ts)
        yield rec


def modbus_records(frames: CaptureFrames, decoder=None, decode=None):
    """Records of a mightyZAP Modbus RTU capture (link type 149): ``time``, ``t``, ``dir``, the
    decoded frame (:class:`zkzap.codec.modbus.ModbusDecoder`: a reply named by the request to
    its ID before it), its ``frame`` hex and, for a reply or an exception reply,
    ``latency_ms`` since the request it answers (null when none was seen). A frame read back
    that is the request just sent (a half-duplex adapter's echo) is decoded as what it is, a
    request."""
    from ..codec import modbus

    decoder = decoder or modbus.ModbusDecoder()
    decode = decode or decoder.decode
    pairing = ZapPairing()
    for ts, direction, frame in frames:
        label = direction_label(direction)
        if label == "d2h" and decoder.pending.get(frame[0]) == frame:
            label_for_decoder = None          # the adapter's echo of the request
        else:
            label_for_decoder = label
        rec = {"time": iso_utc(ts), "t": round(ts - frames.t0, 6), "dir": label}
        rec.update(decode(frame, label_for_decoder))
        rec["frame"] = frame.hex(" ").upper()
        if rec["kind"] == "request":
            if frame[0] != modbus.BROADCAST:          # (an echo read back is inbound: no request)
                pairing.command(frame[0], ts, direction)
        else:
            rec["latency_ms"] = pairing.feedback(frame[0], ts)
        yield rec


CAPTURE_SUFFIXES = (".pcapng", ".pcap", ".ntar")


def capture_inputs(inputs, binary: bool):
    """The decode inputs as captures: a list of paths when every input is a pcapng file (with or
    without ``--binary``), else None (hex or raw bytes, as before). A file named like a capture
    that is not one, or not a zkzap link type, is refused here (exit 2) before any output."""
    from ..link.pcapng import CaptureError, describe_start, is_pcapng
    from ..errors import UsageError

    paths = [p for p in inputs if p != "-"]
    if not paths or len(paths) != len(inputs):
        return None
    from ..infile import is_input

    flags = []
    for p in paths:
        if not is_input(p):
            if binary:
                return None           # the raw reader names the unreadable file
            return None if not p.lower().endswith(CAPTURE_SUFFIXES) else _missing(p)
        pc = is_pcapng(p)
        if not pc and p.lower().endswith(CAPTURE_SUFFIXES):
            with open_input(p) as f:
                raise CaptureError(f"{p}: not a pcapng capture: {describe_start(f.read(64))}")
        flags.append(pc)
    if not any(flags):
        return None
    if not all(flags):
        raise UsageError("input: pcapng captures and raw files cannot be mixed; decode them separately")
    return paths


def _missing(path):
    from ..errors import UsageError

    raise UsageError(f"input: cannot read {path}: no such file")


def check_captures(paths, protocol: str) -> None:
    """Refuse any of ``paths`` that is not a zkzap capture of ``protocol`` (exit 2)."""
    from ..link.pcapng import check_capture

    for p in paths:
        check_capture(p, protocol)


def first_time(path: str, protocol: str):
    """The timestamp of a capture's first chunk (None when it has none)."""
    with Reader(path, protocol) as r:
        for pkt in r:
            return pkt.ts
    return None


class CaptureReplaySource(PacedReplay):
    """``zk monitor --replay CAPTURE``: the status frames of a ZK capture at their recorded
    times (``t`` from the capture's first chunk, ``time`` the capture's own clock), paced in real
    time or, with ``fast``, as fast as they decode. The interface of
    :class:`zkzap.link.zk_sources.ReplaySource`."""

    def __init__(self, path, fast=False):
        import time

        self.path = path
        self.fast = fast
        self.frames = CaptureFrames(path, "zk", "status")
        first = first_time(path, "zk")
        self.wall0 = first if first is not None else time.time()
        self.framer = self.frames          # frames/bad/skipped for the summary and the notes
        self._it = iter(self.frames)
        self._next = None
        self.last_t = 0.0
        self.t0 = time.monotonic()

    def _peek(self):
        if self._next is None:
            item = next(self._it, None)
            if item is None:
                return None
            ts, _direction, frame = item
            self._next = (ts - self.wall0, frame)
        return self._next

    def _pop(self):
        self._next = None

    def close(self):
        self.frames.reader.close()
        note, self._noted = (None if getattr(self, "_noted", False) else self.frames.reading_note()), True
        if note:
            import sys

            print(f"note: {note}", file=sys.stderr)


def replay_source(path, fast=False):
    """The source for ``zk monitor --replay FILE``: a capture by its content, else a raw log."""
    from ..link.pcapng import is_pcapng
    from ..link.zk_sources import ReplaySource

    if is_pcapng(path):
        return CaptureReplaySource(path, fast)
    if path.lower().endswith(CAPTURE_SUFFIXES):
        from ..link.pcapng import CaptureError, describe_start

        with open_input(path) as f:
            raise CaptureError(f"{path}: not a pcapng capture: {describe_start(f.read(64))}")
    return ReplaySource(path, fast=fast)
