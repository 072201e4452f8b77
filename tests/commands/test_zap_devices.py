"""The whole zap command set, with default timing, against devices that are slow (20 ms
turnaround), trickle their reply bytes (1 ms apart) and sit behind an echoing adapter, in every
feedback-return mode."""

import json

import pytest

from zkzap.link.port import sim_url

DEVICES = {
    "slow": {"turnaround": "20"},
    "trickling": {"turnaround": "20", "gap": "1"},
    "echoing": {"turnaround": "20", "gap": "1", "echo": "1"},
}

#: (name, arguments); every one must succeed (exit 0)
COMMANDS = [
    ("echo", ["echo", "--id", "1"]),
    ("echo-count", ["echo", "--id", "1", "--count", "3"]),
    ("load", ["load", "present-voltage", "--id", "1"]),
    ("load-block", ["load", "model-number", "--length", "17", "--id", "2", "-f", "json"]),
    ("store", ["store", "goal-position", "2000", "--id", "1"]),
    ("store-nv", ["store", "long-stroke-limit", "3000", "--id", "1"]),
    ("send", ["send", "goal-position", "1000", "--id", "1"]),
    ("execute", ["execute", "--id", "1"]),
    ("sync-move", ["sync-move", "1:100", "2:200"]),
    ("move", ["move", "100", "--id", "1"]),
    ("move-wait", ["move", "100", "--id", "1", "--speed", "1023", "--wait"]),
    ("dump", ["dump", "--id", "1", "-f", "jsonl"]),
    ("scan", ["scan", "--ids", "0-3", "-f", "jsonl"]),          # an absent ID either side
    ("set-id", ["set-id", "5", "--id", "2"]),
    ("set-baud", ["set-baud", "115200", "--id", "1"]),
    ("restart", ["restart", "--id", "1"]),
    ("factory-reset", ["factory-reset", "--id", "1"]),
    ("raw", ["raw", "load", "8C", "02", "--id", "1"]),
]
#: commands that need Load Data, never answered in return mode 0
NEEDS_LOAD = {"load", "load-block", "move-wait", "dump", "set-id", "set-baud", "raw"}
#: commands whose census listens out a 1.5 s horizon: on the slow device in real time, on the
#: others on the simulator's virtual clock (the same model timing, in no time)
CENSUS = {"set-id", "set-baud"}


def _cases():
    for dev in DEVICES:
        for mode in ("0", "1", "2"):
            for name, args in COMMANDS:
                if mode == "0" and name in NEEDS_LOAD:
                    continue
                yield pytest.param(dev, mode, args, id=f"{dev}-mode{mode}-{name}")


@pytest.mark.parametrize("device,mode,args", list(_cases()))
def test_every_command_works_with_default_timing(cli, device, mode, args):
    clock = {"clock": "virtual"} if args[0] in CENSUS and device != "slow" else {}
    url = sim_url("zap", ids="1,2", return_mode=mode, **DEVICES[device], **clock)
    # the user tells zap the mode only where the default (1) cannot work: mode 0 answers no Load
    extra = ["--return-mode", "0"] if mode == "0" else []
    r = cli("zap", *args, "-p", url, *extra)
    assert r.exit_code == 0, r
    if args[0] == "scan":
        found = [json.loads(line) for line in r.stdout.splitlines()]
        assert [(x["id"], x["status"]) for x in found] == [(1, "ok"), (2, "ok")]
        assert [x["return_mode"] for x in found] == [int(mode)] * 2
    if args[0] == "load" and len(args) == 4:
        assert r.stdout == "120\n"
    if args[0] == "move" and "--wait" in args:
        assert r.stdout == "100\n"


@pytest.mark.parametrize("device", list(DEVICES))
def test_return_mode_auto_on_slow_devices(cli, device):
    url = sim_url("zap", ids="1", return_mode="2", **DEVICES[device])
    r = cli("zap", "store", "goal-position", "500", "--id", "1", "-p", url, "--return-mode", "auto", "-v")
    assert r.exit_code == 0, r
    assert "acknowledged in" in r.stderr


