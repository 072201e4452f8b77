"""Register maps as data: the shipped maps load through the one loader; every fault of a map
file is an error naming FILE:LINE (exit 2)."""

import pytest

from zkzap.codec import regmap, zap
from zkzap.codec.regmap import MapError, parse_map
from zkzap.errors import exit_code

HEAD = "model: X1\nprotocol: {p}\n"


def test_shipped_maps_load_and_agree_with_the_codec():
    ir = regmap.builtin("12lf-ir")
    assert ir.registers is zap.REGISTERS and ir.protocol == "ir" and ir.model == "12Lf"
    assert zap.BAUD_CODES == {16: 115200, 32: 57600, 48: 38400, 64: 19200, 128: 9600}
    assert zap.IDENTITY_REGISTERS == ("id", "baud-rate", "protocol-type")
    gp = ir.by_name["goal-position"]
    assert (gp.address, gp.size, gp.access, gp.memory, gp.lo, gp.hi, gp.byteorder) == (0x86, 2, "RW", "V", 0, 4095,
                                                                                      "little")
    assert ir.by_name["present-voltage"].scale == 0.1 and ir.by_name["present-voltage"].unit == "V"
    mb = regmap.builtin("17lf-modbus")
    assert mb.protocol == "modbus" and all(r.size == 2 and r.byteorder == "big" for r in mb.registers)
    assert mb.by_name["goal-position"].address == 205 and mb.by_name["present-position"].address == 210
    assert mb.by_name["present-current"].address == 211 and mb.by_name["goal-current"].address == 209
    assert mb.baud_codes == {8: 115200, 16: 57600, 32: 38400, 64: 19200, 128: 9600}
    assert mb.identity == ("id", "baud-rate")
    assert mb.by_name["id"].describe_range() == "1..247"
    # the same words where the meaning is the same
    shared = {"goal-position", "present-position", "present-current", "speed-limit", "current-limit",
              "goal-speed", "goal-current", "force-on-off", "moving", "short-stroke-limit", "long-stroke-limit"}
    assert shared <= set(ir.by_name) & set(mb.by_name)


def test_a_user_map_round_trips(tmp_path):
    path = tmp_path / "mine.map"
    path.write_text(HEAD.format(p="modbus") + "# comment\n\n"
                    "0x86 | goal-position | 16 | V | RW | 0..4095 | | | | goal\n"
                    "0x96 | present-position | 16 | V | R | | | | | where it is\n"
                    "2 | id | 16 | NV | RW | 1..247 | | 1 | identity | its ID\n"
                    "3 | volts | 16 | V | R | | 0.1 V | | | supply | with a bar\n")
    m = regmap.load_map(str(path))
    assert m.register("goal_position").address == 0x86
    assert m.identity == ("id",)
    assert m.by_name["volts"].scale == 0.1 and m.by_name["volts"].help == "supply | with a bar"


@pytest.mark.parametrize("protocol,line,fault", [
    ("modbus", "5 | a | 8 | V | RW | | | | | x", "width 8 bits is not allowed on modbus"),
    ("ir", "5 | a | 12 | V | RW | | | | | x", "width 12 bits is not allowed on ir"),
    ("ir", "5 | a | 8 | EEPROM | RW | | | | | x", "unknown memory kind 'EEPROM'"),
    ("ir", "5 | a | 8 | V | RW | 0..300 | | | | x", "does not fit 8 bits"),
    ("modbus", "5 | a | 16 | V | RW | 0..70000 | | | | x", "does not fit 16 bits"),
    ("ir", "5 | a | 8 | V | RW | 9..3 | | | | x", "runs backwards"),
    ("ir", "5 | a | 8 | V | RW | 0..10 | | 11 | | x", "default 11 is outside"),
    ("ir", "5 | a | 8 | V | RW | 0=off; 300=on | | | | x", "choice 300 does not fit"),
    ("ir", "5 | a | 8 | V | RW | bits 9=x | | | | x", "bit 9 does not fit"),
    ("ir", "0x100 | a | 8 | V | RW | | | | | x", "outside the ir address space"),
    ("ir", "0xFF | a | 16 | V | RW | | | | | x", "run past the address space"),
    ("ir", "5 | a | 8 | V | W | | | | | x", "unknown access 'W'"),
    ("ir", "5 | a | 8 | - | RW | | | | | x", "needs its memory kind"),
    ("ir", "5 | a | 8 | V | RW | | | | admin | x", "unknown permission 'admin'"),
    ("ir", "five | a | 8 | V | RW | | | | | x", "address 'five' is not a number"),
    ("ir", "5 | a | 8 | V | RW", "5 cells"),
    ("ir", "5 | Big Name | 8 | V | RW | | | | | x", "kebab-case"),
])
def test_bad_register_lines_name_file_and_line(tmp_path, protocol, line, fault):
    path = tmp_path / "bad.map"
    path.write_text(HEAD.format(p=protocol) + "# registers\n" + line + "\n")
    with pytest.raises(MapError) as e:
        regmap.load_map(str(path))
    assert str(e.value).startswith(f"{path}:4: ") and fault in str(e.value)
    assert e.value.line == 4 and exit_code(e.value) == 2


@pytest.mark.parametrize("text,line,fault", [
    ("model: A\nprotocol: ir\n1 | a | 16 | V | RW | | | | | x\n2 | b | 8 | V | RW | | | | | y\n", 4, "overlaps a (line 3)"),
    ("model: A\nprotocol: modbus\n1 | a | 16 | V | RW | | | | | x\n1 | b | 16 | V | RW | | | | | y\n", 4, "overlaps a"),
    ("model: A\nprotocol: ir\n1 | a | 8 | V | RW | | | | | x\n2 | a | 8 | V | RW | | | | | y\n", 4, "name is taken"),
    ("model: A\nprotocol: can\n", 2, "unknown protocol 'can'"),
    ("protocol: ir\n1 | a | 8 | V | RW | | | | | x\n", 2, "before the 'model' header"),
    ("model: A\nprotocol: ir\n1 | a | 8 | V | RW | | | | | x\nmodel: B\n", 4, "after the first register"),
    ("hello\n", 1, "expected a header line"),
    ("", 1, "not a register map"),
    ("model: A\nprotocol: ir\n", 1, "no register lines"),
])
def test_bad_maps_name_file_and_line(text, line, fault):
    with pytest.raises(MapError) as e:
        parse_map(text, "m.map")
    assert str(e.value).startswith(f"m.map:{line}: ") and fault in str(e.value)


def test_unreadable_and_not_utf8(tmp_path):
    with pytest.raises(MapError, match="cannot read"):
        regmap.load_map(str(tmp_path / "none.map"))
    p = tmp_path / "latin.map"
    p.write_bytes(b"model: \xe9\n")
    with pytest.raises(MapError, match="not UTF-8"):
        regmap.load_map(str(p))


def test_the_manuals_example_map_loads():
    import pathlib
    import re

    page = pathlib.Path(__file__).parents[2] / "docs" / "how-to" / "modbus.md"
    block = re.search(r"```text\n(.*?)```", page.read_text(), re.S).group(1)
    m = parse_map(block, "modbus.md")
    assert m.protocol == "modbus" and m.by_name["present-voltage"].scale == 0.1
