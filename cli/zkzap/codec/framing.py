"""Streaming framers: cut byte chunks of any size into whole, checked frames.

A framer knows only sync, length and checksum (like pymodbus's framers); what the bytes mean
is the business of :mod:`zkzap.codec.zk` and :mod:`zkzap.codec.zap`. Feed it chunks with
:meth:`feed`, which returns the frames completed so far; call :meth:`flush` at the end of the
stream and use the frames it returns. It keeps at most a few frames' worth of bytes between
calls: memory is constant whatever the stream length.

Resynchronisation. After garbage or a CRC failure the framer slides forward one byte and
looks for the next head, so a valid frame that follows is never lost to the damage itself.
An 8-bit CRC (or checksum) also accepts 1 in 256 random candidates, so garbage that ends in a
head byte (a truncated frame, line noise) can form a *false* frame overlapping the real one
after it. Therefore a candidate that validates right after skipped bytes, inside a damaged
region (the span of a candidate that failed its check), is checked against every rival
candidate starting inside it. A rival that also validates wins unless the candidate is
*confirmed* (a valid frame starts right after it) and the rival is not, and provided the rival
would itself win against its own rivals (so the choice never drops both). Outside a damaged
region the earliest valid candidate wins, as before: garbage with no head byte in it never
costs a frame.
Deciding may need the bytes after the candidate: until they arrive it is held back
(``pending``), and :meth:`flush` decides with what there is, so use the frames flush()
returns. A frame that follows a good frame directly (or starts the stream) is returned at
once, with no look-ahead: a live stream is never delayed. The residual rate at which a false
frame still wins (both readings valid and unconfirmed, or garbage right after a good frame)
is measured by ``benchmarks/fuzz.py``.

Counters: ``frames`` (good frames), ``bad`` (candidate frames whose CRC/checksum failed or
that lost to a rival, each damaged region counted once), ``truncated`` (a frame cut short by
the end of the stream: not a CRC error), ``filtered`` (whole, valid frames of the kind a
:class:`ZkFramer` was told not to accept: not errors either), ``skipped`` (bytes that were
not part of a good frame, including those of truncated and filtered frames).
"""

from __future__ import annotations

from ..errors import InvalidValue
from .crc import CRC8_TABLE

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Literal, Optional, Sequence, Union

    from typing_extensions import TypeAlias

    Bytes: TypeAlias = Union[bytes, bytearray, memoryview]

_T = CRC8_TABLE
_HDR = b"\xff\xff\xff"

#: Recently validated frames are remembered (up to this many) so that a repeated frame, the
#: common case in a capture, is recognised without recomputing its CRC or checksum.
VALID_CACHE = 8192
#: How deep a chain of overlapping valid candidates is followed when deciding between them.
MAX_DEPTH = 3
#: Runs of status frames in step are checked this many at a time at most (see ZkFramer._run).
RUN_MAX = 4096
#: The first try at a run checks this many frames; each whole success doubles it.
RUN_MIN = 16
#: Byte -> 0 for a status head, else 1: for framers that return status frames, and those that
#: do not (accept="control").
_NOT_STATUS = (bytes(0 if 0xF1 <= h <= 0xFE else 1 for h in range(256)), b"\x01" * 256)
#: A run's block is cut into frames with these (the 7-byte slices of RUN_MAX frames).
_SLICES = [slice(p, p + 7) for p in range(0, 7 * RUN_MAX, 7)]


