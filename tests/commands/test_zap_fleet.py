"""zap backup / diff / apply / setup / watch / check through the CLI, against simulated buses
whose stored registers live in state files (one file per bus, kept across commands). The fleet
tests run over both mightyZAP protocol families (the ``rig`` fixture: IR 12Lf and Modbus RTU
17Lf), the same test for each."""

import csv
import io
import json
import os

import pytest

from zkzap.codec.regmap import default_map
from zkzap.sim.zap_actuators import from_options


def jsonl(text):
    return [json.loads(line) for line in text.splitlines()]


def make_bus(path, ids="1,2,3", settings=None, protocol="ir"):
    """A simulated bus in state file ``path``; ``settings``: {ID: {register: value}}."""
    bus = from_options(ids=ids, state=str(path), protocol=protocol)
    for ident, regs in (settings or {}).items():
        for name, value in regs.items():
            bus.actuator(ident).set(name, value)
    bus.save()
    # the virtual clock: a census listens out its 1.5 s horizon in no time
    return f"sim://zap?state={path}&clock=virtual" + ("&protocol=modbus" if protocol == "modbus" else "")


class Rig:
    """One protocol family's side of a fleet test: its buses, its backup option, its factory ID."""

    def __init__(self, protocol):
        self.protocol = protocol
        self.map = default_map(protocol)
        self.option = ["--protocol", protocol]          # backup's (diff, apply, setup read it from the file)
        self.factory = self.map.by_name["id"].default or 0

    def bus(self, path, ids="1,2,3", settings=None):
        return make_bus(path, ids, settings, self.protocol)

    def url(self, query):
        # the virtual clock, as make_bus: a census listens out its horizon in no time
        return f"sim://zap?{query}&clock=virtual" + ("&protocol=modbus" if self.protocol == "modbus" else "")

    def order(self, items):
        """(id, register, ...) rows in the order an apply writes them: by ID, then address."""
        return sorted(items, key=lambda x: (x[0], self.map.by_name[x[1]].address))


@pytest.fixture(params=["ir", "modbus"])
def rig(request):
    return Rig(request.param)


def state_of(path):
    return {a["registers"]["id"]: a["registers"] for a in json.load(open(path))["actuators"]}


A_SETTINGS = {1: {"speed-limit": 500, "acceleration": 40}, 2: {"current-limit": 600},
              3: {"long-stroke-limit": 3000, "alarm-led": 1}}


@pytest.fixture
def buses(tmp_path):
    a = make_bus(tmp_path / "a.json", settings=A_SETTINGS)
    b = make_bus(tmp_path / "b.json")           # factory fresh
    return a, b, tmp_path


@pytest.fixture
def fleets(cli, rig, tmp_path):
    """Bus A configured (A_SETTINGS), bus B factory fresh, and A's backup (fleet.json), on ``rig``'s protocol."""
    a = rig.bus(tmp_path / "a.json", settings=A_SETTINGS)
    b = rig.bus(tmp_path / "b.json")
    f = str(tmp_path / "fleet.json")
    r = cli("zap", "backup", "--ids", "1-3", *rig.option, "-p", a, "-o", f)
    assert r.exit_code == 0, r
    return a, b, f, tmp_path


@pytest.mark.parametrize("suffix", [".json", ".toml", ".yaml"])
def test_backup_a_apply_to_fresh_b_then_diff_is_empty(cli, rig, tmp_path, suffix):
    a = rig.bus(tmp_path / "a.json", settings=A_SETTINGS)
    b = rig.bus(tmp_path / "b.json")
    tmp = tmp_path
    fresh = state_of(tmp / "b.json")
    fleet_file = str(tmp / f"fleet{suffix}")
    r = cli("zap", "backup", "--ids", "1-3", *rig.option, "-p", a, "-o", fleet_file)
    assert (r.exit_code, r.stdout) == (0, ""), r
    assert "3 actuators (1-3) backed up" in r.stderr
    r = cli("zap", "diff", fleet_file, "bus", "-p", b)
    assert r.exit_code == 1 and len(jsonl(r.stdout)) == 5 and "note: 5 differences" in r.stderr
    assert "error" not in r.stderr                  # a result, not an error
    r = cli("zap", "apply", fleet_file, "--plan", "-p", b)
    assert r.exit_code == 0 and [x["status"] for x in jsonl(r.stdout)] == ["planned"] * 5
    assert state_of(tmp / "b.json") == fresh                            # --plan writes nothing
    r = cli("zap", "apply", fleet_file, "-p", b)
    assert r.exit_code == 0, r
    rows = jsonl(r.stdout)
    assert [(x["id"], x["register"], x["old"], x["new"], x["status"]) for x in rows] == rig.order(
        [(i, name, fresh[i][name], value, "verified") for i, regs in A_SETTINGS.items() for name, value in regs.items()])
    assert "5 writes made and verified" in r.stderr
    r = cli("zap", "diff", fleet_file, "bus", "-p", b)
    assert (r.exit_code, r.stdout) == (0, ""), r
    r = cli("zap", "apply", fleet_file, "-p", b)
    assert (r.exit_code, r.stdout) == (0, "") and "nothing to write" in r.stderr


