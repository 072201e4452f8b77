"""zap commands on a link: the in-process simulator (--sim, sim://zap?...) through CliRunner."""

import csv
import io
import json

import pytest

from zkzap.sim.zap_actuators import FIRMWARE_VERSION, MODEL_NUMBER


def url(ids="1,2", **opts):
    from zkzap.link.port import sim_url

    return sim_url("zap", ids=ids, **opts)


def jsonl(text):
    return [json.loads(line) for line in text.splitlines()]


# -- load / echo ------------------------------------------------------------------------------

def test_load_prints_the_bare_value(cli):
    r = cli("zap", "load", "present-voltage", "--sim")
    assert (r.exit_code, r.stdout, r.stderr) == (0, "120\n", "")
    r = cli("zap", "load", "present-voltage", "--sim", "--physical")
    assert r.stdout == "12.0\n"


def test_load_records(cli):
    r = cli("zap", "load", "present-voltage", "--id", "3", "--sim", "-f", "json")
    assert r.exit_code == 0, r
    assert json.loads(r.stdout) == [{"id": 3, "register": "present-voltage", "address": 0x92, "value": 120,
                                     "physical": 12.0, "unit": "V", "errors": []}]
    r = cli("zap", "load", "baud-rate", "--id", "3", "--sim", "-f", "csv")
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert rows == [{"id": "3", "register": "baud-rate", "address": "4", "value": "32", "physical": "",
                     "unit": "", "meaning": "57600 bps", "errors": ""}]


def test_load_several_registers(cli):
    r = cli("zap", "load", "model-number", "--length", "4", "--id", "1", "-p", url())
    assert r.exit_code == 0, r
    assert r.stdout.splitlines() == [f"model-number={MODEL_NUMBER}", "firmware-version=21", "id=1"]
    r = cli("zap", "load", "model-number", "--length", "4", "--id", "1", "-p", url(), "-f", "jsonl")
    assert [rec["register"] for rec in jsonl(r.stdout)] == ["model-number", "firmware-version", "id"]


def test_load_run_past_the_map_is_refused(cli):
    r = cli("zap", "load", "moving", "--length", "200", "--sim")
    assert r.exit_code == 2 and r.stdout == ""
    assert "run past address 0xFF" in r.stderr


def test_echo_and_count(cli):
    r = cli("zap", "echo", "--id", "1", "-p", url())
    assert r.exit_code == 0
    assert r.stdout.startswith("reply from ID 1: seq=1 ok ")
    r = cli("zap", "echo", "--id", "1", "-p", url(), "--count", "5", "-f", "jsonl")
    recs = jsonl(r.stdout)
    assert r.exit_code == 0 and [x["seq"] for x in recs] == [1, 2, 3, 4, 5]
    assert all(x["errors"] == [] and x["rtt_ms"] > 0 for x in recs)
    assert "5 sent, 5 answered, 0 lost" in r.stderr


def test_echo_count_reports_losses(cli):
    r = cli("zap", "echo", "--id", "1", "-p", url(faults="1:silent/2"), "--count", "4")
    assert r.exit_code == 3
    assert len(r.stdout.splitlines()) == 2
    assert "4 sent, 2 answered, 2 lost" in r.stderr
    assert "2 of 4 echoes failed" in r.stderr


# -- failures and exit codes ------------------------------------------------------------------

def test_no_device_exit_3(cli):
    r = cli("zap", "load", "present-position", "--id", "9", "-p", url())
    assert r.exit_code == 3 and r.stdout == ""
    assert "no reply from ID 9 at 57600 baud" in r.stderr


def test_overload_exit_5_after_the_value(cli):
    r = cli("zap", "load", "present-position", "--id", "2", "-p", url(faults="2:overload"))
    assert r.exit_code == 5
    assert r.stdout == "0\n"
    assert "ID 2 reports error 0x20: overload" in r.stderr


def test_corrupted_reply_exit_6(cli):
    r = cli("zap", "echo", "--id", "2", "-p", url(faults="2:corrupt"))
    assert r.exit_code == 6
    assert "garbled reply (checksum mismatch: a collision, two actuators answering at once, or a line fault) after 3 tries" in r.stderr
    r = cli("zap", "echo", "--id", "2", "--retries", "0", "-p", url(faults="2:corrupt/1"))
    assert r.exit_code == 6 and "after 1 try" in r.stderr
    r = cli("zap", "echo", "--id", "2", "-p", url(faults="2:corrupt/1"))
    assert r.exit_code == 0


