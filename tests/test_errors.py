"""One error hierarchy and one "did you mean": every error the library raises for bad input
or a device is a ZkzapError (a ValueError too where it is about a value); a misspelt name gets
the closest names, in files, on the command line (over the whole command tree) and in the API."""

from __future__ import annotations

import ast
import os

import click
import pytest

from zkzap import (Bus, ChecksumError, CrcError, Ecu, FieldValueError, FrameError, HexError, InvalidValue,
                   PacketError, UsageError, ZkzapError)
from zkzap.codec import parse_hex, zap, zk
from zkzap.errors import CHECK_FAILED, USAGE, CheckFailed, close_names, did_you_mean, unknown_name
from zkzap.sim import start_zap, start_zk

CLI = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cli", "zkzap")
REGISTERS = [r.name for r in zap.REGISTERS]


@pytest.mark.parametrize("word,choices,expected", [
    ("goal-sped", REGISTERS, ["goal-speed"]),                           # a typo: the one nearest
    ("speed-limt", REGISTERS, ["speed-limit"]),
    ("GOAL_POSITION", REGISTERS, ["goal-position"]),                    # case, _ and - do not count
    ("goal", REGISTERS, ["goal-position", "goal-speed", "goal-current"]),    # a fragment: in table order
    ("voltage", REGISTERS, ["lowest-limit-voltage", "highest-limit-voltage", "present-voltage"]),
    ("stnadby", ["pwm", "stop", "standby", "run"], ["standby"]),
    ("xyzzy", REGISTERS, []),                                             # nothing close: nothing
    ("", REGISTERS, []),
    ("egt", ["rpm", "egt_c", "sw_state"], ["egt_c"]),
    ("goal-speedd" * 20000, REGISTERS, []),          # a key of a damaged file: too long to be close
    ("goal-speedd", ["goal-speed"], ["goal-speed"]),
])
def test_close_names(word, choices, expected):
    assert close_names(word, choices) == expected


def test_did_you_mean_wording():
    assert did_you_mean("goal-sped", REGISTERS) == "; did you mean goal-speed?"
    assert did_you_mean("goal", REGISTERS) == "; did you mean goal-position, goal-speed or goal-current?"
    assert did_you_mean("xyzzy", REGISTERS, otherwise="; see the table") == "; see the table"
    e = unknown_name("state", "rn", ["pwm", "stop", "standby", "run"])
    assert isinstance(e, InvalidValue) and isinstance(e, ValueError) and e.code == USAGE
    assert str(e) == "state: unknown name 'rn'; did you mean run?" and e.suggestions == ["run"]
    assert str(unknown_name("kind", "x", ["zk", "zap"])) == "kind: unknown name 'x'; allowed zk, zap"


@pytest.mark.parametrize("call,cls,code", [
    (lambda: zap.register("goal-sped"), FieldValueError, USAGE),
    (lambda: parse_hex("zz"), HexError, USAGE),
    (lambda: zk.check_frame(b"\xff\x14"), FrameError, USAGE),
    (lambda: zk.check_frame(b"\xff\x14\x64\xd4"), CrcError, CHECK_FAILED),
    (lambda: zap.check_packet(b"\xff\xff\xff\x00\x05\xf1\x0d"), PacketError, USAGE),
    (lambda: zap.check_packet(b"\xff\xff\xff\x00\x02\xf1\x0d"), ChecksumError, CHECK_FAILED),
    (lambda: start_zap(ids=[300]), FieldValueError, USAGE),
    (lambda: start_zap(faults=["1:explode"]), InvalidValue, USAGE),
    (lambda: start_zk(rate=30), InvalidValue, USAGE),
    (lambda: Bus("sim://zap", baud="57600"), InvalidValue, USAGE),
    (lambda: Ecu("sim://zk", baud=9600.0), InvalidValue, USAGE),
])
def test_bad_input_is_a_zkzap_error_and_a_value_error(call, cls, code):
    with pytest.raises(cls) as info:
        call()
    e = info.value
    assert isinstance(e, ZkzapError) and isinstance(e, ValueError) and e.code == code
    assert isinstance(e, CheckFailed) == (code == CHECK_FAILED)
    assert isinstance(e, UsageError) == (cls in (FieldValueError, HexError, InvalidValue))


