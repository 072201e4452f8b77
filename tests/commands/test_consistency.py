"""The same thing works, is refused and is worded the same way across commands: option
combinations that would be ignored, --end of timed ZK sessions, ECU error and port failure
wording, help texts, confirmed writes."""

from __future__ import annotations

import json
import socket
import threading

import pytest

from zkzap.codec import zk

SIM_ZK = "sim://zk?speed=20"
REFUSED = 2


def jsonl(text):
    return [json.loads(line) for line in text.splitlines() if line.strip()]


# --- combinations that would be silently ignored: refused ------------------------------------------

ZAP_WIRE = [
    ["echo", "--id", "1"],
    ["load", "present-position", "--id", "1"],
    ["store", "goal-position", "100", "--id", "1"],
    ["send", "goal-position", "100", "--id", "1"],
    ["execute", "--id", "broadcast"],
    ["restart", "--id", "1"],
    ["sync-move", "1:100"],
    ["raw", "echo", "--id", "1"],
    ["scan", "--ids", "1"],
    ["dump", "--id", "1"],
    ["move", "100", "--id", "1"],
    ["set-id", "2", "--id", "1", "--yes"],
    ["set-baud", "115200", "--id", "1", "--yes"],
]
ZAP_IDS = [a[0] for a in ZAP_WIRE]


@pytest.mark.parametrize("args", ZAP_WIRE, ids=ZAP_IDS)
def test_zap_refuses_sim_together_with_a_port(cli, args):
    r = cli("zap", *args, "--sim", "-p", "sim://zap?ids=1&faults=1:overload")
    assert r.exit_code == REFUSED and r.stdout == ""
    assert "port: give -p PORT or --sim, not both" in r.stderr


@pytest.mark.parametrize("args", ZAP_WIRE, ids=ZAP_IDS)
def test_zap_refuses_sim_ids_without_sim(cli, args):
    r = cli("zap", *args, "--sim-ids", "1,2", "-p", "sim://zap?ids=1")
    assert r.exit_code == REFUSED and r.stdout == ""
    assert "sim-ids: applies only with --sim" in r.stderr


@pytest.mark.parametrize("group,args", [
    ("zk", ["monitor", "--sim"]),
    ("zk", ["send", "control", "--state", "stop", "--sim"]),
    ("zk", ["profile", "-", "--sim"]),
], ids=["monitor", "send", "profile"])
def test_zk_refuses_sim_together_with_a_port(cli, group, args):
    r = cli(group, *args, "-p", SIM_ZK, input="0,0,stop\n1,0,stop\n")
    assert r.exit_code == REFUSED and "port: give -p PORT or --sim, not both" in r.stderr


