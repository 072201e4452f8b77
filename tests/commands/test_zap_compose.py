"""zap instructions with -n: packets composed from register names and values."""

import pytest

CASES = [
    (["echo"], "FF FF FF 00 02 F1 0C"),
    (["load", "present-position"], "FF FF FF 00 04 F2 8C 02 7B"),
    (["load", "0x92"], "FF FF FF 00 04 F2 92 01 76"),
    (["load", "present-position", "--length", "4", "--id", "2"], "FF FF FF 02 04 F2 8C 04 77"),
    (["store", "goal-position", "2047", "--id", "1"], "FF FF FF 01 05 F3 86 FF 07 7A"),
    (["store", "goal-speed", "512", "-i", "1"], "FF FF FF 01 05 F3 88 00 02 7C"),
    (["store", "id", "1", "--id", "0"], "FF FF FF 00 04 F3 03 01 04"),
    (["store", "134", "0x7FF", "--id", "1"], "FF FF FF 01 05 F3 86 FF 07 7A"),
    (["send", "goal-position", "2047", "--id", "1"], "FF FF FF 01 05 F4 86 FF 07 79"),
    (["execute", "--id", "1"], "FF FF FF 01 02 F5 07"),
    (["execute", "--id", "broadcast"], "FF FF FF FE 02 F5 0A"),
    (["factory-reset", "--id", "1", "--reset-id"], "FF FF FF 01 03 F6 01 04"),
    (["restart", "--id", "0"], "FF FF FF 00 02 F8 05"),
    (["sync-move", "1:1023", "2:2047"], "FF FF FF FE 0A 73 86 02 01 FF 03 02 FF 07 F1"),
    (["raw", "load", "8C", "02", "--id", "0"], "FF FF FF 00 04 F2 8C 02 7B"),
    (["raw", "0xF3", "03 01", "--id", "0"], "FF FF FF 00 04 F3 03 01 04"),
    (["echo", "--id", "broadcast"], "FF FF FF FE 02 F1 0E"),
]


@pytest.mark.parametrize("args,expected", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_dry_run(cli, args, expected):
    r = cli("zap", *args, "-n")
    assert r.exit_code == 0, r
    assert r.stdout == expected + "\n"


def test_sync_move_splits_packets(cli):
    targets = [f"{i}:{i}" for i in range(100)]
    r = cli("zap", "sync-move", *targets, "-n")
    lines = r.stdout.splitlines()
    assert r.exit_code == 0 and len(lines) == 2
    assert all(line.startswith("FF FF FF FE") for line in lines)


@pytest.mark.parametrize("args,needle", [
    (["store", "present-position", "1", "--id", "1"], "present-position: read-only register"),
    (["store", "goal-position", "4096", "--id", "1"], "goal-position: 4096 is out of range; allowed 0..4095"),
    (["store", "goal-position", "abc"], "value: 'abc' is not an integer"),
    (["store", "no-such-register", "1"], "register: unknown name 'no-such-register'"),
    (["load", "goal-position", "--length", "0"], "--length"),
    (["echo", "--id", "255"], "id: 255 is out of range; allowed 0..253, 254 or broadcast"),
    (["echo", "--id", "one"], "id: 'one' is not a number"),
    (["sync-move", "1-1023"], "'1-1023' is not ID:VALUE"),
    (["sync-move", "254:5"], "id: 254 is out of range; allowed 0..253"),
    (["sync-move", "1:5000"], "goal-position: 5000 is out of range"),
    (["raw", "jump"], "instruction: unknown 'jump'"),
    (["raw", "load", "8", "--id", "1"], "odd number of hex digits"),
    (["echo"], "no port"),
])
def test_bad_input_exit_2_nothing_on_stdout(cli, args, needle):
    r = cli("zap", *args, *(["-n"] if args != ["echo"] else []))
    assert r.exit_code == 2, r
    assert r.stdout == ""
    assert needle in r.stderr


def test_store_protocol_type_zero_needs_force_when_sent(cli):
    r = cli("zap", "store", "protocol-type", "0", "--id", "0", "-n")          # composed: nothing is sent
    assert r.exit_code == 0 and r.stdout.startswith("FF FF FF 00 04 F3 0A 00")
    r = cli("zap", "store", "protocol-type", "0", "--id", "1", "--sim")
    assert r.exit_code == 2 and r.stdout == "" and "Modbus RTU" in r.stderr and "pass --force" in r.stderr
    r = cli("zap", "store", "protocol-type", "0", "--id", "1", "--sim", "--force")
    assert r.exit_code == 0


def test_zap_entry_point_subprocess(sh):
    r = sh("zap", "sync-move", "1:1023", "2:2047", "-n")
    assert (r.exit_code, r.stdout) == (0, "FF FF FF FE 0A 73 86 02 01 FF 03 02 FF 07 F1\n")
