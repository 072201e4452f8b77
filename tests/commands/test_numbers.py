"""Every numeric input must be a finite number in range, or exit 2 naming it.

The first table is built by walking the whole click application: every option and argument
that takes a float is tried with nan, inf and -inf, so an option added later without the
finite type fails here. The second covers the simulators' URL parameters and options, the
third the codec (file cells and library callers go through it).
"""

from __future__ import annotations

import click
import pytest

from zkzap.commands import root
from zkzap.commands.options import FiniteFloat, FiniteRange

from cmdtree import commands


def _float_params():
    rows = []
    for path, cmd in commands():
        path = list(path)
        positional = [p for p in cmd.params if isinstance(p, click.Argument)]
        for p in cmd.params:
            if not isinstance(p.type, (click.types.FloatParamType, click.FloatRange)):
                continue
            if isinstance(p, click.Option):
                rows.append((path, p, [p.opts[-1] if p.opts[-1].startswith("--") else p.opts[0]]))
            elif positional and positional[0] is p:
                rows.append((path, p, []))
    return rows


FLOATS = _float_params()


def test_the_walk_finds_the_float_options():
    names = {(" ".join(path), p.name) for path, p, _ in FLOATS}
    for expected in [("zk monitor", "timeout"), ("zk monitor", "duration"), ("zk send control", "for_s"),
                     ("zk send control", "throttle_pct"), ("zk send ignition-voltage", "ignition_voltage_v"),
                     ("zk profile", "rate"), ("sim zk", "speed"), ("sim zap", "voltage"),
                     ("zap move", "wait_timeout"), ("zap echo", "timeout")]:
        assert expected in names
    assert len(FLOATS) > 40


@pytest.mark.parametrize("path,param,flag", FLOATS, ids=[f"{' '.join(p)} {x.name}" for p, x, _ in FLOATS])
def test_every_float_param_is_finite_typed(path, param, flag):
    assert isinstance(param.type, (FiniteFloat, FiniteRange)), f"{' '.join(path)} {param.name}"


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "NaN", "1e999"])
@pytest.mark.parametrize("path,param,flag", FLOATS, ids=[f"{' '.join(p)} {x.name}" for p, x, _ in FLOATS])
def test_non_finite_is_refused_naming_the_option(cli, path, param, flag, value):
    # --opt=VALUE: also right for an option whose value is optional (--reconnect [S])
    args = [*path, f"{flag[0]}={value}"] if flag else [*path, value]
    if flag and param.nargs > 1:
        # an option of several values (--between A B): the non-finite one first, finite ones after
        args = [*path, flag[0], value, *["1"] * (param.nargs - 1)]
    r = cli(*args)
    assert r.exit_code == 2, r
    assert r.stdout == ""
    if getattr(param, "_flag_needs_value", False) and value.startswith("-"):
        return      # an optional value never starts with '-': click reads it as an option (still exit 2)
    label = flag[0] if flag else param.human_readable_name
    # 1e999 is finite as written, beyond a float's range: out of range, not infinite
    wording = "out of range" if value == "1e999" else "not a finite number"
    assert f"'{label}'" in r.stderr and wording in r.stderr, r


URL_PARAMS = [
    ("zk monitor --count 1 -p", "sim://zk?speed=nan", "speed: 'nan' is not a finite number"),
    ("zk monitor --count 1 -p", "sim://zk?speed=inf", "speed: 'inf' is not a finite number"),
    ("zk monitor --count 1 -p", "sim://zk?speed=0", "speed: 0 is out of range"),
    ("zk monitor --count 1 -p", "sim://zk?speed=-1", "speed: -1 is out of range"),
    ("zk monitor --count 1 -p", "sim://zk?battery=nan", "battery: 'nan' is not a finite number"),
    ("zk monitor --count 1 -p", "sim://zk?max_thrust=inf", "max_thrust: 'inf' is not a finite number"),
    ("zk monitor --count 1 -p", "sim://zk?ambient=-inf", "ambient: '-inf' is not a finite number"),
    ("zk monitor --count 1 -p", "sim://zk?silent_after=nan", "silent_after: 'nan' is not a finite number"),
    ("zk monitor --count 1 -p", "sim://zk?error=13&error_after=nan", "error_after: 'nan' is not a finite"),
    ("zk monitor --count 1 -p", "sim://zk?max_pump_voltage=1e400", "not a finite number"),
    ("zap echo -p", "sim://zap?speed=nan", "speed: 'nan' is not a finite number"),
    ("zap echo -p", "sim://zap?voltage=nan", "voltage: 'nan' is not a finite number"),
    ("zap echo -p", "sim://zap?voltage=99", "voltage: 99 is out of range"),
    ("zap echo -p", "sim://zap?faults=0:delay=nan", "delay: 'nan' is not a finite number"),
    ("zap echo -p", "sim://zap?faults=0:voltage=inf", "voltage: 'inf' is not a finite number"),
]