class _Framer:
    """What both framers share: counters, the bytes held between calls, the end of a scan, and
    the choice between overlapping valid candidates after damage."""

    #: Frames returned so far.
    frames: int
    #: Frames that failed their check (CRC or checksum) at a frame boundary.
    bad: int
    #: Frames cut short by the end of the input.
    truncated: int
    #: Frames of the kind ``accept`` leaves out (ZK).
    filtered: int
    #: Bytes skipped (garbage, bad frames, a truncated end).
    skipped: int

    def __init__(self) -> None:
        self._buf = b""
        self._bad_until = 0
        self._synced = True
        self._valid = {}
        self.frames = 0
        self.bad = 0
        self.truncated = 0
        self.filtered = 0
        self.skipped = 0

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame (or for the bytes that confirm it)."""
        return len(self._buf)

    def _reset(self):
        self._buf = b""
        self._bad_until = 0
        self._synced = True

    def _end_scan(self, buf, i, out, skipped, bad_until, synced, final):
        """Book-keeping at the end of :meth:`_scan`: counters, and the bytes kept for later."""
        self.frames += len(out)
        if final:
            skipped += len(buf) - i
            i = len(buf)
        self.skipped += skipped
        self._bad_until = bad_until - i
        self._synced = synced
        self._buf = buf[i:]
        return out

    def _decide(self, buf, end, rivals, final, depth):
        """Keep the candidate ending at ``end`` (True) or drop it for one of ``rivals``
        (``(start, end)`` of valid candidates starting inside it) that a following frame
        confirms (False); None when the bytes needed to decide have not arrived."""
        if not rivals:
            return True
        mine = self._valid_at(buf, end, final)
        if mine is None:
            return None
        for j, e in rivals:
            theirs = self._valid_at(buf, e, final)
            if theirs is None:
                return None
            if (theirs or not mine) and depth < MAX_DEPTH:
                wins = self._resync(buf, j, e, final, depth + 1)
                if wins is None:
                    return None
                if wins:
                    return False
        return True


class ZkFramer(_Framer):
    """Frames of the ZK protocol: 4-byte control (``FF``) and 7-byte status (``F1``..``FE``).

    ``accept`` is ``"both"``, ``"status"`` or ``"control"``. Control frames are accepted only
    with a known command ID (0..8) in b1[7:4]; a status frame's CRC covers the head, a control
    frame's does not.
    """

    def __init__(self, accept: Literal["both", "status", "control"] = "both") -> None:
        if accept not in ("both", "status", "control"):
            raise InvalidValue(f"accept: {accept!r}; allowed both, status, control")
        self.accept = accept
        lengths = [0] * 256
        other = [0] * 256               # the kind left out: recognised, counted, not returned
        for h in range(0xF1, 0xFF):
            (lengths if accept in ("both", "status") else other)[h] = 7
        (lengths if accept in ("both", "control") else other)[0xFF] = 4
        self._len = lengths
        self._other = other
        # byte -> 0 for a status head this framer returns, else 1 (see _run)
        self._not_status = _NOT_STATUS[accept == "control"]
        self._run_size = RUN_MIN
        super().__init__()

    def _run(self, buf, i, n):
        """The valid status frames, back to back, that start at ``i``, all checked at once:
        the CRC of every frame of a block is computed column by column (byte 0 of every frame,
        then byte 1...), with ``bytes.translate`` for the table and integer XOR for the
        columns, so its cost per frame is a few machine operations. Returns ``(count, block)``:
        the frames are the first ``count`` 7-byte pieces of ``block``. Equivalent, frame for
        frame, to checking each frame of the run in step."""
        k = min((n - i) // 7, self._run_size)
        if k < 2:
            return 0, b""
        end = i + 7 * k
        block = buf[i:end]
        heads = block[0::7]
        # frames up to the first head that is not a status head of this framer
        h = heads.translate(self._not_status).find(1)
        if h < 0:
            h = k
        T = _T
        c = heads.translate(T)
        frm = int.from_bytes
        for j in range(1, 7):
            c = (frm(c, "little") ^ frm(block[j::7], "little")).to_bytes(k, "little").translate(T)
        # frames up to the first whose CRC fails
        good = k - len(c.lstrip(b"\0"))
        good = min(h, good)
        self._run_size = min(self._run_size * 2, RUN_MAX) if good == k else RUN_MIN
        return good, block

    def _left_out(self, buf, i, final):
        """Length of a valid frame of the kind not accepted at ``i`` (0: none; None: bytes
        missing). A frame of the accepted kind starting inside it wins, as it would have."""
        lo = self._other[buf[i]]
        if not lo:
            return 0
        n = len(buf)
        e = i + lo
        if e > n:
            return 0 if final else None
        if not (buf[i + 1] < 0x90 and _T[_T[_T[buf[i + 1]] ^ buf[i + 2]] ^ buf[i + 3]] == 0 if lo == 4
                else self._ok(buf, i, 7)):
            return 0
        wins = self._resync(buf, i, e, final)
        if wins is None:
            return None
        return lo if wins else 0

    def feed(self, data: Bytes) -> list[bytes]:
        """Frames completed by ``data`` (a frame right after skipped bytes may be held back
        until the bytes that confirm it arrive)."""
        buf = self._buf + bytes(data) if self._buf else bytes(data)
        return self._scan(buf, False)

    def flush(self) -> list[bytes]:
        """End of stream: decide about held frames with the bytes there are and return them;
        bytes still held after that are a truncated frame (counted as skipped)."""
        return self.flush_lines(None)

    def feed_lines(self, data: Bytes, lines: Any) -> list[Any]:
        """:meth:`feed`, returning ``lines.line(frame)`` for each frame instead of the frame,
        where ``lines`` is a :class:`~zkzap.io.zk_lines.ZkLines`. A frame in step whose line is
        in ``lines.memo`` (where only checked frames go) costs one look-up."""
        buf = self._buf + bytes(data) if self._buf else bytes(data)
        return self._scan(buf, False, lines)

    def flush_lines(self, lines: Optional[Any]) -> list[Any]:
        """:meth:`flush`, returning lines as :meth:`feed_lines` does (frames when None)."""
        out = self._scan(self._buf, True, lines) if self._buf else []
        self._reset()
        return out

    def _ok(self, buf, i, ln) -> bool:
        T = _T
        if ln == 7:
            return T[T[T[T[T[T[T[buf[i]] ^ buf[i + 1]] ^ buf[i + 2]] ^ buf[i + 3]] ^ buf[i + 4]]
                     ^ buf[i + 5]] ^ buf[i + 6]] == 0
        return buf[i + 1] < 0x90 and T[T[T[buf[i + 1]] ^ buf[i + 2]] ^ buf[i + 3]] == 0

    def _valid_at(self, buf, p, final):
        """Whether a valid frame starts at ``p``: True/False, None when bytes are missing."""
        n = len(buf)
        if p >= n:
            return False if final else None
        ln = self._len[buf[p]]
        if not ln:
            return False
        if p + ln > n:
            return False if final else None
        return self._ok(buf, p, ln)

    def _resync(self, buf, i, end, final, depth=0):
        """A valid candidate at ``i..end`` after skipped bytes: keep it (True), drop it for a
        rival (False), or None when the bytes needed to decide have not arrived."""
        lens = self._len
        n = len(buf)
        rivals = []
        for j in range(i + 1, end):
            lj = lens[buf[j]]
            if not lj:
                continue
            if j + lj > n:
                if final:
                    continue
                return None
            if self._ok(buf, j, lj):
                rivals.append((j, j + lj))
        return self._decide(buf, end, rivals, final, depth)

    def _scan(self, buf, final, sink=None) -> list:
        out = []
        append = out.append
        lens = self._len
        T = _T
        valid = self._valid
        memo = sink.memo if sink is not None else valid
        n = len(buf)
        i = 0
        skipped = 0
        bad_until = self._bad_until
        synced = self._synced
        other = self._other
        bulk = 0                        # where a run of status frames may be tried next
        while i < n:
            ln = lens[buf[i]]
            if ln == 7 and synced and i >= bulk:
                good, block = self._run(buf, i, n)
                if good >= RUN_MIN:
                    frames = list(map(block.__getitem__, _SLICES[:good]))
                    if sink is None:
                        out += frames
                    else:
                        out += sink.encode_all(frames)
                        memo = sink.memo
                    i += 7 * good
                    continue
                # a short run: frames of other kinds are interleaved; go frame by frame a while
                bulk = i + 7 * 4 * RUN_MIN
            if not ln:
                if other[buf[i]]:
                    lo = self._left_out(buf, i, final)
                    if lo is None:
                        break
                    if lo:
                        self.filtered += 1
                        skipped += lo
                        i += lo
                        synced = True
                        continue
                skipped += 1
                i += 1
                synced = False
                continue
            e = i + ln
            if synced and e <= n:
                # in step: a repeated frame needs no CRC and no look-around
                f = buf[i:e]
                if f in memo:
                    append(f if sink is None else memo[f])
                    i = e
                    continue
            if e > n:
                if not final:
                    break
                ok = False          # a truncated frame at the end of the stream
                e = n
                if i >= bad_until:
                    self.truncated += 1
                    bad_until = e
            else:
                f = buf[i:e]
                if f in valid:
                    ok = True
                else:
                    if ln == 7:
                        ok = T[T[T[T[T[T[T[buf[i]] ^ buf[i + 1]] ^ buf[i + 2]] ^ buf[i + 3]] ^ buf[i + 4]]
                               ^ buf[i + 5]] ^ buf[i + 6]] == 0
                    else:
                        ok = buf[i + 1] < 0x90 and T[T[T[buf[i + 1]] ^ buf[i + 2]] ^ buf[i + 3]] == 0
                    if ok:
                        if len(valid) >= VALID_CACHE:
                            valid.clear()
                        valid[f] = None
                if ok and not synced and i < bad_until:
                    ok = self._resync(buf, i, e, final)
                    if ok is None:
                        break
            if ok:
                if sink is None:
                    append(f)
                else:
                    append(sink.line(f))
                    memo = sink.memo
                i = e
                synced = True
            else:
                if i >= bad_until:
                    self.bad += 1
                    bad_until = e
                skipped += 1
                i += 1
                synced = False
        return self._end_scan(buf, i, out, skipped, bad_until, synced, final)


class ZapFramer(_Framer):
    """Packets of the mightyZAP IR protocol: ``FF FF FF ID SIZE ... CHK``.

    The header is the last three of a run of FF bytes (ID is never FF). SIZE must be at least 2.
    """

    def feed(self, data: Bytes) -> list[bytes]:
        """Packets completed by ``data`` (a packet right after skipped bytes may be held back
        until the bytes that confirm it arrive)."""
        data = self._buf + bytes(data) if self._buf else bytes(data)
        n = len(data)
        # the usual read of a reply or a captured packet: exactly one whole packet, in step (the
        # bytes held may be its first part: a reply read in two pieces)
        if (n >= 7 and self._synced and data[4] + 5 == n and data[4] >= 2 and data[3] != 0xFF
                and data[0] == data[1] == data[2] == 0xFF):
            valid = self._valid
            if data in valid or (0xFF - (sum(data[3:-1]) & 0xFF)) == data[-1]:
                if len(valid) >= VALID_CACHE:
                    valid.clear()
                valid[data] = None
                self.frames += 1
                self._bad_until -= n       # what the scan's end does (see _end_scan)
                self._buf = b""
                return [data]
        return self._scan(data, False)

    def flush(self) -> list[bytes]:
        """End of stream: decide about held packets and return them; bytes still held after
        that are a truncated packet (counted as skipped, and as bad when they began with a
        header)."""
        out = self._scan(self._buf, True) if self._buf else []
        self._reset()
        return out

    @staticmethod
    def _head(buf, p, n):
        """The header position of a run of FFs starting at ``p`` (its last three), or -1."""
        while p + 3 < n and buf[p + 3] == 0xFF:
            p += 1
        return p

    def _valid_at(self, buf, p, final):
        """Whether a valid packet starts at ``p`` (after any extra FFs of its header run)."""
        n = len(buf)
        if p + 3 > n:
            if buf[p:] == _HDR[:n - p]:
                return False if final else None
            return False
        if buf[p:p + 3] != _HDR:
            return False
        p = self._head(buf, p, n)
        if p + 5 > n:
            return False if final else None
        size = buf[p + 4]
        end = p + 5 + size
        if size < 2:
            return False
        if end > n:
            return False if final else None
        return (0xFF - (sum(buf[p + 3:end - 1]) & 0xFF)) == buf[end - 1]

    def _resync(self, buf, i, end, final, depth=0):
        n = len(buf)
        rivals = []
        j = buf.find(_HDR, i + 1, end + 2)
        while 0 <= j < end:
            j = self._head(buf, j, n)
            if j >= end:
                break
            if j + 5 > n:
                if not final:
                    return None
            else:
                size = buf[j + 4]
                e = j + 5 + size
                if size >= 2:
                    if e > n:
                        if not final:
                            return None
                    elif (0xFF - (sum(buf[j + 3:e - 1]) & 0xFF)) == buf[e - 1]:
                        rivals.append((j, e))
            j = buf.find(_HDR, j + 1, end + 2)
        return self._decide(buf, end, rivals, final, depth)

    def _scan(self, buf, final) -> list:
        out = []
        append = out.append
        valid = self._valid
        n = len(buf)
        i = 0
        skipped = 0
        bad_until = self._bad_until
        synced = self._synced
        find = buf.find
        while True:
            j = find(_HDR, i)
            if j < 0:
                # keep a trailing run of FFs: it may be the start of a header
                keep = n
                if not final:
                    while keep > i and keep > n - 2 and buf[keep - 1] == 0xFF:
                        keep -= 1
                if keep > i:
                    synced = False
                skipped += keep - i
                i = keep
                break
            while j + 3 < n and buf[j + 3] == 0xFF:
                j += 1
            if j > i:
                skipped += j - i
                synced = False
            i = j
            if i + 5 > n:
                if not final:
                    break
                ok = False              # a truncated packet at the end of the stream
                end = n
                if i >= bad_until:
                    self.truncated += 1
                    bad_until = end
            else:
                size = buf[i + 4]
                end = i + 5 + size
                if size < 2:
                    ok = False
                    end = i + 5
                elif end > n:
                    if not final:
                        break
                    ok = False
                    end = n
                    if i >= bad_until:
                        self.truncated += 1
                        bad_until = end
                else:
                    p = buf[i:end]
                    if p in valid:
                        ok = True
                    else:
                        ok = (0xFF - (sum(buf[i + 3:end - 1]) & 0xFF)) == buf[end - 1]
                        if ok:
                            if len(valid) >= VALID_CACHE:
                                valid.clear()
                            valid[p] = None
                    if ok and not synced and i < bad_until:
                        ok = self._resync(buf, i, end, final)
                        if ok is None:
                            break
            if ok:
                append(p)
                i = end
                synced = True
            else:
                if i >= bad_until:
                    self.bad += 1
                    bad_until = end
                skipped += 1
                i += 1
                synced = False
        return self._end_scan(buf, i, out, skipped, bad_until, synced, final)


class RtuFramer(_Framer):
    """Frames of Modbus RTU as the mightyZAP 17Lf speaks it (functions 0x03, 0x06, 0x10 and
    their exception replies), cut from a byte stream without its timing.

    A frame's length follows from its function and direction: 0x03 is 8 bytes as a request,
    ``5 + N`` as a reply (N its byte count); 0x06 and 0x10 replies are 8; a 0x10 request
    ``9 + N``; an exception reply 5. Each reading the bytes allow is tried, shortest first, and
    the first whose CRC-16 matches wins (a false match is a 1 in 65536 chance per reading). A
    start with an ID above 247 or a function the actuator does not know is skipped byte by byte.
    The counters are the other framers': ``bad`` (a damaged region: CRC failed), ``truncated``
    (cut short by the end of the stream), ``skipped`` (bytes in no frame).
    """

    #: Functions the framer knows (0x03, 0x06, 0x10) and the highest unit ID.
    FUNCTIONS = (0x03, 0x06, 0x10)
    MAX_ID = 247

    def __init__(self, any_function: bool = False) -> None:
        super().__init__()
        #: Also frames of other function codes, of any length whose CRC matches within the bytes
        #: at hand (a device hearing whole requests: the simulator answers them "illegal function").
        self.any_function = any_function

    def feed(self, data: Bytes) -> list[bytes]:
        """Frames completed by ``data``."""
        return self._scan(self._buf + bytes(data) if self._buf else bytes(data), False)

    def flush(self) -> list[bytes]:
        """End of stream: what is held is a frame cut short (counted as truncated)."""
        out = self._scan(self._buf, True) if self._buf else []
        self._reset()
        return out

    @classmethod
    def _lengths(cls, buf, i, n):
        """The frame lengths the bytes from ``i`` may have (None: more bytes needed to tell)."""
        fn = buf[i + 1]
        if fn & 0x80:
            return (5,)            # an exception reply, to any function (1: illegal function)
        if fn == 0x03:
            if i + 3 > n:
                return None
            c = buf[i + 2]
            return (8, 5 + c) if c and c % 2 == 0 and 5 + c != 8 else (8,)
        if fn == 0x06:
            return (8,)
        if fn == 0x10:
            if i + 7 > n:
                return (8,) if i + 8 <= n else None
            c = buf[i + 6]
            return (8, 9 + c) if c and c % 2 == 0 else (8,)
        return ()

    def _other(self, buf, i, n):
        """Lengths of a frame of a function the framer does not know, within the bytes at hand."""
        return range(4, min(n - i, 256) + 1) if self.any_function else ()

    def _scan(self, buf, final) -> list:
        from .crc import crc16_modbus

        out = []
        n = len(buf)
        i = 0
        skipped = 0
        bad_until = self._bad_until
        synced = self._synced
        while i + 2 <= n:
            if buf[i] > self.MAX_ID:
                skipped += 1
                i += 1
                synced = False
                continue
            lengths = self._lengths(buf, i, n)
            if lengths == () and buf[i + 1] not in self.FUNCTIONS:
                lengths = self._other(buf, i, n)
            if lengths is None:
                if not final:
                    break
                lengths = ()
            found = 0
            waiting = False
            for ln in sorted(lengths):
                if i + ln > n:
                    waiting = True
                    continue
                if crc16_modbus(buf[i:i + ln - 2]) == buf[i + ln - 2] | buf[i + ln - 1] << 8:
                    found = ln
                    break
            if found:
                out.append(buf[i:i + found])
                i += found
                synced = True
                continue
            if waiting and not final:
                break
            if lengths and i >= bad_until:
                if waiting:
                    self.truncated += 1
                else:
                    self.bad += 1
                bad_until = i + max(min(lengths), 1)
            skipped += 1
            i += 1
            synced = False
        if final and i < n:
            if n - i >= 2 and i >= bad_until:
                self.truncated += 1
        return self._end_scan(buf, i, out, skipped, bad_until, synced, final)


#: A stream is taken for a device talking the protocol once this many valid frames came while
#: at least :data:`LOCK_SHARE` of its recent bytes were in valid frames.
LOCK_FRAMES = 3
#: Share of the recent bytes that valid frames must account for before frames are trusted.
LOCK_SHARE = 0.3
#: Below this share (over at least :data:`NOISE_BYTES` recent bytes) a trusted stream is noise
#: again: frames are held back until it proves itself anew.
UNLOCK_SHARE = 0.1
#: "Recent": each byte's weight halves over this many later bytes.
SHARE_HALF_LIFE = 256
#: Bytes that must have come (with too few of them in frames) before a stream is called noise.
NOISE_BYTES = 64
#: Valid frames held back at most while a stream has not proved itself (the oldest go first).
HELD_MAX = 4 * LOCK_FRAMES


class SignalLock:
    """Whether a byte stream is a device talking the protocol, or noise that an 8-bit check
    lets through by chance — the one place that decides "have we got a device".

    A CRC-8 (or an 8-bit checksum) accepts 1 random candidate in 256: random bytes on a line
    (a wrong baud rate, another device, a floating input) give a ZK status frame about every
    4 700 bytes, 2.5 a second at 115200 baud. A device's stream is frames back to back, so
    almost every byte is in one; noise is almost all skipped bytes. The lock weighs the recent
    bytes (:data:`SHARE_HALF_LIFE`): valid frames are handed on only once
    :data:`LOCK_FRAMES` of them came while at least :data:`LOCK_SHARE` of the recent bytes
    were in valid frames (the first ones are held back until then, and handed on with their
    own items), and no longer once the share falls below :data:`UNLOCK_SHARE`.

    ``confirm`` (default :data:`LOCK_FRAMES`) is how many valid frames it takes: a session
    can wait for three frames; a sniffer, whose records must come as they happen and in time
    order, trusts a frame at once when the share allows (noise can then pass one frame, and
    only within its first bytes: about 1 stream start in 300).

    Feed it what a framer returned for each chunk: :meth:`admit` (``nbytes`` the chunk's
    length, ``frames`` the framer's frames, ``items`` what to hand on for each, default the
    frames). Frames of the kind a :class:`ZkFramer` leaves out (``accept``) count as framed
    bytes: a half-duplex echo of the host's control frames is not noise.

    ``locked``; ``noise`` (bytes came, too few in frames); counters ``bytes``, ``accepted``,
    ``rejected`` (valid frames taken for chance: never handed on).
    """

    def __init__(self, framer: Union[ZkFramer, ZapFramer], confirm: int = LOCK_FRAMES) -> None:
        self.framer = framer
        self.confirm = confirm
        accept = getattr(framer, "accept", "both")
        self._other_len = 4 if accept == "status" else 7 if accept == "control" else 0
        self._filtered = framer.filtered
        self.locked = False
        self.held: list[Any] = []
        self.bytes = 0
        self.accepted = 0
        self.rejected = 0
        self._good = 0.0
        self._seen = 0.0

    @property
    def share(self) -> float:
        """The share of the recent bytes that were in valid frames (0..1)."""
        return min(1.0, self._good / self._seen) if self._seen else 0.0

    @property
    def noise(self) -> bool:
        """True when bytes come but not as frames: not (or no longer) a device's stream."""
        return not self.locked and self._seen >= NOISE_BYTES and self.share < LOCK_SHARE

    def admit(self, nbytes: int, frames: Sequence[Bytes], items: Optional[Sequence[Any]] = None) -> list[Any]:
        """The items (default: the frames) to hand on for a chunk of ``nbytes`` bytes whose
        framer returned ``frames``."""
        items = list(frames) if items is None else list(items)
        framed = sum(len(f) for f in frames)
        filtered = self.framer.filtered
        if filtered != self._filtered:
            framed += (filtered - self._filtered) * self._other_len
            self._filtered = filtered
        if nbytes:
            decay = 0.5 ** (nbytes / SHARE_HALF_LIFE)
            self._good *= decay
            self._seen *= decay
        self._good += framed
        self._seen += nbytes
        self.bytes += nbytes
        share = self.share
        if self.locked:
            if share < UNLOCK_SHARE and self._seen >= NOISE_BYTES:
                self.locked = False
            else:
                self.accepted += len(items)
                return items
        held = self.held
        held += items
        if share >= LOCK_SHARE and len(held) >= self.confirm:
            self.locked = True
            self.held = []
            self.accepted += len(held)
            return held
        if self._seen >= NOISE_BYTES and share < UNLOCK_SHARE:
            self.rejected += len(held)
            held.clear()
        elif len(held) > HELD_MAX:
            self.rejected += len(held) - HELD_MAX
            del held[:len(held) - HELD_MAX]
        return []

    def finish(self) -> None:
        """The end of the stream: frames still held never proved themselves (rejected)."""
        self.rejected += len(self.held)
        self.held = []
