"""zk send -n: every control command composed from named, physical values."""

import pytest

CASES = [
    (["keepalive"], "FF 00 00 00"),
    (["control", "--state", "run", "--throttle", "50"], "FF 1D F4 70"),
    (["control", "--state", "stop", "--throttle", "10"], "FF 14 64 D3"),
    (["control", "--state", "pwm"], "FF 10 00 EC"),
    (["action", "drain-oil"], None),
    (["action", "pump-off"], None),
    (["unlock"], None),
    (["ignition-voltage", "5.1"], None),
    (["accel-curve", "40"], None),
    (["mode", "--state", "run", "--rpm-factor", "3"], None),
    (["rpm", "99990", "--rpm-factor", "3"], None),
    (["pressure", "1013"], None),
    (["raw", "1", "sw=3", "throttle_pct=500"], "FF 1D F4 70"),
    (["raw", "1", "state=run", "throttle_pct=0x1F4"], "FF 1D F4 70"),
]


@pytest.mark.parametrize("args,expected", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_dry_run(cli, args, expected):
    from zkzap.codec import zk
    from zkzap.codec.hexfmt import parse_hex

    r = cli("zk", "send", *args, "-n")
    assert r.exit_code == 0, r
    assert r.stderr == ""
    frame = parse_hex(r.stdout)
    zk.check_control(frame)
    if expected:
        assert r.stdout == expected + "\n"
    if args[0] not in ("raw", "keepalive"):
        assert zk.decode_control(frame)["command"] == args[0]


def test_every_action_name_in_order(cli):
    from zkzap.codec import zk

    for param, name in zk.ACTIONS.items():
        r = cli("zk", "send", "action", name, "-n")
        frame = bytes.fromhex(r.stdout)
        assert frame[1] == 0x20 and frame[2] == param


def test_rpm_is_target_speed(cli):
    r = cli("zk", "send", "rpm", "100000", "--rpm-factor", "3", "-n")
    assert r.exit_code == 0
    frame = bytes.fromhex(r.stdout)
    assert ((frame[1] & 0x0F) << 8 | frame[2]) == 3333
    assert "rounded to 99990 rpm" in r.stderr


def test_off_grid_note_on_stderr_only(cli):
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "50.04", "-n")
    assert r.stdout == "FF 1D F4 70\n"
    assert r.stderr.startswith("note: throttle: 50.04 % is not a multiple of 0.1 %")


def test_version_warning(cli):
    r = cli("zk", "send", "action", "pump-on", "--protocol-version", "3", "-n")
    assert r.exit_code == 0 and "needs protocol version 5" in r.stderr


@pytest.mark.parametrize("args,needle", [
    (["control", "--state", "run", "--throttle", "100.5", "-n"], "throttle: 100.5 is out of range; allowed 0..100 %"),
    (["control", "--state", "fly", "-n"], "'fly' is not allowed; allowed"),
    (["action", "launch", "-n"], "'launch' is not allowed; allowed"),
    (["ignition-voltage", "6", "-n"], "ignition-voltage: 6 is out of range; allowed 0..5.1 V"),
    (["accel-curve", "9", "-n"], "accel-curve: 9 is out of range; allowed 10..70"),
    (["mode", "--rpm-factor", "7", "-n"], "rpm-factor: 7 is out of range"),
    (["rpm", "50000", "--rpm-factor", "1", "-n"], "rpm: 50000 is out of range; allowed 0..40950 rpm"),
    (["rpm", "500", "-n"], "--rpm-factor"),
    (["pressure", "1024", "-n"], "pressure: 1024 is out of range; allowed 0..1023 hPa"),
    (["raw", "9", "-n"], "9 is out of range; allowed 0..8"),
    (["raw", "1", "speed=3", "-n"], "speed: not a field of command 1"),
    (["raw", "1", "throttle_pct=1001", "-n"], "throttle_pct: raw value 1001 is out of range 0..1000"),
    (["raw", "1", "sw", "-n"], "'sw' is not FIELD=VALUE"),
    (["control", "--state", "run"], "no port"),
])
def test_bad_input_exit_2_nothing_on_stdout(cli, args, needle):
    r = cli("zk", "send", *args)
    assert r.exit_code == 2, r
    assert r.stdout == ""
    assert needle in r.stderr


def test_zk_entry_point_subprocess(sh):
    r = sh("zk", "send", "control", "--state", "run", "--throttle", "50", "-n")
    assert (r.exit_code, r.stdout, r.stderr) == (0, "FF 1D F4 70\n", "")
    r = sh("zk", "send", "pressure", "2000", "-n")
    assert r.exit_code == 2 and r.stdout == "" and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