@pytest.mark.parametrize("args", [
    ["store", "id", "5", "--id", "1"],
    ["store", "id", "5", "--id", "broadcast"],
    ["send", "id", "5", "--id", "1"],
    ["sync-move", "1:5", "--register", "id"],
    ["raw", "store", "03", "05", "--id", "1"],
    ["raw", "store", "02", "14", "05", "--id", "1"],
])
def test_direct_id_writes_need_force(cli, args):
    url = sim_url("zap", ids="1,2")
    r = cli("zap", *args, "-p", url)
    assert (r.exit_code, r.stdout) == (2, ""), r
    assert "--force" in r.stderr and "IDENTITY" in r.stderr and "writes id" in r.stderr
    assert cli("zap", *args, "-n").exit_code == 0               # a dry run sends nothing: no check
    assert cli("zap", *args, "-p", url, "--force").exit_code == 0


def test_set_id_refuses_a_taken_id_even_when_its_owner_is_slow(cli):
    # answers after the first wait; the virtual clock: the census's horizon in no time
    url = sim_url("zap", ids="1,2", faults="2:delay=30", clock="virtual")
    r = cli("zap", "set-id", "2", "--id", "1", "-p", url)
    assert r.exit_code == 2 and "already taken" in r.stderr, r
    r = cli("zap", "set-id", "3", "--id", "1", "-p", url)
    assert r.exit_code == 0 and "verified" in r.stderr, r


def test_set_id_refuses_an_id_two_actuators_share(cli, tmp_path):
    state = tmp_path / "bus.json"                                  # two actuators share ID 1
    state.write_text(json.dumps({"format": "zkzap-zap-bus/1", "actuators": [
        {"slot": 0, "position": 0, "registers": {"id": 1}},
        {"slot": 1, "position": 2000, "registers": {"id": 1}}]}))
    url = sim_url("zap", state=str(state), clock="virtual")
    r = cli("zap", "set-id", "5", "--id", "1", "-p", url)
    assert r.exit_code == 1 and "collide" in r.stderr and "verified" not in r.stderr, r
    r = cli("zap", "scan", "--ids", "0-3", "-p", url)
    assert [json.loads(x)["status"] for x in r.stdout.splitlines()] in (["duplicate"], ["garbled"])
    assert "two actuators" in r.stderr


def test_vendor_instructions_from_the_command_line(cli):
    r = cli("zap", "raw", "system-write", "01", "--id", "1", "-n")
    assert r.stdout.strip() == "FF FF FF 01 03 F9 01 01"
    r = cli("zap", "raw", "system-write", "01", "--id", "1", "--sim")        # no reply is promised
    assert r.exit_code == 0, r
    r = cli("zap", "decode", "FF FF FF 01 03 F9 01 01")
    rec = json.loads(r.stdout)
    assert (rec["kind"], rec["instruction"], rec["documented"]) == ("command", "system-write", False)
    r = cli("zap", "decode", "FF FF FF 01 02 40 BC", "-f", "table")
    assert r.exit_code == 0 and "unknown 0x40" in r.stdout
    r = cli("zap", "load", "present-temperature", "--id", "1", "--sim")
    assert (r.exit_code, r.stdout) == (0, "245\n")                         # a real 12Lf's


def test_watch_fails_when_the_bus_died_for_most_of_the_run():
    """The actuator answers, then the bus goes dead (every reply lost) for the rest of the watch:
    every row is written, and the exit is 3 naming how long it was silent (never exit 0)."""
    import json
    import threading
    import time

    from click.testing import CliRunner

    from zkzap.commands import root, run
    from zkzap.sim import start_zap

    with start_zap(ids=[1], transport="tcp") as sim:
        runner = CliRunner()
        with runner.isolation(input="") as (out, err, _):
            def die():                         # once the first rows are out, every reply is lost
                while out.getvalue().count(b"\n") < 3:
                    time.sleep(0.005)
                with sim.lock:
                    sim.device.inject(1, "silent")
            timer = threading.Thread(target=die, daemon=True)
            timer.start()
            code = run(root, "zkzap", ["zap", "watch", "present-position", "--ids", "1", "--duration", "2",
                                       "--retries", "0", "--timeout", "0.05", "-f", "jsonl", "-p", sim.url])
            timer.join()
            rows = [json.loads(line) for line in out.getvalue().decode().splitlines()]
            text = err.getvalue().decode()
    assert code == 3, text
    assert rows[0]["status"] == "ok" and rows[-1]["status"] == "no-reply" and rows[-1]["t"] >= 1.5
    assert "ID 1 unanswered for" in text and "the bus was silent for most of the watch" in text, text
