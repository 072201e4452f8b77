"""Frames read together get their own times: back from the read by a frame's time on the wire,
never within a millisecond of the frame before, never before the session's start — and never
after the read (a stamp is never ahead of the clock, even at more than 1000 frames a second)."""

from __future__ import annotations

from zkzap.link.zk_sources import MIN_SPACING_S, LiveSource


class _Ser:
    baudrate, stopbits = 115200, 1


class _Link:
    ser = _Ser()


def _source():
    src = LiveSource.__new__(LiveSource)
    src.link, src.speed, src._wire_s, src._last_t = _Link(), 1.0, None, None
    return src


def test_frames_of_one_read_are_back_dated_by_their_wire_time():
    src = _source()
    got = src._stamp(1.0, [b"a", b"b", b"c"])
    wire = max(7 * 10 / 115200, MIN_SPACING_S)           # 0.61 ms on the wire: at least the 1 ms of a record's t
    assert [round(t, 6) for t, _ in got] == [round(1.0 - 2 * wire, 6), round(1.0 - wire, 6), 1.0]
    later = src._stamp(1.0015, [b"d"])                    # read a while after: its own time
    assert later[0][0] == 1.0015
    sooner = src._stamp(1.002, [b"e"])                    # within a millisecond of it: after it, not after the read
    assert sooner[0][0] == 1.002
    sooner = src._stamp(1.0022, [b"f"])
    assert 1.002 < sooner[0][0] <= 1.0022 + 1e-12
    src._last_t = None
    early = src._stamp(0.0025, [b"x"] * 5)                # bytes waiting before the start
    times = [t for t, _ in early]
    assert times[0] == 0.0 and all(b - a >= MIN_SPACING_S - 1e-12 for a, b in zip(times, times[1:3]))
    assert times[2] < times[3] < times[4] <= 0.0025 + 1e-12   # no room for a millisecond more: up to the read


def test_frames_faster_than_one_a_millisecond_are_never_stamped_ahead_of_the_clock():
    # an overspeed simulator over TCP: 2000 frames a second, read two at a time each millisecond
    src = _source()
    stamps = []
    for i in range(1, 5001):
        clock = i * 0.001
        got = src._stamp(clock, [b"a", b"b"])
        assert all(t <= clock + 1e-12 for t, _ in got)
        stamps += [t for t, _ in got]
    assert all(b >= a for a, b in zip(stamps, stamps[1:]))   # in order
    assert stamps[-1] <= 5.0 and stamps[-1] > 4.99            # 5 s of frames span 5 s, not 10