@pytest.mark.parametrize("args,needle", [
    (["zk", "send", "keepalive", "-n", "-o", "x.csv"], "output: not with -n/--dry-run"),
    (["zk", "send", "keepalive", "-n", "-f", "csv"], "format: not with -n/--dry-run"),
    (["zk", "send", "keepalive", "-n", "--raw-log", "x.bin"], "raw-log: not with -n/--dry-run"),
    (["zk", "send", "control", "--state", "run", "-n", "--abort", "stop"], "abort: not with -n/--dry-run"),
    (["zk", "send", "control", "--state", "run", "-n", "--end", "hold"], "end: not with -n/--dry-run"),
    (["zk", "send", "keepalive", "-n", "--no-wait"], "no-wait: not with -n/--dry-run"),
    (["zk", "send", "control", "--state", "run", "--sim", "--end", "hold"], "end: applies only with --for"),
    (["zk", "send", "control", "--state", "run", "--sim", "--for", "0", "--end", "hold"],
     "end: applies only with --for SECONDS"),
    (["zk", "send", "keepalive", "--sim", "--for", "1", "--end", "stop"], "end: keepalive does not control the engine"),
    (["zap", "echo", "-n", "--count", "5"], "count: not with -n/--dry-run"),
    (["zap", "echo", "-n", "--interval", "1"], "interval: not with -n/--dry-run"),
    (["zap", "echo", "-n", "-f", "json"], "format: not with -n/--dry-run"),
    (["zap", "load", "present-position", "-n", "-f", "json"], "format: not with -n/--dry-run"),
    (["zap", "load", "present-voltage", "-n", "--physical"], "physical: not with -n/--dry-run"),
    (["zap", "store", "goal-position", "1", "--id", "1", "-n", "-v"], "verbose: not with -n/--dry-run"),
    (["zap", "restart", "--id", "1", "-n", "--timeout", "1"], "timeout: not with -n/--dry-run"),
    (["zap", "raw", "echo", "--id", "1", "-n", "--retries", "5"], "retries: not with -n/--dry-run"),
    (["zap", "sync-move", "1:5", "-n", "--return-mode", "2"], "return-mode: not with -n/--dry-run"),
    (["zap", "store", "goal-position", "1", "--id", "1", "-n", "--verify"], "verify: not with -n/--dry-run"),
    (["zap", "store", "goal-position", "1", "--id", "broadcast", "--sim", "--verify"],
     "verify: a broadcast write cannot be read back"),
    (["zap", "store", "id", "3", "--id", "1", "--sim", "--verify", "--force"], "verify: id changes where"),
    (["zap", "move", "100", "--id", "1", "--sim", "--no-stop"], "no-stop: applies only with --wait"),
    (["zk", "monitor", "--sim", "--raw-log", "-", "--count", "1"], "raw-log: '-' is not a file here"),
    (["zk", "send", "keepalive", "--sim", "--for", "1", "--raw-log", "-"], "raw-log: '-' is not a file here"),
    (["zk", "profile", "-", "--sim", "--raw-log", "-"], "raw-log: '-' is not a file here"),
])
def test_options_that_would_be_ignored_are_refused(cli, tmp_path, monkeypatch, args, needle):
    monkeypatch.chdir(tmp_path)
    r = cli(*args, input="0,0,stop\n1,0,stop\n")
    assert r.exit_code == REFUSED, r
    assert needle in r.stderr and r.stdout == ""
    assert not (tmp_path / "-").exists() and not (tmp_path / "x.csv").exists()


# --- timed ZK sessions end as --end says -------------------------------------------------------------

def _last_commands(ecu, n):
    return [(r["command"], r.get("state")) for r in list(ecu.received)[-n:]]


@pytest.mark.parametrize("end,expected", [
    (None, "standby"), ("standby", "standby"), ("stop", "stop"), ("hold", None),
])
@pytest.mark.parametrize("command", [
    ["control", "--state", "run", "--throttle", "30"],
    ["mode", "--state", "run", "--rpm-factor", "2"],
    ["raw", "7", "rpm_value=3000"],
], ids=["control", "mode", "rpm"])
def test_send_for_ends_with_the_end_command(cli, monkeypatch, command, end, expected):
    from zkzap.link import protocol_sim

    devices = []
    real_open = protocol_sim.Serial.open

    def spy_open(self):
        real_open(self)
        devices.append(self.device)

    monkeypatch.setattr(protocol_sim.Serial, "open", spy_open)
    args = ["zk", "send", *command, "-p", SIM_ZK, "--for", "2", "-f", "jsonl", "--ids", "1"]
    r = cli(*args, *(["--end", end] if end else []))
    assert r.exit_code == 0, r
    (ecu,) = devices
    if expected is None:
        # a session left running says how it leaves the engine
        assert "end of --for: --end hold: nothing more sent; the engine is left " in r.stderr
        assert list(ecu.received)[-1]["command"] == zk.decode_control(
            zk.encode_control_raw(7, rpm_value=3000) if command[0] == "raw" else
            zk.encode_control(command[0], **_values(command))[0])["command"]
    else:
        assert f"end of --for: sent {expected}, throttle 0" in r.stderr
        assert _last_commands(ecu, 4) == [("control", expected), ("mode", "none"), ("control", expected),
                                          ("control", expected)]
    assert r.stderr.splitlines()[-1].startswith("zk send ")           # the summary line