def test_port_that_does_not_exist_exit_4(cli):
    r = cli("zap", "load", "present-position", "-p", "/dev/zkzap-no-such-port")
    assert r.exit_code == 4 and "cannot open" in r.stderr


def test_host_at_the_wrong_baud_gets_no_reply(cli):
    r = cli("zap", "echo", "--id", "1", "-b", "115200", "-p", url())
    assert r.exit_code == 3


# -- writes, consent, modes -------------------------------------------------------------------

def test_store_is_quiet_unless_verbose(cli):
    r = cli("zap", "store", "goal-position", "2000", "--id", "1", "--sim")
    assert (r.exit_code, r.stdout, r.stderr) == (0, "", "")
    r = cli("zap", "store", "goal-position", "2000", "--id", "1", "--sim", "-v")
    assert "sent store goal-position=2000 to ID 1: not acknowledged (feedback-return-mode 1" in r.stderr
    r = cli("zap", "store", "goal-position", "2000", "--id", "1", "--sim", "--return-mode", "2", "-v")
    assert "sent store goal-position=2000 to ID 1: acknowledged in" in r.stderr


def test_error_bits_in_an_acknowledgement_exit_5(cli):
    r = cli("zap", "store", "led", "2", "--id", "1", "--return-mode", "2",
            "-p", url(ids="1", return_mode="2", faults="1:overload"))
    assert r.exit_code == 5
    assert "acknowledged in" in r.stderr and "errors: overload" in r.stderr


def test_stored_writes_need_consent_on_a_real_port(cli):
    # checked before the port is opened: a missing device gives 2 (not sent), not 4
    for args in (["store", "long-stroke-limit", "3000", "--id", "1"], ["factory-reset", "--id", "1"],
                 ["raw", "store", "06", "64", "00", "--id", "1"], ["sync-move", "1:100", "--register", "speed-limit"]):
        r = cli("zap", *args, "-p", "/dev/zkzap-no-such-port")
        assert r.exit_code == 2, (args, r)
        assert "pass --yes to confirm" in r.stderr and r.stdout == ""
    r = cli("zap", "store", "long-stroke-limit", "3000", "--id", "1", "-p", "/dev/zkzap-no-such-port", "--yes")
    assert r.exit_code == 4
    # volatile registers, the simulator and loop:// never ask
    assert cli("zap", "store", "goal-position", "5", "--id", "1", "-p", "/dev/zkzap-no-such-port").exit_code == 4
    assert cli("zap", "store", "long-stroke-limit", "3000", "--id", "1", "--sim").exit_code == 0
    assert cli("zap", "store", "long-stroke-limit", "3000", "--id", "1", "-p", "loop://").exit_code == 0


def test_protocol_type_0_needs_force_everywhere(cli):
    for args in (["store", "protocol-type", "0", "--id", "1"], ["raw", "store", "0A", "00", "--id", "1"],
                 ["sync-move", "1:0", "--register", "protocol-type"]):
        r = cli("zap", *args, "--sim")
        assert r.exit_code == 2 and "pass --force" in r.stderr, args
    assert cli("zap", "raw", "store", "0A", "00", "--id", "1", "--sim", "--force").exit_code == 0


def test_stored_value_survives_in_a_state_file(cli, tmp_path):
    state = str(tmp_path / "bus.json")
    port = url(ids="1", state=state)
    assert cli("zap", "store", "long-stroke-limit", "3000", "--id", "1", "-p", port).exit_code == 0
    r = cli("zap", "load", "long-stroke-limit", "--id", "1", "-p", port)
    assert r.stdout == "3000\n"


def test_raw_prints_the_reply(cli):
    r = cli("zap", "raw", "load", "00", "03", "--id", "1", "-p", url())
    assert r.exit_code == 0
    assert r.stdout == "FF FF FF 01 05 00 12 A1 15 31\n"
    r = cli("zap", "raw", "0x99", "--id", "1", "-p", url())               # undocumented: a deliberate act
    assert r.exit_code == 2 and "needs permission UNDOCUMENTED" in r.stderr and "pass --force" in r.stderr
    r = cli("zap", "raw", "0x99", "--id", "1", "-p", url(), "--force")    # unknown: no reply, no error
    assert (r.exit_code, r.stdout) == (0, "")


