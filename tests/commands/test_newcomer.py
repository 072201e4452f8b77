"""What a newcomer trips over, answered: each message names what is wrong and what to do, and
each example of the manual does what it says."""

from __future__ import annotations

import json

import click
import pytest

from zkzap.sim.zap_actuators import from_options


def _bus_file(path, ids):
    bus = from_options(ids=ids, state=str(path))
    bus.save()
    return f"sim://zap?state={path}"


def test_apply_map_on_a_bigger_file_names_its_ids_and_the_fix(cli, tmp_path):
    url = _bus_file(tmp_path / "six.json", "1,2,3,4,5,6")
    assert cli("zap", "backup", "-p", url, "-o", str(tmp_path / "old.json")).exit_code == 0
    r = cli("zap", "apply", str(tmp_path / "old.json"), "--id-map", "1:5,2:6", "-p", url, "--plan")
    assert r.exit_code == 2 and r.stdout == ""
    assert ("--id-map: bus ID 5 would get the settings of two actuators of the file: ID 1 (--id-map 1:5) and ID 5 "
            "(kept as it is)") in r.stderr
    assert "every ID of the file (1-6) is applied: add --ids 1,2 to apply only the mapped ones" in r.stderr
    ok = cli("zap", "apply", str(tmp_path / "old.json"), "--ids", "1,2", "--id-map", "1:5,2:6", "-p", url, "--plan")
    assert ok.exit_code == 0, ok


def test_the_plan_counts_writes_and_stored_ones_apart_from_the_equal_settings(cli, tmp_path):
    url = _bus_file(tmp_path / "bus.json", "1,2")
    assert cli("zap", "store", "speed-limit", "600", "--id", "1", "-p", url).exit_code == 0
    assert cli("zap", "backup", "-p", url, "-o", str(tmp_path / "fleet.json")).exit_code == 0
    r = cli("zap", "apply", str(tmp_path / "fleet.json"), "--ids", "1", "--to", "2", "-p", url, "--plan")
    assert r.exit_code == 0, r
    assert ("plan: 1 write on 1 actuator (to a stored setting, which survives power-off); "
            "17 settings already equal; ") in r.stderr and r.stderr.rstrip().endswith("nothing written")


@pytest.mark.parametrize("prog", ["zk", "zap"])
def test_a_file_named_as_input_is_read_as_hex_text(cli, tmp_path, prog):
    dump = tmp_path / "cap.hex"
    frame = "FF 1D F4 70" if prog == "zk" else "FF FF FF 00 02 F1 0C"
    dump.write_text(f"00000000: {frame}\n")
    r = cli(prog, "decode", str(dump))
    assert r.exit_code == 0 and json.loads(r.stdout)["frame"] == frame, r
    raw = tmp_path / "cap.bin"
    raw.write_bytes(bytes.fromhex(frame) * 3 + b"\x00\x01\x02")
    r = cli(prog, "decode", str(raw))
    assert r.exit_code == 2 and r.stdout == ""
    assert f"{raw}: raw bytes, not hex text: give --binary to decode them (--binary {raw})" in r.stderr
    assert cli(prog, "decode", "--binary", str(raw)).exit_code == 0
    missing = cli(prog, "decode", str(tmp_path / "nothere.bin"))
    assert missing.exit_code == 2 and "does not exist" in missing.stderr


def test_load_reads_several_registers(cli):
    r = cli("zap", "load", "present-position", "present-voltage", "moving", "--id", "1", "--sim", "--physical")
    assert r.exit_code == 0 and r.stdout.splitlines() == ["present-position=0", "present-voltage=12.0", "moving=0"]
    dry = cli("zap", "load", "present-position", "moving", "-n")
    assert dry.stdout.splitlines() == ["FF FF FF 00 04 F2 8C 02 7B", "FF FF FF 00 04 F2 96 01 72"]
    both = cli("zap", "load", "present-position", "moving", "--length", "3", "-n")
    assert both.exit_code == 2 and "--length: reads from one REGISTER; 2 are given" in both.stderr


def test_consent_help_speaks_of_what_the_command_does():
    from cmdtree import commands

    checked = 0
    for path, cmd in commands(hidden=False):
        yes = next((p for p in cmd.params if p.name == "yes" and isinstance(p, click.Option)), None)
        if yes is None:
            continue
        engine = any(w in yes.help for w in ("engine", "igniter", "fuel"))
        assert engine == (path[0] == "zk"), (path, yes.help)
        checked += 1
    assert checked >= 10


@pytest.mark.parametrize("args,needle", [
    (("zap", "watch", "present-position", "--ids", "-1", "--sim"), "--ids: -1 is out of range; allowed 0..253"),
    (("zap", "watch", "present-position", "--ids", "3-", "--sim"), "--ids: '3-': a range needs both ends"),
    (("zap", "watch", "present-position", "--until", "moving", "--sim"), "(for example moving==0)"),
    (("zk", "monitor", "--sim", "--limit", "engine_state_name==1"),
     "unknown field 'engine_state_name'; did you mean engine_state?"),
])
def test_messages(cli, args, needle):
    r = cli(*args)
    assert r.exit_code == 2 and r.stdout == "" and needle in r.stderr, r
    assert "egt_c" not in r.stderr or args[0] == "zk"


def test_the_limits_fields_are_numbers():
    from zkzap.api.limits import FIELDS

    assert "egt_c" in FIELDS and "engine_state" in FIELDS
    assert not {"engine_state_name", "error_name", "sw_state_name", "out_of_range", "frame"} & FIELDS
