"""Hex dumps as the real tools print them, analyser CSV rows, binary fed to the hex reader,
and lines of any length in constant memory."""

from __future__ import annotations

import io
import os
import random
import shutil
import subprocess

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zkzap.codec import hexfmt
from zkzap.codec.hexfmt import HexError, iter_hex_stream, parse_hex

FRAME = bytes.fromhex("FF1464D3F1000000004CA0")
rng = random.Random(7)
DATA = {
    "one-frame": FRAME,
    "repeats": bytes(48) + FRAME + bytes(40) + FRAME + b"\xaa" * 64,
    "zeros": bytes(4096),
    "repeat-at-the-end": FRAME + bytes(100),
    "random": bytes(rng.randrange(256) for _ in range(1000)),
    "16": bytes(range(16)),
    "printable": b"  >x< |y| #z  " * 9 + FRAME,                   # what the ASCII columns show
}
TOOLS = {
    "od -A x -t x1": ["od", "-A", "x", "-t", "x1"],
    "od -t x1": ["od", "-t", "x1"],
    "od -A o -t x1": ["od", "-A", "o", "-t", "x1"],
    "od -A d -t x1": ["od", "-A", "d", "-t", "x1"],
    "od -A x -t x1z": ["od", "-A", "x", "-t", "x1z"],              # z: the >printable< column
    "od -t x1z": ["od", "-t", "x1z"],
    "hexdump -C": ["hexdump", "-C"],
    "xxd": ["xxd"],
    "xxd -a": ["xxd", "-a"],
    "xxd -g1": ["xxd", "-g1"],
}


@pytest.mark.parametrize("name", list(DATA))
@pytest.mark.parametrize("tool", list(TOOLS))
def test_real_tool_dumps_read_back_exactly(tool, name, tmp_path):
    argv = TOOLS[tool]
    if shutil.which(argv[0]) is None:
        pytest.skip(f"{argv[0]} not installed")
    if tool == "od -A d -t x1" and name == "zeros":
        pytest.skip("od -A d after a '*' first line: decimal and octal offsets look alike")
    f = tmp_path / "data.bin"
    f.write_bytes(DATA[name])
    text = subprocess.run([*argv, str(f)], capture_output=True, text=True, check=True).stdout
    assert parse_hex(text) == DATA[name]
    assert b"".join(iter_hex_stream(io.StringIO(text))) == DATA[name]


def test_od_six_digit_offsets_are_not_data():
    assert parse_hex("000000 ff 14 64 d3\n000004\n") == FRAME[:4]
    assert parse_hex("000000 ff 14 64 d3 f1 00 00 00 00 4c a0\n00000b\n") == FRAME
    # a six-digit token that does not start a dump is data, as written
    assert parse_hex("FF1464 D3") == FRAME[:4]
    assert parse_hex("F10000 00 00 4C A0") == bytes.fromhex("F1000000004CA0")


def test_a_repeat_expands_in_bounded_blocks():
    text = "00000000  00 00 00 00 00 00 00 00  00 00 00 00 00 00 00 00  |................|\n*\n01000000\n"
    n = 0
    for piece in iter_hex_stream(io.StringIO(text)):
        assert len(piece) <= hexfmt.BLOCK
        n += len(piece)
    assert n == 0x01000000


@pytest.mark.parametrize("text,needle", [
    ("*\n", "'*' is not hex"),
    ("00000000  ff 14 64 d3  |..d.|\n*\nff 14\n", "not followed by an offset"),
    ("00000010  ff 14 64 d3  |..d.|\n*\n00000000\n", "before the repeated line's end"),
])
def test_bad_repeats_are_refused(text, needle):
    with pytest.raises(HexError, match=needle):
        parse_hex(text)


@pytest.mark.parametrize("text,expected", [
    ("1e-05,0x1D\n", "1D"),
    ("10,0xFF\n", "FF"),
    ("Time [s],Value\n0,0xFF\n1e-05,0x1D\n2.0e-05,0xF4\n10,0x70\n", "FF 1D F4 70"),
    ("time,value,parity\n0.000000000,0xFF,,\n0.000086800,0x1D,,\n", "FF 1D"),
    ('"Async Serial","data",1.5e-3,8.68e-05,"0x14"\n', "14"),
    ("0xFF,0x14,0x64\n", "FF 14 64"),            # no time column: every cell is data
    ("FF,14,64\n", "FF 14 64"),
])
def test_logic_analyser_rows_with_a_time_column(text, expected):
    assert parse_hex(text) == bytes.fromhex(expected)
    assert b"".join(iter_hex_stream(io.StringIO(text))) == bytes.fromhex(expected)


