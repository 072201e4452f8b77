"""Fuzzing the streaming framers and the record decoders (the short version; the long one is
``benchmarks/fuzz.py``, which shares this file's stream model and checker).

Properties, for ZkFramer and ZapFramer and through ZkDecoder/ZapDecoder and the generated
text encoders: nothing raises; every frame returned has a valid CRC/checksum; every byte is
either in a returned frame or counted as skipped; every valid frame embedded in the stream is
returned unless its own bytes were damaged or a false frame (one that passed the 8-bit check
by chance) overlaps it, and such losses stay rare.
"""

from __future__ import annotations

import importlib.util
import os
import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from zkzap.codec import zap, zk
from zkzap.codec.framing import ZapFramer, ZkFramer
from zkzap.commands.zk.decode import columns
from zkzap.io.writers import csv_dialect, json_dialect
from zkzap.io.zk_lines import ZkLines

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_spec = importlib.util.spec_from_file_location("zkzap_fuzz", os.path.join(ROOT, "benchmarks", "fuzz.py"))
fuzz = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fuzz)

FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

status_frames = st.builds(zk.status_frame, st.integers(1, 14), st.binary(min_size=5, max_size=5))
control_frames = st.builds(zk.control_frame, st.integers(0, 8), st.integers(0, 15), st.integers(0, 255))
zk_frames = st.one_of(status_frames, control_frames)
zap_packets = st.builds(zap.packet, st.integers(0, 254), st.integers(0, 255), st.binary(max_size=24))


def run(framer, data, cuts=()):
    out = []
    prev = 0
    for cut in sorted(set(c for c in cuts if 0 < c < len(data))) + [len(data)]:
        out += framer.feed(data[prev:cut])
        prev = cut
    return out + framer.flush()


# --- valid frames split at every offset -----------------------------------------------------

@FAST
@given(st.lists(zk_frames, min_size=1, max_size=6))
def test_zk_frames_split_at_every_offset(frames):
    data = b"".join(frames)
    for cut in range(len(data) + 1):
        f = ZkFramer()
        assert run(f, data, [cut]) == frames
        assert f.skipped == 0 and f.bad == 0 and f.frames == len(frames)


@FAST
@given(st.lists(zap_packets, min_size=1, max_size=4))
def test_zap_packets_split_at_every_offset(packets):
    data = b"".join(packets)
    for cut in range(len(data) + 1):
        f = ZapFramer()
        assert run(f, data, [cut]) == packets
        assert f.skipped == 0 and f.bad == 0


# --- garbage, truncation, false heads, bit flips: the shared checker -------------------------

def zk_piece():
    return st.one_of(
        zk_frames.map(lambda f: ("frame", f)),
        st.binary(min_size=1, max_size=12).map(lambda g: ("garbage", g)),
        st.tuples(st.integers(0xF1, 0xFF), st.binary(max_size=6)).map(lambda t: ("false", bytes((t[0],)) + t[1])),
        st.tuples(zk_frames, st.integers(1, 6)).map(lambda t: ("cut", t[0][:min(t[1], len(t[0]) - 1)])),
        st.tuples(zk_frames, st.integers(0, 55)).map(lambda t: ("flip", _flip(t[0], t[1]))),
    )


def zap_piece():
    return st.one_of(
        zap_packets.map(lambda p: ("frame", p)),
        st.binary(min_size=1, max_size=12).map(lambda g: ("garbage", g)),
        st.tuples(st.integers(1, 4), st.binary(max_size=8)).map(lambda t: ("false", b"\xff" * t[0] + t[1])),
        st.tuples(zap_packets, st.integers(1, 40)).map(lambda t: ("cut", t[0][:min(t[1], len(t[0]) - 1)])),
        st.tuples(zap_packets, st.integers(0, 500)).map(lambda t: ("flip", _flip(t[0], t[1]))),
    )


