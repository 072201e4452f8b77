"""The UART model: what a receiver at other line settings makes of a sender's bytes."""

from hypothesis import given, strategies as st

from zkzap.codec.framing import ZkFramer
from zkzap.sim.uart import Line, reframe

BAUDS = (2400, 4800, 9600, 19200, 38400, 57600, 115200)
FRAME = bytes.fromhex("F1 00 00 00 00 4C A0")


@given(st.binary(max_size=64), st.sampled_from(BAUDS), st.sampled_from((1, 2)))
def test_same_settings_read_cleanly(data, baud, stop):
    assert reframe(data, baud, stop, baud, stop) == data


@given(st.binary(min_size=1, max_size=64), st.sampled_from(BAUDS))
def test_a_receiver_expecting_fewer_stop_bits_reads_cleanly(data, baud):
    assert reframe(data, baud, 2, baud, 1) == data


@given(st.binary(min_size=1, max_size=64), st.sampled_from(BAUDS))
def test_the_sampler_itself_reads_a_slightly_fast_sender(data, baud):
    # 1 % off is within any UART's tolerance: the sampling path (not the shortcut) reads it
    assert reframe(data, baud, 1, round(baud * 1.01), 1) == data


def test_a_two_stop_bit_receiver_misframes_back_to_back_bytes_of_a_one_stop_bit_sender():
    out = reframe(FRAME * 4, 9600, 1, 9600, 2)
    assert out != FRAME * 4 and 0 in out
    assert ZkFramer("status").feed(out) == []


def test_every_other_documented_baud_sees_no_status_frame():
    stream = b"".join(FRAME[:0] + bytes.fromhex(h) for h in (
        "F1 00 00 00 00 4C A0", "F6 00 00 A0 00 10 AB")) * 6
    for tx in BAUDS:
        for rx in BAUDS:
            got = ZkFramer("status").feed(reframe(stream, tx, 1, rx, 1))
            assert (len(got) == 12) == (tx == rx), (tx, rx)


def test_line_without_a_baud_follows_the_host():
    line = Line(None, 1)
    assert line.to_host(FRAME, 2400, 1) == FRAME
    assert line.to_host(FRAME, None, None) == FRAME          # TCP: the host's settings are unknown
    assert Line(9600, 1).to_host(FRAME, 19200, 1) != FRAME
