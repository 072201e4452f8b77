"""mightyZAP records rendered straight to text lines (JSON Lines, CSV rows), with a memo.

A bus capture repeats itself: the same requests, and replies whose data changes slowly. A line
depends only on the packet's bytes and, for a feedback packet, on the Load Data it answers, so
:class:`ZapLines` keeps the rendered line of each (request, packet) pair and renders a packet
once: the record from :func:`zkzap.codec.zap.decode_packet`, its ``frame`` hex, through the
format's dialect (:mod:`zkzap.io.writers`), so the bytes are exactly those of the record
writers. The pairing state is the decoder's own (:class:`zkzap.codec.zap.ZapDecoder`).
"""

from __future__ import annotations

from ..codec import zap

#: Lines kept before the memo starts afresh (bounded memory whatever the capture).
CACHE = 16384


class ZapLines:
    """``encode_all(packets)`` -> their lines, pairing feedback with the Load Data it answers."""

    def __init__(self, decoder: zap.ZapDecoder, dialect, cache: int = CACHE):
        self.decoder = decoder
        self.record = dialect.record
        self.cache = cache
        self.memo = {}

    def encode_all(self, packets) -> list:
        """The lines of ``packets`` (checked, whole packets, in stream order)."""
        pending = self.decoder.pending
        memo = self.memo
        commands = zap.INSTRUCTION_BY_CODE
        load = zap.LOAD_DATA
        out = []
        append = out.append
        for p in packets:
            ident = p[3]
            code = p[5]
            if code in commands:
                if code == load:
                    pending[ident] = p
                else:
                    pending.pop(ident, None)
                req = None
                key = p
            else:
                req = pending.pop(ident, None)
                key = p if req is None else (req, p)
            line = memo.get(key)
            if line is None:
                if len(memo) >= self.cache:
                    memo.clear()
                rec = zap.decode_packet(p, req)
                rec["frame"] = p.hex(" ").upper()
                line = memo[key] = self.record(rec)
            append(line)
        return out
