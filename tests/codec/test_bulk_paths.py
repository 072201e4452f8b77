"""The block paths of binary decoding give what the frame-by-frame paths give.

A run of status frames in step is checked all at once by the ZK framer; a block of frames that
hardly repeat is rendered without the line memo; a wide field's value table is filled whole
once its values keep changing; a version frame that repeats the version is rendered by its
context's encoder. Each is compared here with the plain way, frame for frame and counter for
counter, on streams long enough to take those paths (hundreds to thousands of frames).
"""

from __future__ import annotations

import random

import pytest

from zkzap.codec import framing, zk
from zkzap.codec.framing import ZkFramer
from zkzap.commands.zk.decode import columns
from zkzap.io.writers import csv_dialect, json_dialect
from zkzap.io.zk_lines import ZkLines


def _stream(seed, count, damage=True, controls=True, versions=(5,)):
    """``count`` status frames of IDs 1..14 with random payloads, control frames and damage
    (flipped bytes, cuts, garbage) between them, and version frames of ``versions``."""
    rng = random.Random(seed)
    out = bytearray()
    for i in range(count):
        sid = rng.randint(1, 14)
        payload = bytearray(rng.randbytes(5))
        if sid == 6:
            payload[4] = (rng.choice(versions) << 2) | (payload[4] & 3)
        frame = bytearray(zk.status_frame(sid, bytes(payload)))
        if damage and rng.random() < 0.01:
            frame[rng.randrange(7)] ^= 1 << rng.randrange(8)
        if damage and rng.random() < 0.005:
            frame = frame[:rng.randrange(1, 7)]
        out += frame
        if controls and rng.random() < 0.02:
            out += zk.control_frame(rng.randint(0, 8), rng.randint(0, 15), rng.randint(0, 255))
        if damage and rng.random() < 0.005:
            out += rng.randbytes(rng.randint(1, 9))
    return bytes(out)


def _frames(data, chunk, accept="both"):
    f = ZkFramer(accept)
    out = []
    for i in range(0, len(data), chunk):
        out += f.feed(data[i:i + chunk])
    out += f.flush()
    return out, (f.frames, f.bad, f.truncated, f.filtered, f.skipped)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("accept", ["both", "status", "control"])
def test_runs_checked_at_once_equal_frame_by_frame(seed, accept, monkeypatch):
    controls = seed % 2 == 0
    data = _stream(seed, 3000, damage=seed % 3 != 0, controls=controls)
    fast = _frames(data, 65536, accept)
    assert fast[0] or (accept == "control" and not controls)
    assert fast == _frames(data, 4096 * 7 + 3, accept)            # runs cut by the feeds
    monkeypatch.setattr(framing, "RUN_MIN", 10 ** 9)                # no run is long enough
    slow = _frames(data, 65536, accept)
    assert fast == slow
    assert fast == _frames(data, 5, accept)                         # and a few bytes at a time


def test_a_run_stops_at_the_first_bad_frame():
    good = [zk.status_frame(i % 10 + 1, bytes([i % 256, 0, i // 256, 0, 0])) for i in range(200)]
    bad = bytearray(good[100])
    bad[3] ^= 0x10                                                  # its CRC fails
    data = b"".join(good[:100]) + bytes(bad) + b"".join(good[101:])
    frames, counters = _frames(data, len(data))
    assert frames == good[:100] + good[101:]
    assert counters[:2] == (199, 1)


def _lines(frames, dialect, decoder_args=(), cache=None):
    fast, slow = zk.ZkDecoder(*decoder_args), zk.ZkDecoder(*decoder_args)
    lines = ZkLines(fast, dialect, cache=cache)
    got = []
    for i in range(0, len(frames), 700):                            # blocks, as a framer gives
        got += lines.encode_all(frames[i:i + 700])
    want = []
    for frame in frames:
        rec = slow.decode(frame)
        rec["frame"] = frame.hex(" ").upper()
        want.append(dialect.record(rec))
    return got, want, (fast.version, fast.known, fast.version_source, fast.assumed), \
        (slow.version, slow.known, slow.version_source, slow.assumed)


@pytest.mark.parametrize("versions", [(5,), (1, 5), (2, 3, 4, 6, 40)])
@pytest.mark.parametrize("given", [None, 3])
def test_lines_without_the_memo_equal_the_records(versions, given):
    """Frames that hardly repeat (the memo is left alone), version frames that repeat the
    version or change it in the middle of a block, control frames and unknown IDs."""
    data = _stream(len(versions), 2500, damage=False, versions=versions)
    frames, _ = _frames(data, len(data))
    assert len(frames) > 2500
    for dialect in (json_dialect(), csv_dialect(columns("both", False))):
        got, want, fast, slow = _lines(frames, dialect, (given,))
        assert got == want
        assert fast == slow


def test_wide_field_tables_filled_whole_equal_the_records():
    """Thousands of different thrust (15 bits) and fuel-used (14 bits) values: the tables fill
    as values occur, then whole; every line stays the record's."""
    rng = random.Random(11)
    frames = [zk.status_frame(rng.choice((4, 7)), rng.randbytes(5)) for _ in range(9000)]
    for dialect in (json_dialect(), csv_dialect(columns("both", False))):
        got, want, _, _ = _lines(frames, dialect, (4,))
        assert got == want


def test_repeating_frames_still_use_the_memo():
    frames = [zk.status_frame(i % 10 + 1, bytes([i % 10, 1, 2, 3, 4 << 2])) for i in range(5000)]
    lines = ZkLines(zk.ZkDecoder(), json_dialect())
    lines.encode_all(frames[:1000])
    assert lines._cold <= 0 and len(lines.memo) == 10
    distinct = [zk.status_frame(2, bytes([i % 256, i // 256, 0, 0, 0])) for i in range(1000)]
    lines.encode_all(distinct)
    assert lines._cold > 0                                          # left alone a while
