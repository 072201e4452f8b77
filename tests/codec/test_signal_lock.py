"""Noise is not a device: the SignalLock hands on frames only from a stream that is frames.

Worked examples: random bytes (which an 8-bit CRC lets through about once in 4 700 bytes), an
ECU's stream, both in turn, a damaged line, the host's own echo, a mightyZAP bus at the wrong
baud rate. Streams are fed in chunks the size a serial read returns."""

from __future__ import annotations

import random

import pytest

from zkzap.codec import zap, zk
from zkzap.codec.framing import LOCK_FRAMES, SignalLock, ZapFramer, ZkFramer


def ecu_stream(n, seed=1):
    rng = random.Random(seed)
    return b"".join(zk.status_frame(i % 10 + 1, rng.randbytes(5)) for i in range(n))


def feed(lock, data, chunk=64):
    out = []
    for i in range(0, len(data), chunk):
        part = data[i:i + chunk]
        out += lock.admit(len(part), lock.framer.feed(part))
    return out


def test_random_bytes_give_chance_frames_and_the_lock_hands_on_none():
    noise = random.Random(7).randbytes(200_000)          # about 17 s of a line at 115200 baud
    framer = ZkFramer("status")
    lock = SignalLock(framer)
    assert feed(lock, noise, chunk=115) == []
    assert framer.frames >= 20                            # the CRC let some through by chance...
    assert lock.rejected + len(lock.held) == framer.frames and lock.accepted == 0   # ...none passed
    assert lock.noise and not lock.locked


@pytest.mark.parametrize("chunk", [1, 7, 64, 4096])
def test_an_ecus_stream_is_handed_on_whole_after_the_first_frames(chunk):
    frames = ecu_stream(200)
    lock = SignalLock(ZkFramer("status"))
    got = feed(lock, b"\x33\x10" + frames, chunk)        # starts mid-frame, as a port opened late does
    assert b"".join(got) == frames and lock.locked and not lock.noise


def test_noise_then_an_ecu_then_noise():
    rng = random.Random(3)
    lock = SignalLock(ZkFramer("status"))
    assert feed(lock, rng.randbytes(5000)) == []
    ecu = ecu_stream(100, seed=2)
    got = feed(lock, ecu)
    assert len(got) >= 100 - 2 * LOCK_FRAMES and b"".join(got) in ecu   # the ECU comes through...
    assert feed(lock, rng.randbytes(20_000)) == [] and not lock.locked   # ...and noise after it does not


def test_a_damaged_line_is_still_an_ecu():
    frames = [zk.status_frame(i % 10 + 1, bytes(5)) for i in range(300)]
    # every other frame corrupted: half the bytes are skipped, the other half are frames
    damaged = b"".join(f if i % 2 else f[:3] + bytes([f[3] ^ 0x55]) + f[4:] for i, f in enumerate(frames))
    got = feed(SignalLock(ZkFramer("status")), damaged)
    assert len(got) >= 150 - LOCK_FRAMES


def test_the_hosts_echoed_control_frames_are_not_noise():
    keep = zk.encode_control("keepalive")[0]
    stream = b"".join(keep * 3 + zk.status_frame(i % 10 + 1, bytes(5)) for i in range(100))
    got = feed(SignalLock(ZkFramer("status")), stream)
    assert len(got) == 100


def test_a_sniffer_trusts_a_clean_first_frame_at_once():
    lock = SignalLock(ZkFramer("both"), confirm=1)
    frame = zk.status_frame(1, bytes(5))
    assert lock.admit(7, lock.framer.feed(frame)) == [frame]


def test_a_mightyzap_bus_at_the_wrong_baud_rate_is_noise():
    rng = random.Random(5)
    lock = SignalLock(ZapFramer(), confirm=1)
    assert feed(lock, rng.randbytes(30_000)) == [] and lock.noise
    good = SignalLock(ZapFramer(), confirm=1)
    packets = b"".join(zap.packet(1, 0, bytes([i, 7])) for i in range(50))
    assert len(feed(good, packets)) == 50