def test_backup_to_stdout_and_scan(cli, buses):
    a, _, _ = buses
    r = cli("zap", "backup", "--scan", "--ids", "0-5", "-p", a)
    assert r.exit_code == 0
    doc = json.loads(r.stdout)
    assert sorted(doc["actuators"]) == ["1", "2", "3"]
    r = cli("zap", "backup", "--ids", "2", "-p", a, "-f", "yaml")
    assert r.stdout.startswith('format: "zkzap-fleet/2"\n') and 'protocol: "ir"' in r.stdout and "current-limit: 600" in r.stdout


def test_backup_of_a_silent_id_writes_nothing(cli, buses):
    a, _, tmp = buses
    out = tmp / "x.json"
    r = cli("zap", "backup", "--ids", "1,7", "-p", a, "-o", str(out))
    assert r.exit_code == 3 and not out.exists() and "no reply from ID 7" in r.stderr


def test_diff_formats_and_all(cli, buses):
    a, b, tmp = buses
    fb = str(tmp / "b.toml")
    cli("zap", "backup", "--ids", "1-3", "-p", a, "-o", str(tmp / "fa.json"))
    cli("zap", "backup", "--ids", "1-2", "-p", b, "-o", fb)
    r = cli("zap", "diff", str(tmp / "fa.json"), fb, "-f", "csv")
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert r.exit_code == 1
    assert rows[0] == {"id": "1", "register": "speed-limit", "address": "21", "memory": "NV", "a": "500",
                       "b": "1023", "unit": "", "equal": "false"}
    assert rows[-1]["register"] == "(actuator)" and rows[-1]["b"] == "absent"
    r = cli("zap", "diff", fb, fb, "--all", "--compare", "all", "-f", "json")
    assert r.exit_code == 0 and all(x["equal"] for x in json.loads(r.stdout))
    r = cli("zap", "diff", str(tmp / "fa.json"), fb, "--ids", "2")
    assert (r.exit_code, len(jsonl(r.stdout))) == (1, 1)                 # current-limit only
    r = cli("zap", "diff", str(tmp / "fa.json"), fb, "--ids", "2,9")
    assert (r.exit_code, r.stdout) == (2, "") and "ID 9 is in neither" in r.stderr


def test_apply_clone_with_to_and_map(cli, rig, fleets):
    a, b, f, tmp = fleets
    fresh = state_of(tmp / "b.json")
    r = cli("zap", "apply", f, "--ids", "1", "--to", "1-3", "-p", b)
    assert r.exit_code == 0, r
    assert [(x["id"], x["register"]) for x in jsonl(r.stdout)] == rig.order(
        [(i, reg) for i in (1, 2, 3) for reg in ("speed-limit", "acceleration")])
    st = state_of(tmp / "b.json")
    assert all(st[i]["speed-limit"] == 500 for i in (1, 2, 3))
    r = cli("zap", "apply", f, "--id-map", "2:3", "-p", b)
    assert r.exit_code == 2 and "bus ID 3 would get the settings of two actuators" in r.stderr
    r = cli("zap", "apply", f, "--ids", "2", "--id-map", "2:3", "-p", b)
    assert r.exit_code == 0 and [(x["id"], x["source"], x["register"], x["new"]) for x in jsonl(r.stdout)] == [
        (3, 2, name, v) for _, name, v in rig.order([(3, "speed-limit", fresh[2]["speed-limit"]),
                                                     (3, "acceleration", fresh[2]["acceleration"]),
                                                     (3, "current-limit", 600)])]


USER_MAP = """model: Q17
protocol: modbus
  0 | model-number | 16 | NV | R |  |  |  |  | model
  1 | firmware-version | 16 | NV | R |  |  |  |  | firmware
  4 | id | 16 | NV | RW | 1..247 |  | 1 | identity | actuator ID
  5 | baud-rate | 16 | NV | RW | 8=115200 bps; 16=57600 bps |  | 16 | identity | baud rate code
 20 | speed-limit | 16 | NV | RW |  |  | 1000 |  | speed limit
"""


