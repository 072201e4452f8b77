"""zk decode: frames from arguments, stdin hex, binary; formats; bad frames."""

import csv
import io
import json

import pytest

from zkzap.codec import zk

STREAM = "FF 1D F4 70 F1 00 00 00 00 4C A0 F6 00 00 A0 00 10 AB"


def records(text):
    return [json.loads(line) for line in text.splitlines()]


def test_single_control_frame(cli):
    r = cli("zk", "decode", "FF", "1D", "F4", "70")
    assert r.exit_code == 0
    assert records(r.stdout) == [{"kind": "control", "id": 1, "command": "control", "sw": 3, "state": "run",
                                  "throttle_pct": 50.0, "frame": "FF 1D F4 70"}]


def test_status_keys_exact(cli):
    """Every status ID gives exactly its documented keys."""
    expected = {
        1: ["rpm", "engine_state", "engine_state_name", "error_code", "error_name", "egt_c", "sw_state",
            "sw_state_name"],
        2: ["rpm", "radio_voltage_v", "power_voltage_v", "pump_voltage_v"],
        3: ["rpm", "throttle_pct", "pressure_pa"],
        4: ["rpm", "current_a", "thrust_kg"],
        5: ["rpm", "ignition_pump_voltage_v", "curve_inc", "curve_dec", "out_of_range"],   # curves 4, 5 < 10
        6: ["rpm", "max_rpm", "max_pump_voltage_v", "protocol_version", "status_rate_hz"],
        7: ["rpm", "fuel_flow_l_min", "fuel_used_l"],
        8: ["rpm", "idle_rpm", "esr", "scl", "startup_time_s"],
        9: ["rpm", "ecu_temp_c", "prop_rpm"],
        10: ["rpm", "fuel_pump_rpm"],
    }
    text = " ".join(zk.status_frame(i, [1, 2, 3, 4, 5]).hex() for i in range(1, 11))
    recs = records(cli("zk", "decode", text).stdout)
    assert [r["id"] for r in recs] == list(range(1, 11))
    for rec in recs:
        assert list(rec) == ["kind", "id"] + expected[rec["id"]] + ["frame"]


def test_worked_examples(cli):
    recs = records(cli("zk", "decode", STREAM).stdout)
    assert recs[1]["egt_c"] == 26 and recs[1]["engine_state_name"] == "stop"
    assert recs[2]["max_rpm"] == 160000 and recs[2]["protocol_version"] == 4 and recs[2]["status_rate_hz"] == 20


def test_stdin_hex_lines_and_dump(cli):
    r = cli("zk", "decode", input="FF 1D F4 70\nF1 00 00 00 00 4C A0\n")
    assert [x["id"] for x in records(r.stdout)] == [1, 1]
    dump = "00000000: ff1d f470 f100 0000 004c a0    ...p.....L.\n"
    assert len(records(cli("zk", "decode", input=dump).stdout)) == 2


def test_binary_file_and_stdin(cli, tmp_path):
    p = tmp_path / "cap.bin"
    p.write_bytes(bytes.fromhex(STREAM.replace(" ", "")) * 3)
    assert len(records(cli("zk", "decode", "--binary", str(p)).stdout)) == 9


def test_garbage_is_skipped_and_counted(cli):
    r = cli("zk", "decode", "00 12 " + STREAM + " F1 00 00 00 00 4C A1 99")
    assert r.exit_code == 0
    assert len(records(r.stdout)) == 3
    assert "3 frames decoded; 1 bad (CRC)" in r.stderr


def test_single_bad_frame_is_an_error(cli):
    r = cli("zk", "decode", "FF 1D F4 71")
    assert r.exit_code == 1 and r.stdout == "" and "CRC mismatch: expected 70, found 71" in r.stderr
    r = cli("zk", "decode", "FF 1D F4")
    assert r.exit_code == 2 and r.stdout == "" and "3 bytes" in r.stderr
    r = cli("zk", "decode", "FF 9D 00 " + format(0, "02X"))
    assert r.exit_code in (1, 2) and r.stdout == ""


def test_json_and_csv(cli):
    r = cli("zk", "decode", STREAM, "-f", "json")
    assert len(json.loads(r.stdout)) == 3
    assert json.loads(cli("zk", "decode", "--binary", "/dev/null", "-f", "json").stdout) == []
    r = cli("zk", "decode", STREAM, "-f", "csv")
    rows = list(csv.reader(io.StringIO(r.stdout)))
    header = rows[0]
    assert all(len(row) == len(header) for row in rows)
    assert header[:3] == ["kind", "id", "command"] and header[-1] == "frame"
    assert dict(zip(header, rows[2]))["egt_c"] == "26"
    status_only = next(csv.reader(io.StringIO(cli("zk", "decode", STREAM, "-f", "csv", "--accept", "status").stdout)))
    assert "command" not in status_only and "rpm" in status_only


def test_protocol_version_option_and_note(cli):
    v2 = zk.status_frame(2, [0, 0, 50, 120, 30]).hex()
    r = cli("zk", "decode", v2)
    assert records(r.stdout)[0]["power_voltage_v"] == 24.0 and "protocol version 4" in r.stderr
    r = cli("zk", "decode", v2, "--protocol-version", "3")
    assert records(r.stdout)[0]["power_voltage_v"] == 12.0 and r.stderr == ""
    v6 = zk.status_frame(6, [0, 0, 160, 0, 3 << 2]).hex()
    r = cli("zk", "decode", v6 + v2)
    assert records(r.stdout)[1]["power_voltage_v"] == 12.0


def test_raw_values(cli):
    rec = records(cli("zk", "decode", "F1 00 00 00 00 4C A0", "--raw").stdout)[0]
    assert rec["egt_c_raw"] == 76 and rec["egt_c"] == 26


def test_output_file_and_append(cli, tmp_path):
    out = tmp_path / "log.csv"
    cli("zk", "decode", STREAM, "-f", "csv", "-o", str(out))
    cli("zk", "decode", STREAM, "-f", "csv", "-o", str(out), "--append")
    lines = out.read_text().splitlines()
    assert len(lines) == 7 and lines.count(lines[0]) == 1


@pytest.mark.parametrize("args,code,needle", [
    (["zk", "decode", "XYZ"], 2, "is not hex"),
    (["zk", "decode", "--binary", "/nonexistent/file"], 2, "cannot read /nonexistent/file"),
    (["zk", "decode", "-f", "yaml", "FF"], 2, "'yaml' is not allowed; allowed"),
    (["zk", "decode", "--protocol-version", "0", "FF"], 2, "--protocol-version"),
])
def test_decode_bad_input(cli, args, code, needle):
    r = cli(*args)
    assert r.exit_code == code and r.stdout == "" and needle in r.stderr


def test_subprocess_pipe_defaults_to_jsonl(sh):
    r = sh("zkzap", "zk", "decode", input=STREAM + "\n")
    assert r.exit_code == 0 and len(records(r.stdout)) == 3


def test_subprocess_binary_stdin(sh):
    data = bytes.fromhex(STREAM.replace(" ", "")) * 100
    r = sh("zkzap", "zk", "decode", "--binary", "-f", "csv", input=data)
    assert r.exit_code == 0 and r.stdout.count(b"\n") == 301


def test_logic_analyser_export_on_stdin(cli):
    export = "Time [s],Value\n" + "".join(f"0.{i:06d},0x{b:02X}\n" for i, b in enumerate(bytes.fromhex(
        STREAM.replace(" ", ""))))
    r = cli("zk", "decode", input=export)
    assert r.exit_code == 0 and [x["id"] for x in records(r.stdout)] == [1, 1, 6]