@pytest.mark.parametrize("args,url,needle", URL_PARAMS, ids=[u for _, u, _ in URL_PARAMS])
def test_simulator_url_parameters_must_be_finite(cli, args, url, needle):
    r = cli(*args.split(), url)
    assert r.exit_code == 2, r
    assert needle in r.stderr and r.stdout == ""


@pytest.mark.parametrize("extra,needle", [
    (["zk", "--set", "battery=nan"], "battery: 'nan' is not a finite number"),
    (["zk", "--set", "silent_after=inf"], "silent_after: 'inf' is not a finite number"),
    (["zap", "--fault", "1:delay=nan"], "delay: 'nan' is not a finite number"),
    (["zap", "--fault", "voltage=inf"], "voltage: 'inf' is not a finite number"),
])
def test_simulator_options_must_be_finite(cli, extra, needle):
    r = cli("sim", *extra)
    assert r.exit_code == 2, r
    assert needle in r.stderr


@pytest.mark.parametrize("value", [float("nan"), float("inf"), float("-inf"), "nan", "inf", "-1e999"])
@pytest.mark.parametrize("command,key", [("control", "throttle_pct"), ("ignition-voltage", "ignition_voltage_v"),
                                         ("accel-curve", "accel_curve"), ("pressure", "pressure_hpa")])
def test_codec_refuses_non_finite_field_values(command, key, value):
    from zkzap.codec import zk
    from zkzap.codec.fields import FieldValueError

    extra = {"sw": "run"} if command == "control" else {}
    with pytest.raises(FieldValueError, match="not a finite number|not a number|is not an integer"):
        zk.encode_control(command, **{key: value}, **extra)


def test_clock_and_number_parser():
    from zkzap.sim.base import Clock, parse_number

    for bad in (float("nan"), float("inf"), 0, -2):
        with pytest.raises(ValueError, match="speed"):
            Clock(bad)
    assert parse_number("x", "2.5", 0, 3) == 2.5
    with pytest.raises(ValueError, match="x: 4 is out of range; allowed 0..3"):
        parse_number("x", "4", 0, 3)


@pytest.mark.parametrize("text,ids", [("1 2", {1, 2}), ("1,2", {1, 2}), (" 1 , 6 ", {1, 6}), ("1 - 3", {1, 2, 3}),
                                      ("1-3 9", {1, 2, 3, 9}), ("12", {12})])
def test_ids_lists_split_on_spaces_and_commas(text, ids):
    from zkzap.api.telemetry import parse_ids

    assert parse_ids(text) == ids


# --- numbers read consistently, counted honestly ------------------------------------------

@pytest.mark.parametrize("code,frame", [("242", "FF FF FF 00 02 F2 0B"), ("0xF2", "FF FF FF 00 02 F2 0B"),
                                        ("F2", "FF FF FF 00 02 F2 0B"), ("f2", "FF FF FF 00 02 F2 0B"),
                                        ("10", "FF FF FF 00 02 0A F3"), ("0x0A", "FF FF FF 00 02 0A F3"),
                                        ("echo", "FF FF FF 00 02 F1 0C")])
def test_instruction_codes_read_decimal_and_hex_as_register_addresses_do(cli, code, frame):
    r = cli("zap", "raw", code, "--id", "0", "-n")
    assert r.exit_code == 0 and r.stdout.strip() == frame, r


@pytest.mark.parametrize("code", ["256", "0x100", "999"])
def test_instruction_codes_out_of_range(cli, code):
    r = cli("zap", "raw", code, "--id", "0", "-n")
    assert r.exit_code == 2 and f"code {code} is out of range" in r.stderr