def test_apply_takes_a_register_map_file_and_the_ids_by_id_map(cli, tmp_path):
    """zap apply's --map is the register map file, as on every zap command (a model zkzap does not
    ship); the ID mapping is --id-map. The old --map OLD:NEW still works where it names no file."""
    m = tmp_path / "q17.map"
    m.write_text(USER_MAP)
    bus = make_bus(tmp_path / "b.json", ids="1,2", protocol="modbus")
    f = tmp_path / "q.json"
    r = cli("zap", "backup", "--protocol", "modbus", "--map", str(m), "--ids", "1", "-p", bus, "-o", str(f))
    assert r.exit_code == 0, r
    doc = json.loads(f.read_text())
    assert doc["map"] == "Q17" and doc["actuators"]["1"]["stored"] == {"id": 1, "baud-rate": 16, "speed-limit": 1000}
    doc["actuators"]["1"]["stored"]["speed-limit"] = 555
    f.write_text(json.dumps(doc))
    r = cli("zap", "apply", str(f), "--protocol", "modbus", "-p", bus)          # no map of the Q17 shipped
    assert (r.exit_code, r.stdout) == (2, "") and "give its map file with --map FILE" in r.stderr, r
    r = cli("zap", "apply", str(f), "--protocol", "modbus", "--map", str(m), "--id-map", "1:2", "-p", bus)
    assert r.exit_code == 0 and [(x["id"], x["register"], x["status"]) for x in jsonl(r.stdout)] == [
        (2, "speed-limit", "verified")], r
    assert state_of(tmp_path / "b.json")[2]["speed-limit"] == 555
    # the old spelling: OLD:NEW pairs that name no file are the ID mapping, with a note
    r = cli("zap", "apply", str(f), "--protocol", "modbus", "--map", "1:2", "-p", bus, "--plan")
    assert r.exit_code == 2 and "--map 1:2: the ID mapping is --id-map now" in r.stderr, r   # (no Q17 map)
    legacy = tmp_path / "legacy.json"
    assert cli("zap", "backup", "--protocol", "modbus", "--ids", "1", "-p", bus, "-o", str(legacy)).exit_code == 0
    r = cli("zap", "apply", str(legacy), "--map", "1:2", "-p", bus, "--plan")
    assert r.exit_code == 0 and "taken as --id-map 1:2" in r.stderr, r
    r = cli("zap", "apply", str(legacy), "--map", "1:2", "--id-map", "1:2", "-p", bus, "--plan")
    assert (r.exit_code, r.stdout) == (2, "") and "give the ID mapping once" in r.stderr
    import os

    here = os.getcwd()
    os.chdir(tmp_path)
    try:
        (tmp_path / "1:2").write_text(USER_MAP)        # a file of that name too: ambiguous, refused
        r = cli("zap", "apply", str(legacy), "--map", "1:2", "-p", bus, "--plan")
    finally:
        os.chdir(here)
    assert (r.exit_code, r.stdout) == (2, "") and "both a file and OLD:NEW ID pairs" in r.stderr, r


def test_apply_only_skip_and_protected(cli, buses):
    a, b, tmp = buses
    f = str(tmp / "fleet.json")
    cli("zap", "backup", "--ids", "1-3", "-p", a, "-o", f)
    r = cli("zap", "apply", f, "--skip", "acceleration,alarm-led", "-p", b)
    assert [x["register"] for x in jsonl(r.stdout)] == ["speed-limit", "current-limit", "long-stroke-limit"]
    r = cli("zap", "apply", f, "--only", "id", "-p", b)
    assert (r.exit_code, r.stdout) == (2, "") and "--force" in r.stderr
    r = cli("zap", "apply", f, "--id-map", "1:2", "--ids", "1", "--only", "id", "--force", "--plan", "-p", b)
    assert (r.exit_code, r.stdout) == (2, "") and "would give bus ID 2 the ID 1" in r.stderr


@pytest.mark.parametrize("how", [["--to", "2-3"], ["--id-map", "1:3"]])
def test_a_clone_never_makes_two_actuators_with_one_id(cli, fleets, how):
    """Regression: a clone's plan listed "ID 2 id (2 on the bus, 1 in the file)" and hinted
    --only NAME --force, which gave ID 2 the ID 1."""
    a, b, f, tmp = fleets
    r = cli("zap", "apply", f, "--ids", "1", *how, "--plan", "-p", b)
    assert r.exit_code == 0, r
    assert "id" not in {x["register"] for x in jsonl(r.stdout)} and " id (" not in r.stderr
    r = cli("zap", "apply", f, "--ids", "1", *how, "--only", "id", "--force", "-p", b)
    assert (r.exit_code, r.stdout) == (2, "") and "zap set-id" in r.stderr
    r = cli("zap", "apply", f, "--ids", "1", *how, "--yes", "-p", b)
    assert r.exit_code == 0, r
    assert sorted(state_of(tmp / "b.json")) == [1, 2, 3]           # every actuator keeps its own ID


def test_apply_of_a_baud_rate_says_when_it_takes_effect(cli, rig, tmp_path):
    code = {b: c for c, b in rig.map.baud_codes.items()}[115200]
    a = rig.bus(tmp_path / "a.json", ids="1", settings={1: {"baud-rate": code}})
    b = rig.bus(tmp_path / "b.json", ids="1,2")
    f = str(tmp_path / "fleet.json")
    assert cli("zap", "backup", "--ids", "1", *rig.option, "-p", a, "-b", "115200", "-o", f).exit_code == 0
    r = cli("zap", "apply", f, "--only", "baud-rate", "--force", "-p", b)
    assert r.exit_code == 0, r
    rows = jsonl(r.stdout)
    assert [(x["register"], x["new"], x["status"]) for x in rows] == [("baud-rate", code, "verified")]
    if rig.protocol == "ir":      # the 12Lf: the stored code applies at the next restart
        assert "115200 baud from its next restart" in rows[0]["note"] and "at 57600 baud until then" in r.stderr
    else:                         # the 17Lf answers at the new rate at once: read back there
        assert "read back at 115200 baud" in rows[0]["note"] and "answers at 115200 baud now" in r.stderr
    r = cli("zap", "load", "baud-rate", "--id", "2", *rig.option, "-p", b)      # the other actuator: as it was
    assert (r.exit_code, r.stdout.strip()) == (0, str({v: k for k, v in rig.map.baud_codes.items()}[57600]))


