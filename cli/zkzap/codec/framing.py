"""Streaming framers: cut byte chunks of any size into whole, checked frames.

A framer knows only sync, length and checksum (like pymodbus's framers); what the bytes mean
is the business of :mod:`zkzap.codec.zk` and :mod:`zkzap.codec.zap`. Feed it chunks with
:meth:`feed`, which returns the frames completed so far; call :meth:`flush` at the end of the
stream. After garbage or a CRC failure it slides forward one byte and looks for the next
head, so a valid frame that follows is never lost. It keeps at most one frame's worth of
bytes between calls: memory is constant whatever the stream length.

Counters: ``frames`` (good frames), ``bad`` (candidate frames whose CRC/checksum failed, each
damaged region counted once), ``skipped`` (bytes that were not part of a good frame).
"""

from __future__ import annotations

from .crc import CRC8_TABLE

_T = CRC8_TABLE


class ZkFramer:
    """Frames of the ZK protocol: 4-byte control (``FF``) and 7-byte status (``F1``..``FE``).

    ``accept`` is ``"both"``, ``"status"`` or ``"control"``. Control frames are accepted only
    with a known command ID (0..8) in b1[7:4]; a status frame's CRC covers the head, a control
    frame's does not.
    """

    def __init__(self, accept: str = "both"):
        if accept not in ("both", "status", "control"):
            raise ValueError(f"accept: {accept!r}; allowed both, status, control")
        self.accept = accept
        lengths = [0] * 256
        if accept in ("both", "status"):
            for h in range(0xF1, 0xFF):
                lengths[h] = 7
        if accept in ("both", "control"):
            lengths[0xFF] = 4
        self._len = lengths
        self._buf = b""
        self._bad_until = 0
        self.frames = 0
        self.bad = 0
        self.skipped = 0

    def feed(self, data) -> list:
        buf = self._buf + bytes(data) if self._buf else bytes(data)
        out = []
        append = out.append
        lens = self._len
        T = _T
        n = len(buf)
        i = 0
        skipped = 0
        bad_until = self._bad_until
        while i < n:
            ln = lens[buf[i]]
            if not ln:
                skipped += 1
                i += 1
                continue
            if i + ln > n:
                break
            if ln == 7:
                ok = T[T[T[T[T[T[T[buf[i]] ^ buf[i + 1]] ^ buf[i + 2]] ^ buf[i + 3]] ^ buf[i + 4]]
                       ^ buf[i + 5]] ^ buf[i + 6]] == 0
            else:
                ok = buf[i + 1] < 0x90 and T[T[T[buf[i + 1]] ^ buf[i + 2]] ^ buf[i + 3]] == 0
            if ok:
                append(buf[i:i + ln])
                i += ln
            else:
                if i >= bad_until:
                    self.bad += 1
                    bad_until = i + ln
                skipped += 1
                i += 1
        self.frames += len(out)
        self.skipped += skipped
        self._bad_until = bad_until - i
        self._buf = buf[i:]
        return out

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def flush(self) -> list:
        """End of stream: bytes still held are a truncated frame (counted as skipped)."""
        if self._buf:
            self.skipped += len(self._buf)
            self.bad += 1 if self._bad_until <= 0 else 0
            self._buf = b""
        self._bad_until = 0
        return []


class ZapFramer:
    """Packets of the mightyZAP IR protocol: ``FF FF FF ID SIZE ... CHK``.

    The header is the last three of a run of FF bytes (ID is never FF). SIZE must be at least 2.
    """

    def __init__(self):
        self._buf = b""
        self._bad_until = 0
        self.frames = 0
        self.bad = 0
        self.skipped = 0

    def feed(self, data) -> list:
        buf = self._buf + bytes(data) if self._buf else bytes(data)
        out = []
        n = len(buf)
        i = 0
        skipped = 0
        bad_until = self._bad_until
        find = buf.find
        while True:
            j = find(b"\xff\xff\xff", i)
            if j < 0:
                # keep a trailing run of FFs: it may be the start of a header
                keep = n
                while keep > i and keep > n - 2 and buf[keep - 1] == 0xFF:
                    keep -= 1
                skipped += keep - i
                i = keep
                break
            while j + 3 < n and buf[j + 3] == 0xFF:
                j += 1
            skipped += j - i
            i = j
            if i + 5 > n:
                break
            size = buf[i + 4]
            end = i + 5 + size
            if size < 2:
                ok = False
                end = i + 5
            elif end > n:
                break
            else:
                ok = (0xFF - (sum(buf[i + 3:end - 1]) & 0xFF)) == buf[end - 1]
            if ok:
                out.append(buf[i:end])
                i = end
            else:
                if i >= bad_until:
                    self.bad += 1
                    bad_until = end
                skipped += 1
                i += 1
        self.frames += len(out)
        self.skipped += skipped
        self._bad_until = bad_until - i
        self._buf = buf[i:]
        return out

    @property
    def pending(self) -> int:
        return len(self._buf)

    def flush(self) -> list:
        if self._buf:
            self.skipped += len(self._buf)
            if self._buf.startswith(b"\xff\xff\xff") and self._bad_until <= 0:
                self.bad += 1
            self._buf = b""
        self._bad_until = 0
        return []
