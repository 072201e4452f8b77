"""The Modbus RTU side of the command line: CRCs, decoding, the register maps and --map."""

import json

import pytest


@pytest.mark.parametrize("args,out", [
    (["modbus", "01 03 00 D2 00 01"], "24 33\n"),
    (["modbus", "--append", "01 06 00 CD 03 E8"], "01 06 00 CD 03 E8 18 8B\n"),
    (["modbus", "-a", "01 10 00 D0 00 02 04 03 E8 03 20"], "01 10 00 D0 00 02 04 03 E8 03 20 7F AB\n"),
])
def test_crc_modbus(cli, args, out):
    r = cli("crc", *args)
    assert r.exit_code == 0 and r.stdout == out and r.stderr == ""


@pytest.mark.parametrize("frame", ["01 03 02 03 E8 B8 FA", "01 83 04 40 F3", "01 10 00 D0 00 02 40 31",
                                   "01 03 00 D2 00 01 24 33"])
def test_crc_check_knows_modbus_frames(cli, frame):
    for args in (["modbus", "--check", frame], ["check", frame]):
        r = cli("crc", *args)
        assert r.exit_code == 0 and "Modbus RTU frame" in r.stderr


def test_crc_check_bad_modbus(cli):
    r = cli("crc", "modbus", "--check", "01 03 00 D2 00 01 24 34")
    assert r.exit_code == 1 and "expected 24 33, found 24 34" in r.stderr and r.stdout == ""


def test_decode_modbus_worked_examples(cli):
    r = cli("zap", "decode", "--protocol", "modbus", "-f", "jsonl",
            "01 03 00 D2 00 01 24 33 01 03 02 03 E8 B8 FA 01 83 04 40 F3 01 06 00 D1 03 20 D8 DB")
    assert r.exit_code == 0, r
    recs = [json.loads(x) for x in r.stdout.splitlines()]
    assert [x["kind"] for x in recs] == ["request", "reply", "exception", "request"]
    assert recs[1]["register"] == "present-position" and recs[1]["value"] == 1000
    assert recs[2]["name"] == "slave-device-failure" and recs[2]["exception"] == 4
    assert recs[3]["register"] == "goal-current" and recs[3]["value"] == 800


def test_decode_modbus_single_bad_frame_is_an_error(cli):
    r = cli("zap", "decode", "--protocol", "modbus", "01 03 02 03 E8 B8 FB")
    assert r.exit_code == 1 and r.stdout == "" and "CRC mismatch" in r.stderr


def test_decode_modbus_stream_counts_what_it_skipped(cli, tmp_path):
    p = tmp_path / "bus.bin"
    p.write_bytes(bytes.fromhex("55 01 03 00 D2 00 01 24 34 01 03 00 D2 00 01 24 33 01 03 02"))
    r = cli("zap", "decode", "--protocol", "modbus", "--binary", str(p), "-f", "jsonl")
    assert r.exit_code == 0 and len(r.stdout.splitlines()) == 1
    assert "1 bad (CRC)" in r.stderr and "1 cut short" in r.stderr


def test_registers_modbus(cli):
    r = cli("zap", "registers", "--protocol", "modbus", "goal-position", "id", "-f", "jsonl")
    recs = [json.loads(x) for x in r.stdout.splitlines()]
    assert [(x["name"], x["address"], x["range"]) for x in recs] == [("goal-position", 205, "0..10000"),
                                                                     ("id", 4, "1..247")]


def test_registers_unknown_on_this_map(cli):
    r = cli("zap", "registers", "--protocol", "modbus", "protocol-type")
    assert r.exit_code == 2 and r.stdout == "" and "protocol-type" in r.stderr


@pytest.mark.parametrize("line,fault", [
    ("1 | a | 8 | V | RW | | | | | x", "width 8 bits is not allowed on modbus"),
    ("1 | a | 16 | ROM | RW | | | | | x", "unknown memory kind"),
    ("1 | a | 16 | V | RW | 0..99999 | | | | x", "does not fit 16 bits"),
])
def test_bad_map_file_exit_2_names_file_line(cli, tmp_path, line, fault):
    p = tmp_path / "m.map"
    p.write_text(f"model: Q\nprotocol: modbus\n0 | ok | 16 | V | R | | | | | fine\n{line}\n")
    for cmd in (["registers"], ["decode", "01 03 00 D2 00 01 24 33"]):
        r = cli("zap", *cmd, "--protocol", "modbus", "--map", str(p))
        assert r.exit_code == 2 and r.stdout == "" and f"{p}:4:" in r.stderr and fault in r.stderr, r


def test_map_protocol_must_agree(cli, tmp_path):
    p = tmp_path / "m.map"
    p.write_text("model: Q\nprotocol: modbus\n0 | ok | 16 | V | R | | | | | fine\n")
    r = cli("zap", "registers", "--map", str(p))
    assert r.exit_code == 2 and "--protocol modbus" in r.stderr
    r = cli("zap", "registers", "--protocol", "modbus", "--map", str(p), "-f", "jsonl")
    assert r.exit_code == 0 and json.loads(r.stdout)["name"] == "ok"