def test_a_file_of_one_protocol_is_never_applied_to_the_other(cli, rig, fleets):
    a, b, f, tmp = fleets
    other = "modbus" if rig.protocol == "ir" else "ir"
    fresh = (tmp / "b.json").read_bytes()
    for cmd in (("apply", f, "--yes"), ("diff", f, "bus"), ("setup", "--ids", "1", "--config", f, "--config-id", "1",
                                                             "--state", str(tmp / "s.json"))):
        r = cli("zap", *cmd, "--protocol", other, "-p", b)
        assert (r.exit_code, r.stdout) == (2, ""), r
        assert "their register maps differ" in r.stderr and f"--protocol {rig.protocol} talks to it" in r.stderr
    assert (tmp / "b.json").read_bytes() == fresh and not (tmp / "s.json").exists()
    doc = json.loads(open(f).read())
    assert (doc["format"], doc["protocol"], doc["map"]) == ("zkzap-fleet/2", rig.protocol, rig.map.model)
    r = cli("zap", "diff", f, str(_other_file(cli, tmp, other)))
    assert (r.exit_code, r.stdout) == (2, "") and "their register maps differ" in r.stderr


def _other_file(cli, tmp, protocol):
    out = tmp / f"{protocol}.json"
    r = cli("zap", "backup", "--ids", "1", "--protocol", protocol, "--sim", "-o", str(out))
    assert r.exit_code == 0, r
    return out


def test_a_file_of_the_first_format_is_read_as_ir(cli, buses):
    a, b, tmp = buses
    f = tmp / "old.json"
    f.write_text('{"format":"zkzap-fleet/1","actuators":{"1":{"stored":{"speed-limit":5}}}}')
    r = cli("zap", "apply", str(f), "--plan", "-p", b)
    assert r.exit_code == 0 and [(x["register"], x["new"]) for x in jsonl(r.stdout)] == [("speed-limit", 5)]
    f.write_text('{"format":"zkzap-fleet/1","protocol":"modbus","actuators":{"1":{}}}')
    r = cli("zap", "apply", str(f), "--plan", "-p", b)
    assert (r.exit_code, r.stdout) == (2, "") and "holds IR actuators of the 12Lf only" in r.stderr


def _bad_file(tmp, text, name="bad.json"):
    p = tmp / name
    p.write_text(text)
    return str(p)


@pytest.mark.parametrize("content,name,message", [
    ('{"format":"zkzap-fleet/1","actuators":{"1":{"stored":{"speed-limt":5}}}}', "bad.json",
     "bad.json: actuators.1.stored.speed-limt: unknown register"),
    ('{"format":"zkzap-fleet/1","actuators":{"1":{"stored":{"current-limit":5000}}}}', "bad.json",
     "bad.json: actuators.1.stored.current-limit: 5000 is out of range; allowed 0..1600 mA"),
    ('{"format":"zkzap-fleet/1","actuators":{"x1":{}}}', "bad.json", "bad.json: actuators.x1: 'x1' is not an actuator ID"),
    ('format = "zkzap-fleet/1"\n[actuators.1.stored]\nspeed-limit = -1\n', "bad.toml",
     "bad.toml: actuators.1.stored.speed-limit: -1 is out of range"),
    ('format: "zkzap-fleet/1"\nactuators:\n  "1":\n    stored:\n      acceleration: 300\n', "bad.yaml",
     "bad.yaml: actuators.1.stored.acceleration: 300 is out of range"),
    ("{not json", "bad.json", "bad.json:1: not valid JSON"),
])
def test_bad_files_are_refused_before_any_write(cli, buses, content, name, message):
    _, b, tmp = buses
    before = (tmp / "b.json").read_bytes()
    f = _bad_file(tmp, content, name)
    for cmd in (("apply", f), ("diff", f, "bus")):
        r = cli("zap", *cmd, "-p", b)
        assert (r.exit_code, r.stdout) == (2, ""), r
        assert message in r.stderr
    assert (tmp / "b.json").read_bytes() == before


def test_another_model_is_refused_unless_forced(cli, buses):
    a, b, tmp = buses
    f = tmp / "fleet.json"
    cli("zap", "backup", "--ids", "1", "-p", a, "-o", str(f))
    doc = json.loads(f.read_text())
    doc["actuators"]["1"]["model"] = 0x0C4C
    f.write_text(json.dumps(doc))
    before = (tmp / "b.json").read_bytes()
    r = cli("zap", "apply", str(f), "-p", b)
    assert (r.exit_code, r.stdout) == (2, "") and "model 0xA112, the file's 0x0C4C" in r.stderr
    assert (tmp / "b.json").read_bytes() == before
    r = cli("zap", "apply", str(f), "--force", "-p", b)
    assert r.exit_code == 0 and "warning:" in r.stderr and len(jsonl(r.stdout)) == 2


