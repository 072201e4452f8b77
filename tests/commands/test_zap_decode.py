"""zap decode: commands and feedback, pairing, formats, bad packets."""

import csv
import io
import json

CAPTURE = ("FF FF FF 00 04 F2 8C 02 7B  FF FF FF 00 04 00 FF 07 F5  "
           "FF FF FF 00 04 F2 92 01 76  FF FF FF 00 03 00 7B 81  "
           "FF FF FF 01 03 F6 01 04  FF FF FF 01 02 21 DB")


def records(text):
    return [json.loads(line) for line in text.splitlines()]


def test_capture_of_both_directions(cli):
    recs = records(cli("zap", "decode", CAPTURE).stdout)
    assert [r["kind"] for r in recs] == ["command", "feedback", "command", "feedback", "command", "feedback"]
    assert recs[1]["register"] == "present-position" and recs[1]["value"] == 2047
    assert recs[3]["register"] == "present-voltage" and recs[3]["physical"] == 12.3 and recs[3]["unit"] == "V"
    assert recs[4]["instruction"] == "factory-reset" and recs[4]["reset_id"] is True
    assert recs[5]["errors"] == ["overload", "input-voltage"]


def test_formats(cli):
    assert len(json.loads(cli("zap", "decode", CAPTURE, "-f", "json").stdout)) == 6
    rows = list(csv.reader(io.StringIO(cli("zap", "decode", CAPTURE, "-f", "csv").stdout)))
    assert len(rows) == 7 and all(len(r) == len(rows[0]) for r in rows)
    assert rows[0][0] == "kind" and rows[0][-1] == "frame"


def test_bad_packet_in_stream_and_alone(cli):
    r = cli("zap", "decode", "FF FF FF 00 02 F1 0D " + CAPTURE)
    assert r.exit_code == 0 and len(records(r.stdout)) == 6 and "1 bad (checksum)" in r.stderr
    r = cli("zap", "decode", "FF FF FF 00 02 F1 0D")
    assert r.exit_code == 1 and r.stdout == "" and "expected 0C, found 0D" in r.stderr
    r = cli("zap", "decode", "FF FF FF 00 05 F1 0D")
    assert r.exit_code == 2 and r.stdout == "" and "SIZE 5" in r.stderr


def test_binary(cli, tmp_path):
    p = tmp_path / "bus.bin"
    p.write_bytes(bytes.fromhex(CAPTURE.replace(" ", "")) * 10)
    assert len(records(cli("zap", "decode", "--binary", str(p)).stdout)) == 60