def _values(command):
    if command[0] == "control":
        return {"sw": "run", "throttle_pct": 30}
    return {"sw": "run", "rpm_factor": 2}


def test_a_harmless_timed_command_gets_no_end_command(cli):
    r = cli("zk", "send", "keepalive", "-p", SIM_ZK, "--for", "1", "-f", "jsonl")
    assert r.exit_code == 0 and "sent standby" not in r.stderr and "--end" not in r.stderr


def test_an_error_latched_before_send_for_is_not_exit_0(cli):
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "-p",
            SIM_ZK + "&error=voltage-low&error_after=0", "--for", "2", "-f", "jsonl", "--ids", "1")
    assert r.exit_code == 5
    assert "ECU error 2 (voltage-low: " in r.stderr.splitlines()[-1]


# --- one wording per failure -------------------------------------------------------------------

@pytest.mark.parametrize("args", [
    ["monitor", "--fail-on-error", "--count", "40"],
    ["send", "control", "--state", "run", "--throttle", "30", "--for", "30"],
    ["profile", "-"],
], ids=["monitor", "send", "profile"])
def test_the_ecu_error_message_is_the_same_everywhere(cli, args):
    r = cli("zk", *args, "-p", SIM_ZK + "&error=egt-high&error_after=0.5", "-f", "jsonl", "--ids", "1",
            input="0,30,run\n30,30\n")
    assert r.exit_code == 5
    line = [ln for ln in r.stderr.splitlines() if ln.startswith("zkzap: error:")]
    assert line and line[0].startswith("zkzap: error: ECU error 8 (egt-high: Exhaust temperature is high) at t=")


def test_a_failed_port_is_worded_the_same_in_zk_and_zap():
    import serial

    from zkzap.link.zap_bus import ZapBus
    from zkzap.link.zk_port import ZkLink

    class Broken:
        timeout = 0.01
        baudrate = 57600

        def read(self, n=1):
            raise serial.SerialException("read failed: [Errno 5] Input/output error")

        write = reset_input_buffer = read

        def close(self):
            pass

    messages = []
    for attempt in (lambda: ZkLink(Broken(), "/dev/ttyUSB9").read(),
                    lambda: ZapBus(Broken(), url="/dev/ttyUSB9").echo(1)):
        with pytest.raises(Exception) as e:
            attempt()
        messages.append(str(e.value))
    assert messages == ["port /dev/ttyUSB9 failed: read failed: Input/output error"] * 2


# --- help speaks of each command's own outcomes ------------------------------------------------------

@pytest.mark.parametrize("args,present,absent", [
    (["zk", "send", "control", "--help"], ["--for ran its time", "--end"], ["--fail-on-error", "end of replay"]),
    (["zk", "profile", "--help"], ["the schedule ran to its end"], ["--fail-on-error", "end of replay", "--count"]),
    (["zk", "monitor", "--help"], ["--fail-on-error, an ECU error", "end of replay"], []),
    (["zap", "store", "--help"], ["stored settings", "--verify"], ["engine"]),
    (["zap", "set-id", "--help"], ["stored settings"], ["engine"]),
    (["zk", "send", "action", "--help"], ["start the engine"], []),
])
def test_help_speaks_of_its_own_command(cli, args, present, absent):
    r = cli(*args)
    text = " ".join(r.stdout.split())
    for p in present:
        assert p in text, p
    for a in absent:
        assert a not in text, a


@pytest.mark.parametrize("args,needle", [
    (["zk", "decode", "FF1DF470", "00"], "1 frame decoded; 0 bad (CRC); 1 byte skipped"),
    (["zap", "decode", "FF", "FF", "FF", "00", "02", "F1", "0C", "00"], "1 packet decoded; 0 bad (checksum); 1 byte skipped"),
])
def test_one_is_singular(cli, args, needle):
    r = cli(*args)
    assert needle in r.stderr


def test_no_error_error(cli):
    r = cli("zk", "monitor", "-p", "sim://zk?error=bogus", "--count", "1")
    assert r.exit_code == 2 and "error: error" not in r.stderr.replace("zkzap: error: ", "", 1)
    assert "error=bogus: not an ECU error code or name" in r.stderr