@pytest.mark.parametrize("args,expected", [
    ("present-position --length 1", ["present-position(partial)=0"]),
    ("goal-position --length 3", ["goal-position=0", "goal-speed(partial)=255"]),
])
def test_a_value_cut_by_length_is_labelled_never_bare(cli, args, expected):
    r = cli("zap", "load", *args.split(), "--sim")
    assert r.exit_code == 0, r
    assert r.stdout.split() == expected
    assert "is not the register's value" in r.stderr
    r = cli("zap", "load", *args.split(), "--sim", "-f", "jsonl")
    import json

    recs = [json.loads(x) for x in r.stdout.splitlines()]
    assert recs[-1]["partial"] is True
    assert all("partial" not in rec for rec in recs[:-1])


def test_a_whole_value_stays_bare(cli):
    r = cli("zap", "load", "present-position", "--sim")
    assert r.stdout == "0\n" and "partial" not in r.stderr


CONTROL, STATUS = "FF 1D F4 70", "F1 00 00 00 00 4C A0"


@pytest.mark.parametrize("args,needle", [
    (["--accept", "status", CONTROL, STATUS, CONTROL, STATUS], "2 frames decoded; 2 control frames left out "
                                                               "(--accept status), 0 bad (CRC); 8 bytes skipped"),
    (["--accept", "control", CONTROL, STATUS, CONTROL], "2 frames decoded; 1 status frame left out "
                                                        "(--accept control), 0 bad (CRC); 7 bytes skipped"),
    ([CONTROL, STATUS, "F1 00 00"], "2 frames decoded; 0 bad (CRC), 1 cut short by the end of the input; "
                                    "3 bytes skipped"),
    ([CONTROL, "F1 00 00 00 00 4C A1", CONTROL], "2 frames decoded; 1 bad (CRC); 7 bytes skipped"),
])
def test_decode_counts_left_out_and_cut_frames_apart_from_crc_errors(cli, args, needle):
    r = cli("zk", "decode", *" ".join(args).split())
    assert r.exit_code == 0, r
    assert needle in r.stderr, r


def test_zap_decode_counts_a_cut_tail_apart(cli):
    r = cli("zap", "decode", *"FF FF FF 00 02 F1 0C FF FF FF 00 02".split())
    assert "1 cut short by the end of the input" in r.stderr and "0 bad (checksum)" in r.stderr


@pytest.fixture(scope="module")
def raw_log(tmp_path_factory):
    """A raw log of 80 status frames: 4 s at the simulator's 20 Hz."""
    from click.testing import CliRunner

    from zkzap.commands import run

    log = tmp_path_factory.mktemp("replay") / "run.bin"
    with CliRunner().isolation():
        assert run(root, "zkzap", ["zk", "monitor", "-p", "sim://zk?speed=20", "--count", "80", "--protocol-version",
                                   "6", "--raw-log", str(log), "-f", "jsonl"]) == 0
    return log


@pytest.mark.parametrize("duration", ["0.5", "1", "2.5"])
def test_a_fast_replay_stops_at_its_duration_and_invents_no_wall_clock(cli, raw_log, duration):
    import json

    r = cli("zk", "monitor", "--replay", str(raw_log), "--fast", "--duration", duration, "-f", "jsonl")
    assert r.exit_code == 0, r
    recs = [json.loads(x) for x in r.stdout.splitlines()]
    assert recs and max(rec["t"] for rec in recs) < float(duration)
    assert len(recs) == round(float(duration) * 20)        # 20 Hz status rate
    assert all(rec["time"] is None for rec in recs)        # a raw log holds no times


@pytest.mark.parametrize("ids,version,code,needle", [
    ("11", 6, 3, "the ECU never sends status ID 11 (its cycle is IDs 1-10)"),
    ("11-14", 6, 3, "never sends status IDs 11-14"),
    ("9,10", 4, 3, "never sends status IDs 9-10 (its cycle is IDs 1-8)"),
    ("1,9", 4, 0, "never sends status ID 9 (its cycle is IDs 1-8)"),
])
def test_ids_the_ecu_never_sends_end_or_warn_instead_of_waiting(cli, ids, version, code, needle):
    r = cli("zk", "monitor", "-p", f"sim://zk?speed=20&protocol_version={version}", "--ids", ids,
            "--count", "40", "-f", "jsonl")
    assert r.exit_code == code, r
    assert needle in r.stderr
