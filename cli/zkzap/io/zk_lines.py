"""ZK records rendered straight to text lines (JSON Lines, CSV rows): :class:`ZkLines`.

The encoders are generated from the codec's tables (:meth:`zkzap.codec.fields.Layout.
text_encoder`) for the output dialects of :mod:`zkzap.io.writers`; a bounded memo serves a
repeated frame's line. Rendering text is the output layer's business, so this lives in io; the
codec stays free of formats.
"""

from __future__ import annotations

from ..codec.zk import (CONTROL_BY_ID, STATUS_BY_ID, STATUS_LEN, VERSION_HEAD, VERSIONED_STATUS,
                        ZkDecoder, protocol_version_of)

__all__ = ["ZkLines", "LINE_CACHE"]


#: Rendered lines remembered per decoding context, in two generations of this many (a capture
#: repeats frames heavily; the recently used ones survive a rotation).
LINE_CACHE = 16384
_MAX_CONTEXTS = 8
#: The memo is worth its look-ups while at least one frame in this many of a block hits it.
MEMO_WORTH = 4
#: Frames rendered without the memo after a block that hardly used it, before trying again.
COLD_SPAN = 1 << 16
#: The last item of every line: the frame's hex.
_TAIL = (("frame", "str", "b.hex(' ').upper()"),)


def _status_head(sid):
    """The first items of a status line."""
    return (("kind", "const", "status"), ("id", "const", sid))


#: Compiled text encoders, shared by every ZkLines: (dialect key, raw, ID, context) -> function.
_ENCODERS = {}