def test_apply_ids_not_in_the_file(cli, tmp_path):
    f = tmp_path / "f.json"
    f.write_text('{"format":"zkzap-fleet/1","actuators":{"1":{"stored":{"speed-limit":5}}}}')
    r = cli("zap", "apply", str(f), "--ids", "9", "-p", "sim://zap?ids=1")
    assert (r.exit_code, r.stdout) == (2, "") and "--ids: ID 9 is not in the file; it has 1" in r.stderr


def test_interrupted_apply_reports_and_rerun_finishes(cli, rig, fleets, monkeypatch):
    a, b, f, tmp = fleets
    from zkzap.api import fleet

    real = fleet.execute

    def interrupted(bus, writes, done, on_write=None):
        def stop(w):
            if len(done) == 2:
                raise KeyboardInterrupt
        return real(bus, writes, done, on_write=stop)

    monkeypatch.setattr(fleet, "execute", interrupted)
    r = cli("zap", "apply", f, "-p", b)
    assert r.exit_code == 130
    first = rig.order([(1, "speed-limit"), (1, "acceleration")])
    assert [(x["id"], x["register"], x["status"]) for x in jsonl(r.stdout)] == [(i, n, "verified") for i, n in first]
    assert (f"2 of 5 writes made: ID 1 {first[0][1]}, ID 1 {first[1][1]}; 3 not made") in r.stderr
    monkeypatch.setattr(fleet, "execute", real)
    r = cli("zap", "apply", f, "-p", b)
    assert r.exit_code == 0 and [(x["id"], x["register"]) for x in jsonl(r.stdout)] == rig.order([
        (2, "current-limit"), (3, "long-stroke-limit"), (3, "alarm-led")])


def test_apply_to_a_silent_actuator_writes_nothing(cli, rig, fleets):
    a, _, f, tmp = fleets
    r = cli("zap", "apply", f, "-p", rig.url("ids=1,2"))
    assert r.exit_code == 3 and r.stdout == "" and "no reply from ID 3" in r.stderr


# -- setup -------------------------------------------------------------------------------------

def test_setup_one_actuator_per_run_resumes_from_the_state_file(cli, rig, tmp_path):
    state = str(tmp_path / "setup.json")
    cfg = tmp_path / "cfg.json"
    src = rig.bus(tmp_path / "src.json", ids="1", settings={1: {"speed-limit": 700}})
    cli("zap", "backup", "--ids", "1", *rig.option, "-p", src, "-o", str(cfg))
    new = str(rig.factory)                          # a factory-fresh actuator's ID
    first = rig.bus(tmp_path / "n1.json", ids=new)
    second = rig.bus(tmp_path / "n2.json", ids=new)
    args = ("zap", "setup", "--ids", "4-5", "--state", state, "--find-ids", "0-7", "--find-baud", "57600",
            "--config", str(cfg))
    r = cli(*args, "-p", first, input="\n")        # Enter once, then stdin ends: more to do (8)
    assert r.exit_code == 8 and r.stdout == ""
    assert f"ID 4 done: found at ID {new}, 57600 baud; 1 settings from" in r.stderr
    assert "stopped before ID 5" in r.stderr and "more to do: ID 5 not set up yet" in r.stderr
    assert state_of(tmp_path / "n1.json")[4]["speed-limit"] == 700
    # the same actuator again is refused: it was set up already
    r = cli(*args, "-p", first, input="\n")
    assert r.exit_code == 1 and "answers as ID 4" in r.stderr and "gave already" in r.stderr
    r = cli(*args, "-p", second, input="\n")
    assert r.exit_code == 0, r
    assert "ID 5 done" in r.stderr and "setup: 2 of 2 done (4-5)" in r.stderr
    assert 5 in state_of(tmp_path / "n2.json")
    r = cli(*args, "-p", second, input="")
    assert r.exit_code == 0 and "every ID of 4-5 is done" in r.stderr
    saved = json.load(open(state))
    assert sorted(saved["done"]) == ["4", "5"] and saved["done"]["5"]["from_id"] == rig.factory


def test_setup_skip_redo_and_two_actuators(cli, tmp_path):
    state = str(tmp_path / "setup.json")
    two = make_bus(tmp_path / "two.json", ids="0,3")
    base = ("zap", "setup", "--ids", "1-2", "--state", state, "--find-ids", "0-4", "--find-baud", "57600")
    r = cli(*base, "-p", two, input="\n")
    assert r.exit_code == 1 and "2 actuators answer at 57600 baud (IDs 0, 3)" in r.stderr
    assert not state_of(tmp_path / "two.json").get(1)
    one = make_bus(tmp_path / "one.json", ids="0")
    r = cli(*base, "-p", one, input="s\n\n")
    assert r.exit_code == 1 and "ID 1 skipped" in r.stderr and "ID 2 done" in r.stderr
    assert "skipped 1" in r.stderr
    r = cli(*base, "-p", one, input="")             # nothing pending, but ID 1 is not done: not "every ID"
    assert r.exit_code == 1 and "every ID" not in r.stderr
    assert "setup not complete: ID 1 skipped (--redo 1 sets it up)" in r.stderr
    r = cli(*base, "--redo", "2", "-p", f"sim://zap?state={tmp_path / 'one.json'}", "--no-wait")
    assert r.exit_code == 1 and "ID 2 done: found at ID 2" in r.stderr      # ID 1 is still skipped
    r = cli(*base, "--redo", "7", "-p", one)
    assert r.exit_code == 2 and "--redo: ID 7 is not in --ids" in r.stderr


