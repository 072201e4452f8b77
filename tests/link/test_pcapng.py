"""The pcapng writer and reader: blocks as the format defines them, times and directions intact,
truncated files read to their last whole block, other files refused with what they are."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings, strategies as st

from zkzap.errors import OutputError
from zkzap.link import pcapng
from zkzap.link.pcapng import INBOUND, OUTBOUND, UNKNOWN, CaptureError, Reader, Writer


def write(path, chunks, protocol="zk"):
    w = Writer(str(path))
    i = w.interface(protocol, "/dev/ttyUSB0", 115200)
    for ts, data, d in chunks:
        w.packet(i, ts, data, d)
    w.close()


def test_blocks_are_pcapng(tmp_path):
    p = tmp_path / "c.pcapng"
    write(p, [(1700000000.123456, b"\xff\x1d\xf4\x70", OUTBOUND)])
    raw = p.read_bytes()
    # section header: type, length, byte-order magic, version 1.0
    btype, length, bom, major, minor = struct.unpack("<IIIHH", raw[:16])
    assert (btype, bom, major, minor) == (0x0A0D0D0A, 0x1A2B3C4D, 1, 0)
    assert raw[length - 4:length] == raw[4:8]                    # trailing length repeated
    idb = raw[length:]
    assert struct.unpack("<I", idb[:4])[0] == 1
    assert struct.unpack("<H", idb[8:10])[0] == 147              # DLT_USER0
    epb = idb[struct.unpack("<I", idb[4:8])[0]:]
    assert struct.unpack("<I", epb[:4])[0] == 6
    _, _, if_id, hi, lo, cap, orig = struct.unpack("<IIIIIII", epb[:28])
    assert (if_id, cap, orig) == (0, 4, 4)
    assert (hi << 32 | lo) == 1700000000123456                  # microseconds
    assert epb[28:32] == b"\xff\x1d\xf4\x70"
    assert epb[32:44] == struct.pack("<HHI", 2, 4, OUTBOUND) + b"\0\0\0\0"   # epb_flags, end of options


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 2 ** 40), st.binary(min_size=1, max_size=40),
                          st.sampled_from([INBOUND, OUTBOUND, UNKNOWN])), max_size=30))
def test_round_trip(tmp_path_factory, chunks):
    p = tmp_path_factory.mktemp("rt") / "c.pcapng"
    write(p, [(us / 1e6, data, d) for us, data, d in chunks], "zap")
    if not chunks:
        assert not p.exists()            # no packet, no file: a header is not a record
        return
    r = Reader(str(p), "zap")
    got = [(round(k.ts * 1e6), k.data, k.direction, k.protocol, k.name) for k in r]
    assert got == [(us, data, d, "zap", "/dev/ttyUSB0") for us, data, d in chunks]
    assert not r.truncated


def test_truncated_capture_reads_to_the_last_whole_block(tmp_path):
    p = tmp_path / "c.pcapng"
    write(p, [(1.0 + i, bytes([i]) * 7, INBOUND) for i in range(10)])
    whole = p.read_bytes()
    for cut in (1, 5, 17, 30):
        (tmp_path / "t.pcapng").write_bytes(whole[:-cut])
        r = Reader(str(tmp_path / "t.pcapng"))
        got = list(r)
        assert r.truncated and len(got) == 9 and got[-1].data == bytes([8]) * 7


@pytest.mark.parametrize("content,what", [
    (b"", "an empty file"),
    (b"\xd4\xc3\xb2\xa1\x02\x00\x04\x00" + bytes(16), "a pcap (libpcap) file, not pcapng"),
    (b"FF 1D F4 70\n", "text (starts with 46 46 20 31)"),
    (b"\xff\x1d\xf4\x70", "data starting with FF 1D F4 70"),
])
def test_not_pcapng_is_refused_saying_what_it_is(tmp_path, content, what):
    p = tmp_path / "x.pcapng"
    p.write_bytes(content)
    with pytest.raises(CaptureError) as e:
        Reader(str(p))
    assert str(e.value) == f"{p}: not a pcapng capture: {what}"
    assert e.value.code == 2


def test_other_link_types_are_refused(tmp_path):
    p = tmp_path / "eth.pcapng"
    p.write_bytes(pcapng.section_header("x") + pcapng.interface_block(1, "eth0", ""))
    with pytest.raises(CaptureError, match=r"interface 0 has link type 1 \(ETHERNET\); zkzap captures use 147"):
        list(Reader(str(p)))
    write(tmp_path / "zk.pcapng", [(1.0, b"\x00", INBOUND)], "zk")
    with pytest.raises(CaptureError, match=r"a ZK capture \(link type 147\); expected mightyZAP \(link type 148\)"):
        list(Reader(str(tmp_path / "zk.pcapng"), "zap"))


def test_a_failed_write_leaves_whole_blocks_and_raises_output_error(tmp_path, monkeypatch):
    p = tmp_path / "c.pcapng"
    w = Writer(str(p))
    i = w.interface("zk", "sim://zk")
    w.packet(i, 1.0, b"\xf1" * 7, INBOUND)
    good = p.stat().st_size
    real = pcapng.os.write

    def short(fd, data):                  # the disk fills in the middle of a block
        if len(data) > 8:
            real(fd, bytes(data[:8]))
            return 8
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pcapng.os, "write", short)
    with pytest.raises(OutputError, match=f"capture: cannot write {p}: No space left on device"):
        w.packet(i, 2.0, b"\xf2" * 7, INBOUND)
    monkeypatch.setattr(pcapng.os, "write", real)
    assert p.stat().st_size == good
    with pytest.raises(OutputError):
        w.packet(i, 3.0, b"\xf3" * 7, INBOUND)      # later writes fail the same way
    w.close()
    r = Reader(str(p))
    assert [k.data for k in r] == [b"\xf1" * 7] and not r.truncated


# --- captures that lie about their blocks -------------------------------------------------------

def _blocks(raw):
    """[(offset, type, length)] of a little-endian capture written by Writer."""
    out, off = [], 0
    while off < len(raw):
        btype, length = struct.unpack("<II", raw[off:off + 8])
        out.append((off, btype, length))
        off += length
    return out


def _packet_block(body_len_fields):
    body = struct.pack("<I", 0) * body_len_fields
    n = 12 + len(body)
    return struct.pack("<II", pcapng.EPB, n) + body + struct.pack("<I", n)


def _lie(raw, how):
    """``raw`` with its third packet block made to lie as ``how`` says."""
    off, _, length = [b for b in _blocks(raw) if b[1] == pcapng.EPB][2]
    b = bytearray(raw)
    if how == "short body":                  # a packet block shorter than its five fields
        b[off:off + length] = _packet_block(2)
    elif how == "caplen beyond the body":
        b[off + 20:off + 24] = struct.pack("<I", 1000)
    elif how == "undescribed interface":
        b[off + 8:off + 12] = struct.pack("<I", 7)
    elif how == "time after 9999":
        b[off + 12:off + 20] = b"\xff" * 8
    elif how == "length 0xFFFFFFFF":
        b[off + 4:off + 8] = b"\xff" * 4
    elif how == "length 8":
        b[off + 4:off + 8] = struct.pack("<I", 8)
    elif how == "closing length differs":
        b[off + length - 4:off + length] = struct.pack("<I", length + 4)
    elif how == "length beyond the file":
        b[off + 4:off + 8] = struct.pack("<I", len(raw) * 4)
    return bytes(b)


#: how -> (packets read of the 10, what problems() says)
LIES = {
    "short body": (9, r"1 malformed block skipped \(the first at byte \d+: a packet block of 20 bytes"),
    "caplen beyond the body": (9, r"1 malformed block skipped .*a packet of 1000 bytes in a block of"),
    "undescribed interface": (9, r"1 malformed block skipped .*interface 7, which was never described"),
    "time after 9999": (9, r"1 malformed block skipped .*after the year 9999"),
    "length 0xFFFFFFFF": (2, r"damaged at byte \d+ \(a block of length 4294967295 \(at most 16777216 bytes\)\): "
                             r"decoded up to there \(2 chunks\)"),
    "length 8": (2, r"damaged at byte \d+ \(a block of length 8 \(at least 12"),
    "closing length differs": (2, r"damaged at byte \d+ \(a block whose closing length \d+ differs"),
    "length beyond the file": (2, r"the capture is truncated: decoded up to its last whole block \(2 chunks\)"),
}


@pytest.mark.parametrize("how", list(LIES))
def test_a_capture_that_lies_about_a_block_gives_what_is_whole_and_says_what_is_not(tmp_path, how):
    p = tmp_path / "c.pcapng"
    write(p, [(1.0 + i, bytes([i]) * 7, INBOUND) for i in range(10)])
    p.write_bytes(_lie(p.read_bytes(), how))
    count, said = LIES[how]
    r = Reader(str(p))
    got = list(r)
    assert len(got) == r.packets == count
    assert [k.data[0] for k in got] == [i for i in range(10) if i != 2][:count]
    assert len(r.problems()) == 1
    assert pytest.importorskip("re").search(said, r.problems()[0]), r.problems()


def test_a_later_interface_of_another_link_type_is_skipped_and_counted(tmp_path):
    p = tmp_path / "c.pcapng"
    w = Writer(str(p))
    zk_if = w.interface("zk", "/dev/ttyUSB0")
    w.packet(zk_if, 1.0, b"\x01", INBOUND)
    w.close()
    raw = p.read_bytes() + pcapng.interface_block(1, "eth0", "") + pcapng.packet_block(1, 2, b"\x02") \
        + pcapng.packet_block(0, 3, b"\x03", INBOUND)
    p.write_bytes(raw)
    r = Reader(str(p), "zk")
    assert [k.data for k in r] == [b"\x01", b"\x03"] and r.foreign == 1
    assert r.problems() == ["1 chunk of interfaces of another link type skipped"]


def test_a_broken_section_header_is_not_a_capture(tmp_path):
    p = tmp_path / "c.pcapng"
    p.write_bytes(pcapng.MAGIC + b"\xff\xff\xff\xff" + struct.pack("<I", 0x1A2B3C4D) + bytes(16))
    with pytest.raises(CaptureError, match=r"not a pcapng capture: a block of length 4294967295 .* at byte 0"):
        list(Reader(str(p)))
