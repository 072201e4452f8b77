"""Frames read together get their own times: back from the read by a frame's time on the wire,
never within a millisecond of the frame before, never before the session's start."""

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
    later = src._stamp(1.0002, [b"d"])                    # read just after: still after the last one
    assert later[0][0] == 1.0 + MIN_SPACING_S
    src._last_t = None
    early = src._stamp(0.0005, [b"x"] * 5)                # bytes waiting before the start
    times = [t for t, _ in early]
    assert times[0] == 0.0 and all(b - a >= MIN_SPACING_S - 1e-12 for a, b in zip(times, times[1:]))
