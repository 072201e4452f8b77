"""zkzap crc: compute, append, check."""

import pytest


@pytest.mark.parametrize("args,out", [
    (["zk", "14", "64"], "D3\n"),
    (["zk", "F1 00 00 00 00 4C"], "A0\n"),
    (["zap", "00", "02", "F1"], "0C\n"),
    (["zap", "0x01,0x05,0xF3,0x88,0x00,0x02"], "7C\n"),
    (["zk", "--append", "14", "64"], "14 64 D3\n"),
    (["zap", "-a", "00:02:F1"], "00 02 F1 0C\n"),
])
def test_compute(cli, args, out):
    r = cli("crc", *args)
    assert r.exit_code == 0 and r.stdout == out and r.stderr == ""


@pytest.mark.parametrize("frame", ["FF 14 64 D3", "F1 00 00 00 00 4C A0", "FF FF FF 00 02 F1 0C",
                                   "F6 00 00 A0 00 10 AB", "FF FF FF FE 0A 73 86 02 01 FF 03 02 FF 07 F1"])
def test_check_good(cli, frame):
    for args in (["zk", "--check", frame], ["zap", "--check", frame], ["check", frame]):
        r = cli("crc", *args)
        assert r.exit_code == 0 and r.stdout == "" and "ok" in r.stderr


@pytest.mark.parametrize("frame,expected,found", [("FF 14 64 D4", "D3", "D4"), ("F1 00 00 00 00 4C A1", "A0", "A1"),
                                                  ("FF FF FF 00 02 F1 0D", "0C", "0D")])
def test_check_bad(cli, frame, expected, found):
    r = cli("crc", "check", frame)
    assert r.exit_code == 1 and r.stdout == ""
    assert f"expected {expected}, found {found}" in r.stderr


def test_stdin(cli):
    assert cli("crc", "zk", input="14 64\n").stdout == "D3\n"
    assert cli("crc", "zk", "-", input="14 64\n").stdout == "D3\n"
    assert cli("crc", "check", input="FF 14 64 D3\n").exit_code == 0


@pytest.mark.parametrize("args,needle", [
    (["zk", "1"], "odd number of hex digits"),
    (["zk", "XY"], "is not hex"),
    (["check", "FF 14 64"], "ZK frame: 3 bytes"),
    (["check", "FF 14"], "ZK frame: 2 bytes"),
    (["zk", "--check", "--append", "FF 14 64 D3"], "exclude each other"),
])
def test_bad_input(cli, args, needle):
    r = cli("crc", *args)
    assert r.exit_code == 2 and r.stdout == "" and needle in r.stderr


def test_installed_entry_point(sh):
    r = sh("zkzap", "crc", "zk", "14", "64")
    assert (r.exit_code, r.stdout) == (0, "D3\n")
    r = sh("zkzap", "crc", "check", "FF 14 64 D4")
    assert r.exit_code == 1 and "expected D3, found D4" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("args,out", [
    (["zap", "FF FF FF 01 05 F3 86 FF 07"], "7A\n"),            # the packet up to its checksum
    (["zap", "FF FF FF 01 05 F3 86 FF 07 7A"], "7A\n"),         # whole: the checksum it should end with
    (["zap", "-a", "FF FF FF 01 05 F3 86 FF 07"], "FF FF FF 01 05 F3 86 FF 07 7A\n"),
])
def test_a_zap_packet_with_its_header_is_summed_from_its_id(cli, args, out):
    """The header is never summed (once FF FF FF 01 05 F3 86 FF 07 printed 7D)."""
    r = cli("crc", *args)
    assert r.exit_code == 0 and r.stdout == out and r.stderr == ""


@pytest.mark.parametrize("args,words", [
    (["zap", "FF FF FF 01 05 F3"], "is no packet: SIZE 5 means 10 bytes"),
    (["zap", "FF FF FF 01"], "too short for a packet"),          # once summed with its header
    (["zap", "-a", "FF FF FF 01 05 F3 86 FF 07 7A"], "already ends with its checksum"),
])
def test_bytes_with_the_header_that_are_no_packet_are_refused(cli, args, words):
    r = cli("crc", *args)
    assert r.exit_code == 2 and r.stdout == "" and words in r.stderr
