"""Hex text in the common notations and in dump formats."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from zkzap.codec.hexfmt import HexError, format_hex, parse_hex

EXPECTED = bytes([0xFF, 0x14, 0x64])


@pytest.mark.parametrize("text", ["FF 14 64", "ff1464", "0xFF,0x14,0x64", "FF:14:64", "FF-14-64", "\\xff\\x14\\x64",
                                  "0xff 0x14 0x64", "  FF  14\t64  ", "FF14 64 # a comment", "FF;14;64"])
def test_notations(text):
    assert parse_hex(text) == EXPECTED


def test_dumps():
    xxd = "00000000: ff14 64d3 f100 0000 004c a0              ..d......L.\n"
    assert parse_hex(xxd) == bytes.fromhex("FF1464D3F1000000004CA0")
    hexdump = ("00000000  ff 14 64 d3 f1 00 00 00  00 4c a0 ff 1d f4 70     |..d......L....p|\n"
               "0000000f\n")
    assert parse_hex(hexdump) == bytes.fromhex("FF1464D3F1000000004CA0FF1DF470")
    od = "0000000 ff 14 64 d3\n0000004\n"
    assert parse_hex(od) == bytes.fromhex("FF1464D3")


def test_ambiguous_offsets_are_data():
    # a zap header written as FFFF FF must not be mistaken for an offset
    assert parse_hex("FFFF FF 00 02 F1 0C\nFFFF FF 00 02 F1 0C") == bytes.fromhex("FFFFFF0002F10C") * 2


@pytest.mark.parametrize("text,needle", [("F", "odd number of hex digits"), ("FG", "is not hex"),
                                         ("FF 1", "'1' has an odd number"), ("0x", "is not hex")])
def test_errors(text, needle):
    with pytest.raises(HexError, match=needle):
        parse_hex(text)


def test_error_names_the_line():
    with pytest.raises(HexError, match="line 2"):
        parse_hex("FF 14\nZZ")


@given(st.binary(max_size=100))
def test_round_trip(data):
    assert parse_hex(format_hex(data)) == data
    assert format_hex(data) == " ".join(f"{b:02X}" for b in data)


def test_logic_analyser_csv_exports():
    # Saleae Logic 1: time, value, error columns, a header row
    legacy = ("Time [s],Value,Parity Error,Framing Error\n0.000000000,0xFF,,\n0.000086800,0x1D,,\n"
              "0.000173600,0xF4,,\n0.000260400,0x70,,\n")
    assert parse_hex(legacy) == bytes.fromhex("FF1DF470")
    # Saleae Logic 2: quoted analyser name and type, start time, duration, data
    logic2 = ('name,type,start_time,duration,data\n"Async Serial","data",0.0010,8.68e-05,0xFF\n'
              '"Async Serial","data",0.0011,8.68e-05,0x14\n')
    assert parse_hex(logic2) == bytes.fromhex("FF14")


def test_a_header_is_skipped_only_as_the_first_line():
    with pytest.raises(HexError, match="'foo' is not hex"):
        parse_hex("FF 14\nfoo,bar\n")
    with pytest.raises(HexError):
        parse_hex("Time,Value")          # a single line of arguments is never a header