# -- watch and check ---------------------------------------------------------------------------

def test_watch_csv_file_and_jsonl(cli, tmp_path):
    out = tmp_path / "w.csv"
    r = cli("zap", "watch", "present-position", "present-voltage", "--ids", "1,2", "--count", "3",
            "-p", "sim://zap?ids=1,2", "-o", str(out))
    assert r.exit_code == 0 and r.stdout == ""
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 6 and list(rows[0]) == ["time", "t", "poll", "id", "present-position", "present-voltage",
                                                "errors", "status", "rtt_ms"]
    assert rows[0]["present-voltage"] == "120"
    assert "3 polls in" in r.stderr and "wire limit" in r.stderr and "ID 1 3/3" in r.stderr
    r = cli("zap", "watch", "moving", "--ids", "1", "--count", "2", "-p", "sim://zap?ids=1")
    assert [x["moving"] for x in jsonl(r.stdout)] == [0, 0]


def test_watch_until_and_faults(cli):
    r = cli("zap", "watch", "present-position", "--ids", "1,2", "--until", "moving==0",
            "--retries", "0", "-p", "sim://zap?ids=1,2&faults=2:silent/1")
    assert r.exit_code == 0, r
    rows = jsonl(r.stdout)
    assert rows[1]["status"] == "no-reply" and rows[-1]["status"] == "ok" and "condition met" in r.stderr
    r = cli("zap", "watch", "present-position", "--ids", "1,5", "--count", "2", "-p", "sim://zap?ids=1")
    assert r.exit_code == 3 and "no reply from ID 5" in r.stderr and len(jsonl(r.stdout)) == 4


@pytest.mark.parametrize("args,message", [
    (("nope",), "unknown name 'nope'"),
    (("present-position", "--until", "bogus==1"), "unknown field 'bogus'"),
    (("present-position", "--until", "moving=0"), "expected FIELD OP NUMBER"),
    (("present-position", "--count", "2", "--duration", "1"), "--count and --duration"),
])
def test_watch_bad_input(cli, args, message):
    r = cli("zap", "watch", *args, "--sim")
    assert (r.exit_code, r.stdout) == (2, "") and message in r.stderr


def test_check_exit_codes(cli, rig):
    r = cli("zap", "check", "--ids", "1", *rig.option, "-p", rig.url("ids=1&speed=4"))
    assert r.exit_code == 0, r
    voltage = "skipped" if rig.protocol == "modbus" else "pass"    # the 17Lf's map gives no voltage limits
    assert [x["verdict"] for x in jsonl(r.stdout)] == ["pass"] * 2 + [voltage] + ["pass"] * 5
    r = cli("zap", "check", "--ids", "1,2", *rig.option, "-p", rig.url("ids=1,2&speed=4&faults=2:stuck"), "-f", "csv")
    assert r.exit_code == 1 and "ID 2 failed a check" in r.stderr
    r = cli("zap", "check", "--ids", "1", "--no-move", *rig.option, "-p", rig.url("ids=1&faults=1:overload"))
    assert r.exit_code == 5 and "ID 1 reports error bits" in r.stderr
    assert jsonl(r.stdout)[3] == {"id": 1, "check": "errors", "verdict": "error", "value": "overload", "limit": None,
                                  "detail": jsonl(r.stdout)[3]["detail"]}


def test_moves_and_writes_need_consent_on_a_real_port(cli, tmp_path):
    f = tmp_path / "f.json"
    f.write_text('{"format":"zkzap-fleet/1","actuators":{"1":{"stored":{"speed-limit":5}}}}')
    dev = str(tmp_path / "ttyUSB9")          # a real-port name: refused before it is opened
    for args in (("check", "--ids", "1"), ("setup", "--ids", "1", "--state", str(tmp_path / "s.json")),
                 ("apply", str(f))):
        r = cli("zap", *args, "-p", dev)
        assert (r.exit_code, r.stdout) == (2, ""), r
        assert "--yes" in r.stderr
    assert not os.path.exists(tmp_path / "s.json")


def test_error_bits_give_exit_5_after_the_data(cli, buses):
    a, _, tmp = buses
    f = str(tmp / "fleet.json")
    r = cli("zap", "backup", "--ids", "1-3", "-p", a, "-o", f)
    assert r.exit_code == 0
    low = "sim://zap?ids=1,2,3&voltage=5"
    r = cli("zap", "apply", f, "-p", low)
    assert r.exit_code == 5 and "ID 1 reports error 0x01" in r.stderr
    rows = jsonl(r.stdout)
    assert len(rows) == 5 and all(x["status"] == "verified" and x["errors"] == ["input-voltage"] for x in rows)
    out = tmp / "low.json"
    r = cli("zap", "backup", "--ids", "1", "-p", low, "-o", str(out))
    assert r.exit_code == 5 and json.loads(out.read_text())["actuators"]["1"]["errors"] == ["input-voltage"]