class ZkLines:
    """Frames to text lines (no newline) of one dialect: the records :class:`ZkDecoder` gives,
    with the frame's hex under ``frame``, rendered by encoders generated from the tables.

    Equal to rendering ``decoder.decode(frame) | {"frame": hex}`` with the dialect, line for
    line, and it updates the decoder's state the same way. A bounded memo maps a frame's bytes
    to its line for each decoding context (version, known version, RPM factor): a frame that
    would change the context is never served from it, so state changes are never skipped.
    """

    def __init__(self, decoder: ZkDecoder, dialect, cache=None):
        cache = LINE_CACHE if cache is None else cache
        self.decoder = decoder
        self.dialect = dialect
        self.cache = cache
        self._contexts = {}
        self._cold = 0
        self._encs = [None] * 256
        self._select()

    def _select(self):
        d = self.decoder
        key = (d.version, d.known, d.rpm_factor)
        c = self._contexts.get(key)
        if c is None:
            if len(self._contexts) >= _MAX_CONTEXTS:
                self._contexts.clear()
            # [young memo, old memo, status encoders by head byte that keep this context,
            #  version frame encoders by the version they repeat, the encoder of every head
            #  byte (the miss where there is none yet)]
            c = self._contexts[key] = [{}, {}, {}, {}, [self._miss] * 256]
        self._key = key
        self._memo, self._old, self._fast, self._six, encs = c
        # one list object for the life of this ZkLines, refilled in place: a loop that holds
        # it sees a change of context at the very next frame
        self._encs[:] = encs
        self.memo = self._memo
        self._ctx = c

    def _rotate(self):
        c = self._ctx
        c[1] = c[0]
        c[0] = {}
        self._memo, self._old = c[0], c[1]
        self.memo = self._memo
        return c[0]

    def line(self, f) -> str:
        """The line of one checked frame (bytes), after a miss in :attr:`memo` (the current
        context's young memo, which a framer may read directly: see ZkFramer.feed_lines)."""
        line = self._old.get(f)
        if line is None:
            enc = self._fast.get(f[0])
            if enc is None:
                return self._miss(f)
            line = enc(f)
        memo = self._memo
        if len(memo) >= self.cache:
            memo = self._rotate()
        memo[f] = line
        return line

    def encode_all(self, frames) -> list:
        """The lines of ``frames`` (bytes objects, as a framer returns them), in order.

        While frames hardly repeat (fewer than one in :data:`MEMO_WORTH` of a block found in
        the memo) the memo is left alone for the next :data:`COLD_SPAN` frames: looking up and
        storing lines that are never used again would cost more than the encoders."""
        if self._cold > 0:
            self._cold -= len(frames)
            return self._encode_cold(frames)
        out = []
        append = out.append
        memo = self._memo
        get = memo.get
        old = self._old.get
        fast = self._fast.get
        cap = self.cache
        misses = 0
        for f in frames:
            line = get(f)
            if line is None:
                misses += 1
                line = old(f)
                if line is None:
                    enc = fast(f[0])
                    if enc is None:
                        line = self._miss(f)
                        memo = self._memo
                        get = memo.get
                        old = self._old.get
                        fast = self._fast.get
                        append(line)
                        continue
                    line = enc(f)
                if len(memo) >= cap:
                    memo = self._rotate()
                    get = memo.get
                    old = self._old.get
                memo[f] = line
            append(line)
        if len(out) >= 256 and (len(out) - misses) * MEMO_WORTH < len(out):
            self._cold = COLD_SPAN
        return out

    def _encode_cold(self, frames) -> list:
        """:meth:`encode_all` without the memo: each frame's encoder by its head byte (the miss
        changes the list in place when the context changes)."""
        encs = self._encs
        return [encs[f[0]](f) for f in frames]

    def _serve(self, head, enc):
        """``enc`` renders frames of ``head`` in the current context from now on."""
        self._ctx[4][head] = enc
        self._encs[head] = enc

    def encode(self, frame) -> str:
        return self.encode_all([bytes(frame)])[0]

    def _miss(self, f):
        """A frame with no line in the memo and no fast encoder: render it the full way, then
        remember it (or its encoder) unless it changed the decoding context."""
        key = self._key
        d = self.decoder
        if f[0] == VERSION_HEAD and len(f) == STATUS_LEN and d.version_source == "frame":
            # a version frame that repeats the version already read from a frame changes no
            # state: its encoder for this context serves it
            enc = self._six.get(f[5] >> 2)
            if enc is not None:
                return enc(f)
        line, enc = self._render(f)
        if f[0] == VERSION_HEAD and len(f) == STATUS_LEN:
            if (d.version, d.known, d.rpm_factor) == key and d.version_source == "frame":
                v = d.version
                self._six[v] = self._version_enc
                # for the loop without the memo: this context's version frame encoder, which
                # hands a frame of another version to the full way
                st = STATUS_BY_ID[VERSION_HEAD & 0x0F]
                self._serve(VERSION_HEAD, st.layout.text_encoder(
                    self.dialect, {"version": v}, v, d.raw, guard=(f"b[5] >> 2 != {v}", self._miss),
                    head=_status_head(VERSION_HEAD & 0x0F), tail=_TAIL))
        if (d.version, d.known, d.rpm_factor) == key:
            if self.cache:
                if len(self._memo) >= self.cache:
                    self._rotate()
                self._memo[bytes(f)] = line
            if enc is not None:
                self._fast[f[0]] = enc
                self._serve(f[0], enc)
        else:
            self._select()
        return line

    def _generic(self, f):
        rec = self.decoder.decode(f)
        rec["frame"] = f.hex(" ").upper()
        return self.dialect.record(rec)

    def _render(self, f):
        """(line, the status encoder when it may serve this head byte from now on, else None)."""
        d = self.decoder
        raw = d.raw
        if len(f) == STATUS_LEN:
            sid = f[0] & 0x0F
            st = STATUS_BY_ID.get(sid)
            if st is None:
                return self._generic(f), None
            if sid == 6:
                d.version = d.known = version = known = protocol_version_of(f)
                d.version_source = "frame"
            else:
                version, known = d.version, d.known
                if d.version_source == "default" and sid in VERSIONED_STATUS:
                    d.assumed = True
            k = (getattr(self.dialect, "key", id(self.dialect)), raw, sid, version, known)
            enc = _ENCODERS.get(k)
            if enc is None:
                if len(_ENCODERS) >= 512:
                    _ENCODERS.clear()
                enc = _ENCODERS[k] = st.layout.text_encoder(
                    self.dialect, {"version": version}, known, raw,
                    head=_status_head(sid), tail=_TAIL)
            if sid == 6:
                self._version_enc = enc
                return enc(f), None
            return enc(f), enc
        cmd_id = f[1] >> 4
        cmd = CONTROL_BY_ID.get(cmd_id)
        if cmd is None or cmd_id == 6 or cmd.layout.reserved_bits(f):
            return self._generic(f), None
        k = (getattr(self.dialect, "key", id(self.dialect)), raw, "control", cmd_id, d.rpm_factor)
        enc = _ENCODERS.get(k)
        if enc is None:
            if len(_ENCODERS) >= 512:
                _ENCODERS.clear()
            enc = _ENCODERS[k] = cmd.layout.text_encoder(
                self.dialect, {"rpm_factor": d.rpm_factor}, None, raw,
                head=(("kind", "const", "control"), ("id", "const", cmd_id), ("command", "const", cmd.name)),
                tail=_TAIL)
        return enc(f), None


def capture_lines(frames, lines: ZkLines, csv: bool):
    """Blocks of text lines (JSON objects or CSV rows of ``TIME_KEYS`` + the decode columns) of
    a ZK capture (a :class:`zkzap.link.capture.CaptureFrames`), rendered by ``lines``: the
    same records as :func:`zkzap.api.capture.zk_records`, through the table-generated text
    encoders, one block per chunk."""
    from ..api.capture import direction_label, iso_utc
    from .writers import _dumps

    t0 = None
    for ts, direction, block in frames.chunks():
        if t0 is None:
            t0 = frames.t0
        t = round(ts - t0, 6)
        d = direction_label(direction)
        if csv:
            head = f"{iso_utc(ts)},{t!r},{d or ''},"
            yield [head + line for line in lines.encode_all(block)]
        else:
            head = '{"time":"%s","t":%s,"dir":%s,' % (iso_utc(ts), _dumps(t), _dumps(d))
            yield [head + line[1:] for line in lines.encode_all(block)]