class _View:
    made = []

    def __init__(self, title):
        self.title, self.duration = title, None
        _View.made.append(self)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def update(self, snapshot, health):
        pass

    def note(self, text):
        pass


@pytest.mark.parametrize("args,title,duration", [
    (["send", "control", "--state", "run", "--throttle", "50", "--for", "1"], "zk send control run 50 %", 1.0),
    (["send", "action", "test-pump", "--for", "1"], "zk send action test-pump", 1.0),
    (["profile", "-"], "zk profile stdin", 1.0),
    (["monitor", "--duration", "1"], "ZK ECU", 1.0),
], ids=["send-control", "send-action", "profile", "monitor"])
def test_dashboard_title_names_the_command_and_knows_the_length(cli, monkeypatch, args, title, duration):
    from zkzap.commands.zk import monitor as mon
    from zkzap.io import term

    _View.made = []
    monkeypatch.setattr(mon, "_dashboard", _View)
    real = term.is_tty
    monkeypatch.setattr(term, "is_tty", lambda stream: stream is mon.sys.stdout or real(stream))
    r = cli("zk", *args, "-p", SIM_ZK, input="0,10,run\n1,0,standby\n")
    assert r.exit_code == 0, r
    (view,) = _View.made
    assert view.title == f"{title} on {SIM_ZK}" and "FF " not in view.title
    assert view.duration == duration


# --- writes that nothing confirms ---------------------------------------------------------------------

@pytest.fixture
def silent_port():
    """A TCP port that takes every byte and never answers: a serial line with nothing attached."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    stop = threading.Event()

    def serve():
        srv.settimeout(0.1)
        conns = []
        while not stop.is_set():
            try:
                conns.append(srv.accept()[0])
            except OSError:
                pass
            for c in conns:
                c.setblocking(False)
                try:
                    c.recv(4096)
                except OSError:
                    pass
        for c in conns:
            c.close()

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    yield f"socket://127.0.0.1:{srv.getsockname()[1]}"
    stop.set()
    t.join(2)
    srv.close()


@pytest.mark.parametrize("args", [
    ["store", "goal-position", "100", "--id", "1"],
    ["sync-move", "1:100", "2:200"],
], ids=["store", "sync-move"])
def test_an_unconfirmed_write_succeeds_unless_verified(cli, silent_port, args):
    r = cli("zap", *args, "-p", silent_port, "--timeout", "0.05", "--retries", "0")
    assert r.exit_code == 0                                   # nothing can tell: unconfirmed
    r = cli("zap", *args, "-p", silent_port, "--timeout", "0.05", "--retries", "0", "--verify")
    assert r.exit_code == 3 and "unconfirmed: no reply to the read-back" in r.stderr


@pytest.mark.parametrize("args,code,needle", [
    (["store", "goal-speed", "300", "--id", "1"], 0, "ID 1: goal-speed reads back 300"),
    (["sync-move", "1:100", "2:200", "--register", "goal-speed"], 0, "ID 2: goal-speed reads back 200"),
    (["store", "goal-position", "4000", "--id", "1"], 1, "ID 1: goal-position reads back 3686, not the 4000 written"),
])
def test_verify_reads_the_written_values_back(cli, args, code, needle):
    r = cli("zap", *args, "-p", "sim://zap?ids=1,2", "--verify", "-v")
    assert r.exit_code == code, r
    assert needle in r.stderr


def test_scan_warns_of_actuators_sharing_an_id(cli):
    r = cli("zap", "scan", "-p", "sim://zap?ids=1,1,2", "--ids", "0-3", "-f", "jsonl")
    assert r.exit_code == 0
    recs = jsonl(r.stdout)
    assert [(x["id"], x["status"]) for x in recs] == [(1, "garbled"), (2, "ok")]
    assert "ID 1 at 57600 baud: every reply was garbled: two actuators may answer to this ID" in r.stderr