BINARY = [b"\xff\x14\x64\xd3\xf1\x00\x00\x00\x00\x4c\xa0", b"FF 14\x00", b"\x1b[0m", bytes(range(256))]


@pytest.mark.parametrize("data", BINARY, ids=["frames", "nul", "escape", "all-bytes"])
@pytest.mark.parametrize("command", [["zk", "decode"], ["zap", "decode"], ["crc", "zk"], ["crc", "check"],
                                     ["zk", "decode", "-"]])
def test_binary_fed_to_the_hex_reader_points_to_binary(sh, command, data):
    r = sh("zkzap", *command, input=data)
    err = r.stderr.decode("utf-8", "replace")
    assert r.exit_code == 2, r
    assert "binary input" in err and "use --binary" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not r.stdout


def test_a_long_line_is_read_in_bounded_pieces(monkeypatch):
    line = "ff1464d3" * 100_000 + "\n"
    pieces = list(iter_hex_stream(io.StringIO(line)))
    assert b"".join(pieces) == bytes.fromhex("ff1464d3") * 100_000
    assert max(map(len, pieces)) <= hexfmt.PIECE // 2 + 1


@settings(max_examples=200, deadline=None)
@given(data=st.binary(min_size=0, max_size=60), sep=st.sampled_from([" ", "", ",", ":", "\\x", " 0x", "-"]),
       piece=st.integers(3, 17), comment=st.booleans())
def test_pieces_cut_anywhere_read_the_same(data, sep, piece, comment):
    if sep in ("\\x", " 0x"):
        text = "".join(f"{sep}{b:02x}" for b in data)
    else:
        text = sep.join(f"{b:02X}" for b in data)
    text = text + (" # a comment, ff ff" if comment else "")
    stream = io.StringIO(text + "\n" + text + "\n")
    old, hexfmt.PIECE = hexfmt.PIECE, piece
    try:
        assert b"".join(iter_hex_stream(stream)) == data * 2
    finally:
        hexfmt.PIECE = old


def test_a_long_line_with_bad_hex_names_its_line(monkeypatch):
    monkeypatch.setattr(hexfmt, "PIECE", 8)
    with pytest.raises(HexError, match="line 2"):
        list(iter_hex_stream(io.StringIO("ff\n" + "ff" * 20 + "zz" + "ff" * 20 + "\n")))


def test_a_stream_that_has_given_bytes_skips_and_counts_its_damaged_lines():
    text = "FF 14 64 D3\n# ok\nxx yy\nF1 00 00 00 00 4C A0\n0\n" + "Z" * (3 * hexfmt.PIECE) + "\nFF 1D F4 70\n"
    skipped = hexfmt.HexSkips()
    got = b"".join(iter_hex_stream(io.StringIO(text), skipped=skipped))
    assert got == bytes.fromhex("FF1464D3 F1000000004CA0 FF1DF470")
    assert skipped.lines == 3 and skipped.note() == "3 lines that are not hex skipped (the first: 'xx' is not hex (line 3))"
    with pytest.raises(HexError, match=r"'xx' is not hex \(line 3\)"):      # without a tally: an error, as before
        b"".join(iter_hex_stream(io.StringIO(text)))
    with pytest.raises(HexError, match=r"'xx' is not hex \(line 1\)"):      # a stream that starts so is refused
        b"".join(iter_hex_stream(io.StringIO("xx\nFF 14\n"), skipped=hexfmt.HexSkips()))


@pytest.mark.parametrize("cmd", ["zk", "zap"])
def test_decode_of_a_damaged_hex_stream_gives_the_whole_lines_and_a_note(sh, cmd):
    frame = "F1 00 00 00 00 4C A0" if cmd == "zk" else "FF FF FF 00 04 00 FF 07 F5"
    data = (f"{frame}\n".encode() + b"\xff\xfe garbage\n" + b"zz\n" + f"{frame}\n".encode())
    r = sh(cmd, "decode", "-f", "jsonl", input=data)
    assert r.exit_code == 0 and len(r.stdout.splitlines()) == 2, r
    assert b"note: stdin: 2 lines that are not hex skipped (the first: binary input (line 2))" in r.stderr
    r = sh(cmd, "decode", "-f", "jsonl", input=b"\xff\xfe\n" + data)
    assert (r.exit_code, r.stdout) == (2, b"") and b"stdin: binary input (line 1): use --binary" in r.stderr