def _flip(frame, bit):
    b = bytearray(frame)
    bit %= 8 * len(b)
    b[bit // 8] ^= 1 << (bit % 8)
    return bytes(b)


def case_of(proto, pieces, cuts, accept="both"):
    data = b""
    expected = []
    for kind, piece in pieces:
        if kind == "frame" and (proto == "zap" or accept == "both" or (len(piece) == 7) == (accept == "status")):
            expected.append((len(data), piece))
        data += piece
    return fuzz.Case(proto, data, expected, accept if proto == "zk" else None, sorted(set(cuts)))


def assert_sound(tally):
    assert tally.errors == 0 and tally.violations == 0, tally.examples
    assert tally.lost_unexplained == 0


@FAST
@given(st.lists(zk_piece(), max_size=14), st.lists(st.integers(1, 150), max_size=6),
       st.sampled_from(["both", "both", "status", "control"]))
def test_zk_streams(pieces, cuts, accept):
    assert_sound(fuzz.check_case(case_of("zk", pieces, cuts, accept)))


@FAST
@given(st.lists(zap_piece(), max_size=10), st.lists(st.integers(1, 400), max_size=6))
def test_zap_streams(pieces, cuts):
    assert_sound(fuzz.check_case(case_of("zap", pieces, cuts)))


@pytest.mark.parametrize("proto", ["zk", "zap"])
def test_seeded_random_streams(proto):
    """8000 streams of the long fuzzer's model: no violation, and the losses to false frames
    stay near the measured residual rate (about 1e-3 of the embedded frames)."""
    tally = fuzz.run_batch(proto, seed=20240611, count=8000)
    assert tally.streams == 8000 and tally.embedded > 16000
    assert_sound(tally)
    assert tally.recovered + tally.lost_explained == tally.embedded
    assert tally.lost_explained <= tally.embedded * 0.005


# --- resynchronisation ----------------------------------------------------------------------

def test_zk_truncated_frame_no_longer_hides_the_next_frame():
    """A false frame formed by a truncated head and the start of the real frame loses to the
    real frame, which a following frame confirms."""
    rng = random.Random(3)
    for _ in range(20000):
        real = zk.status_frame(rng.randint(1, 10), rng.randbytes(5))
        cut = bytes((rng.choice(range(0xF1, 0xFF)),)) + rng.randbytes(rng.randint(1, 5))
        false = cut + real[:7 - len(cut)]
        damaged = (b"\xf1" + cut + real)[:7]             # a damaged frame whose span covers the cut
        if zk.crc8_maxim(false[:6]) == false[6] and zk.crc8_maxim(damaged[:6]) != damaged[6]:
            after = zk.status_frame(1, b"\x00\x00\x00\x00\x4c")
            f = ZkFramer()
            data = b"\xf1" + cut + real + after
            assert run(f, data) == [real, after]
            for k in range(len(data) + 1):
                assert run(ZkFramer(), data, [k]) == [real, after]
            return
    pytest.fail("no colliding prefix found")


def test_held_frame_is_returned_by_flush():
    real = zk.status_frame(2, b"\x10\x20\xf5\x01\x02")   # an F5 inside: a rival head to check
    assert zk.crc8_maxim(b"\xf1\x00" + real[:4]) != real[4]   # F1 00 ... is a damaged frame
    f = ZkFramer()
    assert f.feed(b"\xf1\x00" + real) == []      # inside a damaged region: waits for what follows
    assert f.pending == 7
    assert f.flush() == [real]
    assert f.skipped == 2 and f.frames == 1 and f.bad == 1


def test_in_step_frames_are_never_held():
    frames = [zk.status_frame(2, b"\x10\x20\xf5\x01\x02"), zk.control_frame(1, 0xD, 0xF4)]
    f = ZkFramer()
    for fr in frames:
        assert f.feed(fr) == [fr] and f.pending == 0
    p = zap.packet(1, 0, b"\xff\xff\xff\x05")
    g = ZapFramer()
    assert g.feed(p) == [p] and g.feed(p[:4]) == [] and g.feed(p[4:]) == [p]


# --- the text encoders are the record decoders, line for line ---------------------------------

@FAST
@given(st.lists(zk_frames, max_size=60), st.sampled_from([None, 1, 3, 4, 6]), st.booleans(),
       st.sampled_from(["both", "status", "control"]))
def test_text_lines_equal_rendered_records(frames, version, raw, accept):
    frames = frames + frames[: len(frames) // 2]              # repeats: served by the memo
    for dialect in (json_dialect(), csv_dialect(columns(accept, raw))):
        fast = zk.ZkDecoder(version, raw=raw)
        slow = zk.ZkDecoder(version, raw=raw)
        lines = ZkLines(fast, dialect, cache=8).encode_all(frames)
        for frame, line in zip(frames, lines):
            rec = slow.decode(frame)
            rec["frame"] = frame.hex(" ").upper()
            assert line == dialect.record(rec)
        assert (fast.version, fast.known, fast.version_source, fast.rpm_factor, fast.assumed) == \
               (slow.version, slow.known, slow.version_source, slow.rpm_factor, slow.assumed)


def test_memo_stays_bounded():
    lines = ZkLines(zk.ZkDecoder(), json_dialect(), cache=64)
    rng = random.Random(5)
    frames = [zk.status_frame(rng.randint(1, 10), rng.randbytes(5)) for _ in range(1000)]
    lines.encode_all(frames)
    assert len(lines._memo) <= 64 and len(lines._old) <= 64