def test_sync_move_and_execute_are_broadcasts(cli):
    r = cli("zap", "sync-move", "1:100", "2:200", "--sim", "-v")
    assert r.exit_code == 0
    assert "sync-move goal-position 1:100 2:200 to every actuator (broadcast): not acknowledged" in r.stderr
    r = cli("zap", "execute", "--id", "broadcast", "--sim", "-v")
    assert r.exit_code == 0 and "never answered" in r.stderr


def test_return_mode_auto_and_mode_0(cli):
    r = cli("zap", "store", "led", "2", "--id", "1", "--return-mode", "auto", "-v",
            "-p", url(ids="1", return_mode="2"))
    assert "acknowledged in" in r.stderr
    r = cli("zap", "load", "present-position", "--id", "1", "--return-mode", "auto",
            "-p", url(ids="1", return_mode="0"))
    assert r.exit_code == 2 and "feedback-return-mode 0" in r.stderr
    r = cli("zap", "load", "present-position", "--return-mode", "0", "--sim")
    assert r.exit_code == 2


def test_sim_ids_are_validated(cli):
    r = cli("zap", "echo", "--sim", "--sim-ids", "1,x")
    assert r.exit_code == 2 and "--sim-ids" in r.stderr
    r = cli("zap", "echo", "--id", "4", "--sim", "--sim-ids", "4,5")
    assert r.exit_code == 0


# -- scan, dump, move, set-id, set-baud ---------------------------------------------------------

def test_scan_finds_every_actuator(cli):
    r = cli("zap", "scan", "--ids", "0-10", "--sim", "--sim-ids", "1,2,7")
    assert r.exit_code == 0, r
    recs = jsonl(r.stdout)
    assert [(x["id"], x["baud"], x["model"], x["firmware"], x["return_mode"], x["status"]) for x in recs] == \
        [(i, 57600, MODEL_NUMBER, FIRMWARE_VERSION, 1, "ok") for i in (1, 2, 7)]


def test_scan_over_bauds_errors_and_formats(cli):
    r = cli("zap", "scan", "--ids", "0-5", "-b", "all", "-f", "csv",
            "-p", url(ids="1,3@115200,4@9600", faults="1:overload"))
    assert r.exit_code == 0, r
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert [(x["id"], x["baud"], x["status"], x["errors"]) for x in rows] == \
        [("1", "57600", "error", "overload"), ("3", "115200", "ok", ""), ("4", "9600", "ok", "")]
    r = cli("zap", "scan", "--ids", "0-5", "-p", url(ids="2", return_mode="0"), "-f", "json")
    (rec,) = json.loads(r.stdout)
    assert rec["return_mode"] == 0 and rec["model"] is None


def test_scan_nothing_found_exit_3(cli):
    r = cli("zap", "scan", "--ids", "10-12", "--sim")
    assert r.exit_code == 3 and "no actuator answered (IDs 10-12 at 57600 baud" in r.stderr
    assert r.stdout == ""


@pytest.mark.parametrize("args,needle", [
    (["scan", "--ids", "5-1"], "runs backwards"),
    (["scan", "--ids", "254"], "out of range"),
    (["scan", "-b", "1200"], "not an actuator baud rate"),
    (["move", "5000", "--id", "1"], "goal-position: 5000 is out of range; allowed 0..4095"),
    (["move", "100", "--id", "1", "--speed", "2000"], "goal-speed: 2000 is out of range"),
    (["move", "100", "--id", "broadcast", "--wait"], "--wait: a broadcast"),
    (["set-id", "254"], "id: 254 is out of range"),
    (["set-baud", "1200"], "1200"),
])
def test_bad_input_exit_2(cli, args, needle):
    r = cli("zap", *args, "-p", "/dev/zkzap-no-such-port")
    assert r.exit_code == 2, r
    assert needle in r.stderr and r.stdout == ""