def test_apply_through_line_faults(cli, buses):
    a, _, tmp = buses
    f = str(tmp / "fleet.json")
    cli("zap", "backup", "--ids", "1-3", "-p", a, "-o", f)
    # a corrupted and a truncated reply are retried; the writes still read back
    r = cli("zap", "apply", f, "-p", "sim://zap?ids=1,2,3&faults=2:corrupt/1,3:truncate/2")
    assert r.exit_code == 0, r
    assert [x["status"] for x in jsonl(r.stdout)] == ["verified"] * 5
    # a reply that stays corrupted after the retries: exit 6 before any write
    r = cli("zap", "apply", f, "--retries", "1", "-p", "sim://zap?ids=1,2,3&faults=3:corrupt")
    assert (r.exit_code, r.stdout) == (6, "") and "ID 3: garbled reply" in r.stderr


# -- summaries that say what they left out ------------------------------------------------------

def test_a_plan_names_the_differences_it_does_not_write(cli, tmp_path):
    dst = make_bus(tmp_path / "dst.json", ids="1")
    fleet_file = tmp_path / "fleet.json"
    assert cli("zap", "backup", "--ids", "1", "-p", dst, "-o", str(fleet_file)).exit_code == 0
    doc = json.loads(fleet_file.read_text())
    doc["actuators"]["1"]["stored"].update({"baud-rate": 16, "feedback-return-mode": 2})
    fleet_file.write_text(json.dumps(doc))
    fleet_file = str(fleet_file)
    r = cli("zap", "apply", fleet_file, "-p", dst, "--plan")
    assert r.exit_code == 0 and jsonl(r.stdout) == []
    assert "nothing to write" in r.stderr and "2 differences not written" in r.stderr, r
    assert "ID 1 baud-rate (32 on the bus, 16 in the file)" in r.stderr
    assert "ID 1 feedback-return-mode (1 on the bus, 2 in the file)" in r.stderr
    assert "--only NAME --force writes them" in r.stderr
    r = cli("zap", "apply", fleet_file, "-p", dst, "--skip", "speed-limit")
    assert r.exit_code == 0 and "nothing to write" in r.stderr and "2 differences not written" in r.stderr


def test_setup_no_wait_has_its_own_status_for_more_to_do(cli, tmp_path):
    state = str(tmp_path / "setup.json")
    args = ("zap", "setup", "--ids", "1-3", "--state", state, "--find-ids", "0-3", "--find-baud", "57600",
            "--no-wait")
    codes = []
    for n in range(3):
        new = make_bus(tmp_path / f"new{n}.json", ids="0")          # the next factory-fresh actuator
        codes.append(cli(*args, "-p", new).exit_code)
    assert codes == [8, 8, 0]                                      # more to do, more to do, done
    r = cli(*args, "-p", make_bus(tmp_path / "none.json", ids="0"))
    assert r.exit_code == 0 and "every ID of 1-3 is done" in r.stderr
    r = cli(*args, "-p", make_bus(tmp_path / "empty.json", ids="9"), "--redo", "2", "--find-ids", "0")
    assert r.exit_code == 1 and "no actuator answers" in r.stderr  # a failure is not "more to do"


def test_backup_and_diff_find_what_scan_finds_at_every_baud(cli, tmp_path):
    bus = "sim://zap?ids=1,2@115200&clock=virtual"       # the census at each rate in no time
    out = tmp_path / "fleet.json"
    r = cli("zap", "backup", "--scan", "--ids", "0-9", "-b", "57600,115200", "-p", bus, "-o", str(out))
    assert r.exit_code == 0, r
    doc = json.loads(out.read_text())
    assert {k: v["baud"] for k, v in doc["actuators"].items()} == {"1": 57600, "2": 115200}
    r = cli("zap", "backup", "-p", bus)                              # 57600 only, as scan
    assert r.exit_code == 0 and sorted(json.loads(r.stdout)["actuators"]) == ["1"]
    r = cli("zap", "backup", "--scan", "--ids", "0-3", "-b", "all", "-p", bus)      # -b all, as scan
    assert r.exit_code == 0 and sorted(json.loads(r.stdout)["actuators"]) == ["1", "2"]
    r = cli("zap", "diff", str(out), "bus", "--ids", "1,2", "-b", "57600,115200", "-p", bus)
    assert (r.exit_code, r.stdout) == (0, ""), r


@pytest.mark.parametrize("args", [["backup", "-o", "{tmp}/x.json"], ["diff", "{tmp}/f.json", "bus"]],
                         ids=["backup", "diff"])
def test_a_bus_where_two_actuators_share_an_id_is_refused(cli, rig, tmp_path, args):
    (tmp_path / "f.json").write_text(cli("zap", "backup", "--ids", "1", *rig.option, "--sim").stdout)
    r = cli("zap", *[a.format(tmp=tmp_path) for a in args], *rig.option, "-p", rig.url("ids=1,4,4"))
    assert (r.exit_code, r.stdout) == (1, "")
    assert "ID 4 at 57600 baud: two actuators answer to this ID" in r.stderr and "set-id" in r.stderr
    assert not (tmp_path / "x.json").exists()


