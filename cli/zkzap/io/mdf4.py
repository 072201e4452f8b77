"""ASAM MDF 4.10 written as it is measured: the blocks a file of one channel group of float64
channels needs, then one data block that grows by each chunk of records, appended and flushed.

While it is written the file is *unfinalized* in MDF's own terms (identification ``UnFinMF``,
flags: the channel group's cycle count and the last data block's length to be updated), the state
the standard defines for a data logger's file cut by a power loss; a reader such as asammdf
finalizes it on opening, so a run killed without a word still leaves every record flushed before
the kill. :meth:`Mdf4Stream.close` writes the length and the count and marks the file finalized.

asammdf, the reference Python library, keeps appended samples in a temporary file of its own and
writes the measurement file only when it is saved, at the end: there is nothing on disk of a run
until then, and the run's data is written twice. Hence this writer, tested against asammdf's
reader.

Pure Python (struct, array): memory is one chunk of records, whatever the run's length.
"""

from __future__ import annotations

import struct
import sys
from array import array

from ..errors import InvalidValue

#: Identification flags of an unfinalized file: update the CG cycle counters (bit 0) and the
#: length of the last DT block (bit 2).
UNFINALIZED = 1 | 4
_HEAD = struct.Struct("<4s4xQQ")          # block id, length, link count


def _block(kind: bytes, links, data: bytes) -> bytes:
    body = b"".join(struct.pack("<Q", a) for a in links) + data
    return _HEAD.pack(kind, _HEAD.size + len(body), len(links)) + body


def _text(kind: bytes, text: str) -> bytes:
    raw = text.encode("utf-8") + b"\0"
    raw += b"\0" * (-len(raw) % 8)
    return _block(kind, (), raw)


def _xml(text: str) -> str:
    from xml.sax.saxutils import escape

    return escape(text)


class Mdf4Stream:
    """One MDF 4.10 file of float64 channels over a float64 master ``t`` (s), written as records
    come: ``channels`` ``[(name, unit)]`` (not the master); ``start_ns`` the measurement's start
    (UTC, ns since the epoch: its t = 0); ``stream`` a binary file open for writing at 0."""

    def __init__(self, stream, channels, start_ns: int, tool_version: str = "", comment: str = ""):
        self.stream = stream
        self.n = len(channels)
        self.count = 0
        self.record = 8 * (1 + self.n)
        head = bytearray()
        ident = (b"UnFinMF " + b"4.10    " + b"zkzap   " + b"\0" * 4 + struct.pack("<H", 410) + b"\0" * 30
                 + struct.pack("<HH", UNFINALIZED, 0))
        head += ident
        # the addresses: identification 64, header 104 long, then the rest in order
        at = {"hd": 64}
        at["fh"] = at["hd"] + 104
        fh_md = _text(b"##MD", f"<FHcomment><TX>{_xml(comment or 'measured')}</TX><tool_id>zkzap</tool_id>"
                               f"<tool_vendor>zkzap</tool_vendor><tool_version>{_xml(tool_version)}</tool_version>"
                               "</FHcomment>")
        at["fh_md"] = at["fh"] + 56
        at["dg"] = at["fh_md"] + len(fh_md)
        at["cg"] = at["dg"] + 64
        at["cn"] = at["cg"] + 104
        names = [("t", "s")] + list(channels)
        texts, addr = [], at["cn"] + 160 * len(names)
        name_at, unit_at = [], []
        for name, unit in names:
            blk = _text(b"##TX", name)
            texts.append(blk)
            name_at.append(addr)
            addr += len(blk)
            if unit:
                blk = _text(b"##TX", unit)
                texts.append(blk)
                unit_at.append(addr)
                addr += len(blk)
            else:
                unit_at.append(0)
        self.dt_at = addr
        head += _block(b"##HD", (at["dg"], at["fh"], 0, 0, 0, 0),
                       struct.pack("<QhhBBBBdd", start_ns, 0, 0, 0, 0, 0, 0, 0.0, 0.0))
        head += _block(b"##FH", (0, at["fh_md"]), struct.pack("<Qhhb3x", start_ns, 0, 0, 0))
        head += fh_md
        head += _block(b"##DG", (0, at["cg"], self.dt_at, 0), struct.pack("<B7x", 0))
        self.cg_count_at = len(head) + _HEAD.size + 6 * 8 + 8        # cg_cycle_count, after the record id
        head += _block(b"##CG", (0, at["cn"], 0, 0, 0, 0), struct.pack("<QQHH4xII", 0, 0, 0, 0, self.record, 0))
        for k, (name, unit) in enumerate(names):
            nxt = at["cn"] + 160 * (k + 1) if k + 1 < len(names) else 0
            master = k == 0
            head += _block(b"##CN", (nxt, 0, name_at[k], 0, 0, 0, unit_at[k], 0),
                           struct.pack("<BBBBIIIIBBH6d", 2 if master else 0, 1 if master else 0, 4, 0, 8 * k, 64, 0,
                                       0, 0, 0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        for blk in texts:
            head += blk
        assert len(head) == self.dt_at, (len(head), self.dt_at)
        head += _HEAD.pack(b"##DT", _HEAD.size, 0)     # its length written at the close
        stream.write(head)
        stream.flush()

    def append(self, rows) -> None:
        """Append records ``[(t, v1, ..., vn)]`` (NaN: no value) and flush them to the file."""
        values = array("d")
        for row in rows:
            values.extend(row)
        if len(values) != len(rows) * (1 + self.n):
            raise InvalidValue(f"MDF record of {len(values)} values for {len(rows)} rows of {1 + self.n}")
        if sys.byteorder != "little":
            values.byteswap()
        self.stream.write(values.tobytes())
        self.stream.flush()
        self.count += len(rows)

    def close(self) -> None:
        """Write the data block's length and the record count, and mark the file finalized."""
        s = self.stream
        s.seek(self.dt_at + 8)
        s.write(struct.pack("<Q", _HEAD.size + self.count * self.record))
        s.seek(self.cg_count_at)
        s.write(struct.pack("<Q", self.count))
        s.seek(0)
        s.write(b"MDF     ")
        s.seek(60)
        s.write(struct.pack("<HH", 0, 0))
        s.flush()


def empty(stream, start_ns: int) -> None:
    """A finalized MDF 4.10 file of no measurement (a run that wrote no record with a time)."""
    stream.write(b"MDF     " + b"4.10    " + b"zkzap   " + b"\0" * 4 + struct.pack("<H", 410) + b"\0" * 30
                 + struct.pack("<HH", 0, 0))
    stream.write(_block(b"##HD", (0, 64 + 104, 0, 0, 0, 0),
                        struct.pack("<QhhBBBBdd", start_ns, 0, 0, 0, 0, 0, 0, 0.0, 0.0)))
    stream.write(_block(b"##FH", (0, 0), struct.pack("<Qhhb3x", start_ns, 0, 0, 0)))