def test_dump_reads_the_whole_map(cli):
    from zkzap.codec import zap

    r = cli("zap", "dump", "--id", "2", "--sim", "-f", "json")
    assert r.exit_code == 0, r
    recs = json.loads(r.stdout)
    assert [x["register"] for x in recs] == [reg.name for reg in sorted(zap.REGISTERS, key=lambda g: g.address)]
    by = {x["register"]: x for x in recs}
    assert by["id"]["value"] == 2 and by["id"]["memory"] == "NV" and by["id"]["access"] == "RW"
    assert by["present-voltage"]["physical"] == 12.0 and by["goal-position"]["memory"] == "V"
    assert by["feedback-return-mode"]["meaning"] == "Load Data and Echo"


def test_dump_uses_few_reads():
    from zkzap.commands.zap.scan import map_blocks
    from zkzap.codec import zap

    blocks = map_blocks()
    assert len(blocks) == 2
    covered = {a for start, n in blocks for a in range(start, start + n)}
    assert all(reg.address in covered for reg in zap.REGISTERS)


def test_move_wait_prints_the_final_position(cli):
    r = cli("zap", "move", "1500", "--id", "1", "--speed", "1023", "--wait", "--sim")
    assert (r.exit_code, r.stdout) == (0, "1500\n")
    r = cli("zap", "move", "4000", "--id", "1", "--wait", "--sim")
    assert r.stdout == "3686\n" and "clamped to 3686" in r.stderr


def test_move_wait_timeout_and_stops(cli):
    r = cli("zap", "move", "1500", "--id", "1", "--wait", "--wait-timeout", "0.1", "-p", url(ids="1", faults="1:stuck"))
    assert r.exit_code == 3 and "still moving after 0.1 s (position 0, goal 1500)" in r.stderr
    r = cli("zap", "move", "1500", "--id", "1", "--wait", "-p", url(ids="1", faults="1:overload"))
    assert r.exit_code == 5
    r = cli("zap", "move", "1500", "--id", "1", "--wait", "-p", url(ids="1", voltage="6.0"))
    assert r.exit_code == 5 and "input voltage" in r.stderr


def test_set_id_verified(cli, tmp_path):
    state = str(tmp_path / "bus.json")
    port = url(ids="0,5", state=state, clock="virtual")   # the census horizon in no time
    r = cli("zap", "set-id", "3", "--id", "0", "-p", port)
    assert r.exit_code == 0 and "ID 0 is now ID 3 (verified)" in r.stderr
    assert cli("zap", "echo", "--id", "3", "-p", port).exit_code == 0
    r = cli("zap", "set-id", "5", "--id", "3", "-p", port)
    assert r.exit_code == 2 and "ID 5 is already taken" in r.stderr
    r = cli("zap", "set-id", "4", "--id", "9", "-p", port)
    assert r.exit_code == 3


def test_read_back_mismatch_exit_1(cli, monkeypatch):
    from zkzap.sim.zap_actuators import Actuator

    accept = Actuator._accept
    # an actuator whose firmware ignores writes to its ID and baud rate
    monkeypatch.setattr(Actuator, "_accept", lambda self, reg, v: reg.name not in ("id", "baud-rate")
                        and accept(self, reg, v))
    r = cli("zap", "set-id", "4", "--id", "3", "--sim", "--ready-timeout", "0.2")
    assert r.exit_code == 1 and "ID 4 does not answer after the change" in r.stderr
    r = cli("zap", "set-baud", "115200", "--id", "3", "--no-restart", "--sim")
    assert r.exit_code == 1 and "reads back baud-rate 32, expected 16" in r.stderr
    r = cli("zap", "set-baud", "115200", "--id", "3", "--sim", "--ready-timeout", "0.2")
    assert r.exit_code == 1 and "does not answer at 115200 baud" in r.stderr


def test_set_baud_verified(cli, tmp_path):
    state = str(tmp_path / "bus.json")
    port = url(ids="1", state=state, clock="virtual")   # the census horizon in no time
    r = cli("zap", "set-baud", "115200", "--id", "1", "-p", port)
    assert r.exit_code == 0 and "now talks at 115200 baud (verified)" in r.stderr
    assert cli("zap", "echo", "--id", "1", "-b", "115200", "-p", port).exit_code == 0
    assert cli("zap", "echo", "--id", "1", "-p", port).exit_code == 3
    r = cli("zap", "set-baud", "57600", "--id", "1", "-b", "115200", "--no-restart", "-p", port)
    assert r.exit_code == 0 and "takes effect at the next restart" in r.stderr
