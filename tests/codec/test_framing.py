"""Streaming framers: arbitrary chunking, garbage, resynchronisation, counters, bounded memory."""

import random

from hypothesis import given
from hypothesis import strategies as st

from zkzap.codec import zap, zk
from zkzap.codec.framing import ZapFramer, ZkFramer


def feed_chunked(framer, data, cuts):
    out = []
    pos = 0
    for cut in sorted(set(c for c in cuts if 0 < c < len(data))) + [len(data)]:
        out += framer.feed(data[pos:cut])
        pos = cut
    out += framer.flush()
    return out


status_frames = st.builds(lambda i, p: zk.status_frame(i, p), st.integers(1, 10), st.binary(min_size=5, max_size=5))
control_frames = st.builds(lambda i, a, b: zk.control_frame(i, a, b), st.integers(0, 8), st.integers(0, 15),
                           st.integers(0, 255))
# garbage without any head byte cannot form a false frame
zk_garbage = st.binary(max_size=20).map(lambda b: bytes(x & 0xEF for x in b))


@given(st.lists(st.tuples(zk_garbage, st.one_of(status_frames, control_frames)), max_size=30),
       st.lists(st.integers(0, 400)))
def test_zk_recovers_every_frame_at_any_chunking(items, cuts):
    data = b"".join(g + f for g, f in items)
    framer = ZkFramer()
    out = feed_chunked(framer, data, cuts)
    assert out == [f for _, f in items]
    assert framer.frames == len(items)
    assert framer.skipped == sum(len(g) for g, _ in items)


def test_zk_resynchronises_after_a_bad_crc():
    good = zk.status_frame(1, b"\x00\x00\x00\x00\x4c")
    bad = bytearray(good)
    bad[6] ^= 0xFF
    f = ZkFramer()
    assert f.feed(bytes(bad) + good + b"\xff\x1d\xf4\x70") == [good, bytes.fromhex("FF1DF470")]
    assert f.bad == 1 and f.skipped == 7


def test_zk_accept_filters_kinds():
    data = bytes.fromhex("FF1DF470") + bytes.fromhex("F1000000004CA0")
    assert ZkFramer("status").feed(data) == [data[4:]]
    assert ZkFramer("control").feed(data) == [data[:4]]


def test_zk_byte_at_a_time_and_bounded_buffer():
    rng = random.Random(1)
    frames = [zk.status_frame(rng.randint(1, 9), bytes(rng.randrange(256) for _ in range(5))) for _ in range(500)]
    f = ZkFramer()
    got = []
    for b in b"".join(frames):
        got += f.feed(bytes([b]))
        assert f.pending < 7
    assert got == frames


zap_packets = st.builds(lambda i, c, p: zap.packet(i, c, p), st.integers(0, 254), st.integers(0, 255),
                        st.binary(max_size=40))
zap_garbage = st.binary(max_size=20).map(lambda b: bytes(x & 0x7F for x in b))


@given(st.lists(st.tuples(zap_garbage, zap_packets), max_size=20), st.lists(st.integers(0, 1200)))
def test_zap_recovers_every_packet_at_any_chunking(items, cuts):
    data = b"".join(g + p for g, p in items)
    framer = ZapFramer()
    out = feed_chunked(framer, data, cuts)
    assert out == [p for _, p in items]
    assert framer.skipped == sum(len(g) for g, _ in items)


def test_zap_header_inside_a_run_of_ff():
    pkt = zap.echo(0)
    f = ZapFramer()
    assert f.feed(b"\xff\xff" + pkt) == [pkt]
    assert f.skipped == 2


def test_zap_resynchronises_after_bad_checksum_and_short_size():
    good = zap.store(1, "goal-position", 2047)
    bad = bytearray(good)
    bad[-1] ^= 1
    f = ZapFramer()
    assert f.feed(bytes(bad) + b"\xff\xff\xff\x01\x01" + good) == [good]
    assert f.bad == 2


def test_truncated_tail_is_counted_at_flush():
    f = ZkFramer()
    assert f.feed(bytes.fromhex("F1000000")) == []
    f.flush()
    assert f.skipped == 4
    g = ZapFramer()
    g.feed(zap.echo(0)[:5])
    g.flush()
    assert f.truncated == 1 and f.bad == 0
    assert g.skipped == 5 and g.truncated == 1 and g.bad == 0