def test_crc_mismatches_carry_both_bytes():
    with pytest.raises(CrcError) as info:
        zk.check_frame(b"\xff\x14\x64\xd4")
    assert (info.value.expected, info.value.found) == (0xD3, 0xD4)


#: Builtin exceptions the library may raise: attribute protocol, signals, abstract methods.
ALLOWED_BUILTINS = {"AttributeError", "NotImplementedError", "KeyboardInterrupt", "BrokenPipeError",
                    "StopIteration"}
#: The in-process simulator is a pyserial URL handler: it raises pyserial's own exceptions,
#: which zkzap.link.port turns into PortError like any port's.
PYSERIAL_HANDLERS = {os.path.join("link", "protocol_sim.py")}
LIBRARY = ("api", "codec", "link", "sim", "io")


def _caught_here(tree) -> set:
    """The raise statements inside a ``try`` whose own handlers catch them (a local jump)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Try):
            caught = {n.id for h in node.handlers if h.type is not None
                      for n in ast.walk(h.type) if isinstance(n, ast.Name)}
            for stmt in node.body:
                for sub in ast.walk(stmt):
                    if isinstance(sub, ast.Raise) and isinstance(sub.exc, ast.Name) and sub.exc.id in caught:
                        out.add(id(sub))
    return out


def _raised_builtins():
    import builtins

    for package in LIBRARY:
        for dirpath, _, files in os.walk(os.path.join(CLI, package)):
            for name in files:
                path = os.path.join(dirpath, name)
                if not name.endswith(".py") or os.path.relpath(path, CLI) in PYSERIAL_HANDLERS:
                    continue
                tree = ast.parse(open(path, encoding="utf-8").read())
                local = _caught_here(tree)
                for node in ast.walk(tree):
                    if isinstance(node, ast.Raise) and node.exc is not None and id(node) not in local:
                        target = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
                        if isinstance(target, ast.Name) and isinstance(getattr(builtins, target.id, None), type):
                            if target.id not in ALLOWED_BUILTINS:
                                yield f"{os.path.relpath(path, CLI)}:{node.lineno}: raise {target.id}"


def test_the_library_raises_no_bare_builtin_error():
    assert list(_raised_builtins()) == []


# --- the API: registers, fields, kinds, keyword arguments ----------------------------------------

def test_api_names_the_closest_register_and_field():
    with start_zap(ids=[1]) as sim, Bus(sim.url) as bus:
        with pytest.raises(AttributeError, match="no register 'goal_sped'; did you mean goal_speed"):
            bus[1].goal_sped  # noqa: B018
        with pytest.raises(FieldValueError, match="register: unknown name 'goal-sped'; did you mean goal-speed"):
            bus.load(1, "goal-sped")
    with start_zk(speed=50) as sim, Ecu(sim.url) as ecu:
        rec = next(ecu.status())
        with pytest.raises(AttributeError, match="did you mean rpm"):
            rec.rmp  # noqa: B018
        with pytest.raises(FieldValueError, match="command: unknown kind 'contrl'; did you mean control"):
            ecu.frame("contrl")
        with pytest.raises(FieldValueError, match="state: unknown name 'rn'; did you mean run"):
            ecu.frame("control", state="rn")
        with pytest.raises(FieldValueError, match="throtle_pct: not a field of control; did you mean throttle_pct"):
            ecu.frame("control", state="run", throtle_pct=10)


def test_simulator_options_name_the_closest():
    with pytest.raises(InvalidValue, match="zk simulator: unknown option 'protocol_versoin'; did you mean "
                                           "protocol_version"):
        from zkzap.sim.zk_ecu import from_options

        from_options(protocol_versoin="4")
    with pytest.raises(InvalidValue, match="sim://zap: zap simulator: unknown option 'idz'; did you mean ids"):
        Bus("sim://zap?idz=1")


def test_a_misspelt_marker_option_names_the_closest(pytester):
    pytester.makepyfile("""
        import pytest

        @pytest.mark.zap_sim(idz=[1, 2])
        def test_it(zap_sim):
            pass
    """)
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider")
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines(["*@pytest.mark.zap_sim: unknown option 'idz'; did you mean ids?*"])


# --- the command line: every choice, every number, every command name ----------------------------

def _params():
    from cmdtree import commands

    for path, cmd in commands():
        for p in cmd.params:
            yield path, p


def test_every_choice_and_number_of_the_command_tree_speaks_zkzap():
    from zkzap.commands import options

    ours = (options.Choice, options.IntRange, options.FiniteRange, options.FiniteFloat, options.Integer)
    clicks = (click.Choice, click.types.IntParamType, click.types.FloatParamType)
    foreign = sorted({f"{' '.join(path)} {p.name}" for path, p in _params()
                      if isinstance(p.type, clicks) and not isinstance(p.type, ours)})
    assert foreign == []


def test_every_choice_names_the_closest(cli):
    from zkzap.commands import options

    checked = 0
    for path, p in _params():
        if not isinstance(p.type, options.Choice) or not isinstance(p, click.Option) or not p.opts[-1].startswith("--"):
            continue
        choice = str(p.type.choices[-1])
        if len(choice) < 3:
            continue
        typo = choice[:-1] + ("x" if choice[-1] != "x" else "y")
        message = p.type.convert.__func__             # the type's own conversion, as click calls it
        with pytest.raises(click.BadParameter) as info:
            message(p.type, typo, p, None)
        text = info.value.format_message()
        assert f"'{typo}' is not allowed; allowed " in text, (path, text)
        assert choice in text.partition("; did you mean ")[2], (path, text)
        checked += 1
    assert checked >= 20
    r = cli("zk", "send", "control", "--state", "rn", "-n")
    assert r.exit_code == 2 and r.stdout == ""
    assert "'rn' is not allowed; allowed pwm, stop, standby, run; did you mean run?" in r.stderr


@pytest.mark.parametrize("args,needle", [
    (("zk", "sned"), "No such command 'sned'; did you mean send?"),
    (("zpa", "load"), "No such command 'zpa'; did you mean zap?"),
    (("zap", "lod", "x"), "No such command 'lod'; did you mean load?"),
    (("zap", "xyzzy"), "No such command 'xyzzy' (see 'zkzap zap --help')"),
    (("zap", "load", "goal-sped", "-n"), "register: unknown name 'goal-sped'; did you mean goal-speed?"),
    (("zap", "load", "xyzzy", "-n"), "register: unknown name 'xyzzy'; 'zap registers' lists them"),
    (("zk", "monitor", "--sim", "--limit", "egt<=3"), "unknown field 'egt'; did you mean egt_c?"),
    (("zk", "monitor", "--sim", "--rate", "abc"), "'abc' is not a number; allowed 1..200"),
    (("zk", "monitor", "--sim", "--rate", "500"), "500 is out of range; allowed 1..200"),
    (("zk", "monitor", "--sim", "--protocol-version", "x"), "'x' is not an integer; allowed 1..63"),
    (("zap", "watch", "present-position", "--sim", "--count", "0"), "0 is out of range; allowed 1 or more"),
    (("zk", "monitor", "--sim", "--duration", "0"), "0 is out of range; allowed more than 0"),
])
def test_command_line_messages(cli, args, needle):
    r = cli(*args)
    assert r.exit_code == 2 and r.stdout == "" and needle in r.stderr, r
    assert "valid float" not in r.stderr and "valid integer" not in r.stderr and "<=x<=" not in r.stderr