def test_watch_names_the_collision_of_two_actuators_with_one_id(cli):
    r = cli("zap", "watch", "present-position", "--ids", "1,4", "--count", "1", "-p", "sim://zap?ids=1,4,4")
    assert r.exit_code == 6 and "every reply was garbled" in r.stderr and "collision" in r.stderr
    rows = jsonl(r.stdout)
    assert [(x["id"], x["status"]) for x in rows] == [(1, "ok"), (4, "bad-reply")]


def test_setup_brings_every_actuator_to_one_baud_rate(cli, rig, tmp_path):
    state = str(tmp_path / "setup.json")
    code = {b: c for c, b in rig.map.baud_codes.items()}[115200]
    new = rig.bus(tmp_path / "new.json", ids=str(rig.factory))              # factory fresh, at 57600
    args = ("zap", "setup", "--ids", "4", "--state", state, "--find-ids", "0-7", "--set-baud", "115200", "--no-wait")
    r = cli(*args, *rig.option, "-p", new)
    assert r.exit_code == 0, r
    assert f"ID 4 done: found at ID {rig.factory}, 57600 baud; now at 115200 baud" in r.stderr
    assert state_of(tmp_path / "new.json")[4]["baud-rate"] == code
    r = cli("zap", "load", "id", "--id", "4", "-b", "115200", *rig.option, "-p", new)    # answers there
    assert (r.exit_code, r.stdout.strip()) == (0, "4"), r
    if rig.protocol == "ir":
        # ID 4 answers at 115200 already: the new actuator keeps its ID (at the new rate), never a second ID 4
        clash = rig.bus(tmp_path / "clash.json", ids=f"{rig.factory},4@115200")
        r = cli(*args, "--find-baud", "57600", "--state", str(tmp_path / "s2.json"), "-p", clash)
        assert r.exit_code == 1 and "ID 4 answers as well" in r.stderr, r
        assert sorted(state_of(tmp_path / "clash.json")) == [rig.factory, 4]


def test_several_buses_backed_up_diffed_and_applied_at_once(cli, tmp_path, rig):
    """Two buses, each with its own ID 1, read on a thread each; the backup names each bus, and
    a diff and an apply take it bus by bus onto two other buses named in a machine file (the
    file's protocol is theirs: diff and apply are given none)."""
    left = rig.bus(tmp_path / "l.json", ids="1,2", settings={1: {"speed-limit": 500}})
    right = rig.bus(tmp_path / "r.json", ids="1,3", settings={1: {"speed-limit": 600}, 3: {"acceleration": 33}})
    two = tmp_path / "two.json"
    r = cli("zap", "backup", *rig.option, "-p", left, "-p", right, "-o", str(two))
    assert r.exit_code == 0 and "4 actuators on 2 buses" in r.stderr, r
    doc = json.loads(two.read_text())
    assert {b["port"]: b["ids"] for b in doc["buses"].values()} == {left: [1, 2], right: [1, 3]}
    assert "actuators" not in doc and doc["buses"][right]["actuators"]["1"]["stored"]["speed-limit"] == 600
    # the same machine's settings onto two fresh buses, named in the file
    fresh = {n: rig.bus(tmp_path / f"{n}2.json", ids=ids) for n, ids in (("left", "1,2"), ("right", "1,3"))}
    doc["buses"] = {"left": dict(doc["buses"][left], port=fresh["left"]),
                    "right": dict(doc["buses"][right], port=fresh["right"])}
    machine = tmp_path / "machine.json"
    machine.write_text(json.dumps(doc))
    r = cli("zap", "diff", str(machine), "bus", "--buses", "all")
    assert r.exit_code == 1, r
    assert sorted((x["bus"], x["id"], x["register"], x["a"]) for x in jsonl(r.stdout)) == [
        ("left", 1, "speed-limit", 500), ("right", 1, "speed-limit", 600), ("right", 3, "acceleration", 33)]
    r = cli("zap", "apply", str(machine), "-p", fresh["left"])          # one bus given: the file has two
    assert (r.exit_code, r.stdout) == (2, "") and "keeps its actuators per bus" in r.stderr, r
    r = cli("zap", "apply", str(machine), "--buses", "all")
    assert r.exit_code == 0, r
    assert sorted((x["bus"], x["id"], x["status"]) for x in jsonl(r.stdout)) == [
        ("left", 1, "verified"), ("right", 1, "verified"), ("right", 3, "verified")]
    assert state_of(tmp_path / "right2.json")[1]["speed-limit"] == 600
    assert state_of(tmp_path / "left2.json")[1]["speed-limit"] == 500
    r = cli("zap", "diff", str(machine), "bus", "--buses", "left,right")
    assert (r.exit_code, r.stdout) == (0, ""), r
    r = cli("zap", "diff", str(machine), "bus", "-p", fresh["left"])     # a single port: refused, not half a diff
    assert (r.exit_code, r.stdout) == (2, ""), r
    other = "ir" if rig.protocol == "modbus" else "modbus"     # the file's buses speak its protocol only
    r = cli("zap", "watch", "present-position", "--buses", "all", "--fleet", str(machine), "-c", "1",
            "--protocol", other)
    assert (r.exit_code, r.stdout) == (2, "") and f"speak the {rig.protocol} protocol" in r.stderr, r
