"""api.fleet against the in-process bus simulator: documents, diffs, minimal-write plans,
interrupted applies and the guided setup."""

import json

import pytest

from zkzap.api import fleet
from zkzap.codec import zap
from zkzap.codec.permissions import FORCE
from zkzap.errors import NoReply, PermissionNeeded, UsageError
from zkzap.link.zap_bus import open_bus
from zkzap.sim.zap_actuators import Actuator

R = zap.REGISTER_BY_NAME


@pytest.fixture
def bus_of():
    opened = []

    def make(ids="1,2,3", **opts):
        opts.setdefault("clock", "virtual")          # a census's 1.5 s horizon in no time
        q = "&".join(f"{k}={v}" for k, v in opts.items())
        bus = open_bus(f"sim://zap?ids={ids}" + (f"&{q}" if q else ""), 57600)
        opened.append(bus)
        return bus

    yield make
    for b in opened:
        b.close()


def stores(bus, since=0):
    """Writes the simulated actuators heard since index ``since``: Store Data packets (IR), Write
    Multiple Registers frames (Modbus RTU)."""
    if fleet.regmap_of(bus).protocol == "modbus":
        return [p for p in list(bus.port.device.received)[since:] if p[1] == 0x10]
    return [p for p in list(bus.port.device.received)[since:] if p[5] == 0xF3]


@pytest.fixture(params=["ir", "modbus"])
def proto_bus(request):
    """bus_of over each protocol family (the 12Lf's IR, the 17Lf's Modbus RTU)."""
    opened = []

    def make(ids="1,2,3"):
        q = "&clock=virtual" + ("&protocol=modbus" if request.param == "modbus" else "")
        bus = open_bus(f"sim://zap?ids={ids}{q}", 57600, protocol=request.param)
        opened.append(bus)
        return bus

    yield make
    for b in opened:
        b.close()


def configured(bus):
    dev = bus.port.device
    dev.actuator(1).set("speed-limit", 500)
    dev.actuator(1).set("acceleration", 40)
    dev.actuator(2).set("current-limit", 600)
    dev.actuator(3).set("long-stroke-limit", 3000)
    dev.actuator(3).set("alarm-led", 1)
    return 5


# -- documents ---------------------------------------------------------------------------------

def test_backup_document_sections_and_identity(bus_of):
    bus = bus_of()
    configured(bus)
    doc = fleet.read_bus(bus, [1, 2, 3])
    assert doc["format"] == fleet.FORMAT and doc["zkzap"] and doc["time"].endswith("Z")
    e1 = doc["actuators"]["1"]
    assert e1["model"] == 0xA112 and e1["firmware"] == 21 and e1["baud"] == 57600
    assert e1["stored"]["speed-limit"] == 500 and e1["stored"]["id"] == 1
    assert "goal-speed" in e1["volatile"] and "present-voltage" in e1["read-only"]
    # every register of the map, each in the section of its memory
    names = {n for s in fleet.SECTIONS for n in e1[s]}
    assert names == {r.name for r in zap.REGISTERS}
    assert set(e1["stored"]) == {r.name for r in zap.REGISTERS if r.memory == "NV"}


@pytest.mark.parametrize("fmt", ["json", "toml", "yaml"])
def test_formats_round_trip(bus_of, fmt):
    doc = fleet.read_bus(bus_of(), [1, 2])
    text = fleet.dumps(doc, fmt)
    assert fleet.loads(text, fmt, "x") == doc
    assert set(fleet.check_document(fleet.loads(text, fmt, "x"))) == {1, 2}


def test_yaml_is_read_by_pyyaml_too(bus_of):
    yaml = pytest.importorskip("yaml")
    doc = fleet.read_bus(bus_of(), [1])
    assert yaml.safe_load(fleet.dumps(doc, "yaml")) == doc


def test_yaml_hand_edits_are_read_by_the_safe_loader():
    pytest.importorskip("yaml")
    text = ("# hand edited\n---\nformat: zkzap-fleet/1\nactuators:\n  '7':   # the gripper\n"
            "    model: 0x0C4C\n    stored:\n      speed-limit: 600  # slower\n      led-unused: ~\n")
    doc = fleet.loads(text, "yaml", "f.yaml")
    assert doc["actuators"]["7"]["model"] == 0x0C4C
    assert doc["actuators"]["7"]["stored"] == {"speed-limit": 600, "led-unused": None}
    with pytest.raises(fleet.DocumentError, match=r"^f.yaml:2: mapping values are not allowed here"):
        fleet.loads("a:\n  b: c: 2\n", "yaml", "f.yaml")
    with pytest.raises(fleet.DocumentError, match=r"^f.yaml:2: key 'a' is given twice"):
        fleet.loads("a: 1\na: 2\n", "yaml", "f.yaml")
    with pytest.raises(fleet.DocumentError, match=r"^f.yaml: actuators.7.stored: expected an object"):
        fleet.check_document(fleet.loads("format: zkzap-fleet/1\nactuators:\n  7:\n    stored:\n      - 1\n",
                                         "yaml", "f.yaml"), "f.yaml")


def _doc(entry, key="1"):
    return {"format": fleet.FORMAT, "actuators": {key: entry}}


@pytest.mark.parametrize("entry,key,message", [
    ({"stored": {"speed-limt": 5}}, "1", r"actuators\.1\.stored\.speed-limt: unknown register; did you mean"),
    ({"stored": {"speed-limit": 5000}}, "1", r"actuators\.1\.stored\.speed-limit: 5000 is out of range; allowed 0..1023"),
    ({"stored": {"goal-speed": 5}}, "1", r"goal-speed is a volatile register, not stored"),
    ({"volatile": {"present-position": 5}}, "1", r"present-position is a read-only register"),
    ({"stored": {"baud-rate": 33}}, "1", r"baud-rate: 33 is not allowed"),
    ({"stored": {"alarm-led": 30}}, "1", r"stored\.alarm-led: 30 is not allowed; allowed bits 0 \(input voltage\), "
                                         r"5 \(overload\): 0, 1, 32, 33"),
    ({"volatile": {"led": 9}}, "1", r"volatile\.led: 9 is out of range"),
    ({"stored": {"id": 4}}, "1", r"stored\.id: 4 differs from the actuator's key 1"),
    ({"stored": {"speed-limit": "fast"}}, "1", r"'fast' is not an integer"),
    ({"stored": {"speed-limit": True}}, "1", r"True is not an integer"),
    ({}, "300", r"actuators\.300: '300' is not an actuator ID"),
    ({}, "abc", r"actuators\.abc: 'abc' is not an actuator ID"),
    ({"colour": 1}, "1", r"actuators\.1\.colour: unknown key"),
    ({"baud": 1234}, "1", r"actuators\.1\.baud: 1234 is not an actuator baud rate"),
])
def test_bad_documents_name_file_and_key(entry, key, message):
    with pytest.raises(fleet.DocumentError, match=message) as e:
        fleet.check_document(_doc(entry, key), "fleet.json")
    assert str(e.value).startswith("fleet.json: ")
    assert e.value.code == 2


def test_bad_document_format():
    with pytest.raises(fleet.DocumentError, match="format: missing"):
        fleet.check_document({"actuators": {}}, "f")
    with pytest.raises(fleet.DocumentError, match="actuators: missing or empty"):
        fleet.check_document({"format": fleet.FORMAT}, "f")
    with pytest.raises(UsageError, match="unknown file type '.txt'"):
        fleet.format_of("fleet.txt")


# -- diff and plan -----------------------------------------------------------------------------

def test_diff_lists_only_differences(bus_of):
    a, b = bus_of(), bus_of()
    n = configured(a)
    ea = fleet.check_document(fleet.read_bus(a, [1, 2, 3]))
    eb = fleet.check_document(fleet.read_bus(b, [1, 2]))
    rows = fleet.diff(ea, eb)
    regs = [(r["id"], r["register"]) for r in rows]
    assert regs == [(1, "speed-limit"), (1, "acceleration"), (2, "current-limit"), (3, "(actuator)")]
    assert rows[2] == {"id": 2, "register": "current-limit", "address": 0x34, "memory": "NV", "a": 600, "b": 800,
                       "unit": "mA", "equal": False}
    assert rows[3]["a"] == "present" and rows[3]["b"] == "absent"
    assert n == 5
    every = fleet.diff(ea, ea, compare="all", everything=True)
    assert every and all(r["equal"] for r in every)
    volts = next(r for r in every if r["register"] == "present-voltage")
    assert volts["unit"] == "0.1 V" and volts["memory"] == "R"


def test_backup_of_bus_a_applied_to_fresh_bus_b_takes_exactly_the_minimal_writes(proto_bus):
    a, b = proto_bus(), proto_bus()
    changed = configured(a)
    entries = fleet.check_document(json.loads(json.dumps(fleet.read_bus(a, [1, 2, 3]))))
    mark = len(b.port.device.received)
    writes, unchanged = [], 0
    for ident, entry in entries.items():
        values, _ = fleet.PROCEDURES.read_map(b, ident)
        w, u = fleet.plan(entry, ident, values)
        writes += w
        unchanged += u
    assert len(writes) == changed
    done = []
    fleet.execute(b, writes, done)
    assert [w.status for w in done] == ["verified"] * changed
    assert len(stores(b, mark)) == changed                    # one Store Data per changed setting, no more
    after = fleet.check_document(fleet.read_bus(b, [1, 2, 3]))
    assert fleet.diff(entries, after) == []
    # a second apply has nothing to do
    for ident, entry in entries.items():
        values, _ = fleet.PROCEDURES.read_map(b, ident)
        assert fleet.plan(entry, ident, values)[0] == []


def test_plan_rules(bus_of):
    bus = bus_of()
    configured(bus)
    entry = fleet.check_document(fleet.read_bus(bus, [1]))[1]
    fresh = Actuator(0, 5)
    current = {r.name: fresh.get(r) for r in zap.REGISTERS}
    w, _ = fleet.plan(entry, 5, current)
    assert {x.register.name for x in w} == {"speed-limit", "acceleration"}     # id never, by default
    w, _ = fleet.plan(entry, 5, current, skip=[R["acceleration"]])
    assert [x.register.name for x in w] == ["speed-limit"]
    w, _ = fleet.plan(entry, 5, dict(current, **{"goal-speed": 700}), only=[R["goal-speed"]])
    assert [(x.register.name, x.old, x.new) for x in w] == [("goal-speed", 700, 1023)]   # volatile: when named
    with pytest.raises(UsageError, match="--only id: .*--force"):
        fleet.plan(entry, 5, current, only=[R["id"]])
    with pytest.raises(UsageError, match="would give bus ID 5 the ID 1"):    # a clone: id is the file's key
        fleet.plan(entry, 5, current, only=[R["id"], R["speed-limit"]], force=True)
    w, _ = fleet.plan(entry, 5, current, only=[R["speed-limit"]], force=True)
    assert [x.register.name for x in w] == ["speed-limit"]
    w, _ = fleet.plan(entry, 1, dict(current, id=5), only=[R["id"], R["speed-limit"]], force=True)
    assert [x.register.name for x in w] == ["speed-limit", "id"]               # id last


def test_an_id_write_through_apply_is_checked_free_like_set_id(proto_bus):
    from zkzap.errors import IdTaken

    bus = proto_bus()
    R = fleet.regmap_of(bus).by_name
    mark = len(bus.port.device.received)
    taken = fleet.Write(1, 1, R["id"], 1, 2)
    done = []
    with pytest.raises(IdTaken):
        fleet.execute(bus, [taken], done, allow="identity")
    assert done == [] and taken.status == "refused" and stores(bus, mark) == []
    assert sorted(a.ident for a in bus.port.device.actuators) == [1, 2, 3]
    free = fleet.Write(1, 1, R["id"], 1, 7)
    fleet.execute(bus, [free], done, allow="identity")
    assert (free.status, free.read_back) == ("verified", 7) and done == [free]
    assert sorted(a.ident for a in bus.port.device.actuators) == [2, 3, 7]
    with pytest.raises(UsageError, match="--only: .*read-only"):
        fleet.registers_option(["present-position"], "--only")
    with pytest.raises(UsageError, match="unknown name"):
        fleet.registers_option(["nope"], "--only")


def test_assignments():
    entries = {1: None, 2: None}
    assert fleet.assignments(entries) == [(1, 1), (2, 2)]
    assert fleet.assignments(entries, mapping={1: 5, 2: 6}) == [(1, 5), (2, 6)]
    assert fleet.assignments(entries, ids=[1], to=[3, 4, 5]) == [(1, 3), (1, 4), (1, 5)]
    with pytest.raises(UsageError, match="--to clones one actuator, but 2"):
        fleet.assignments(entries, to=[3])
    with pytest.raises(UsageError, match="--ids: ID 9 is not in the file"):
        fleet.assignments(entries, ids=[9])
    with pytest.raises(UsageError, match="bus ID 2 would get the settings of two"):
        fleet.assignments(entries, mapping={1: 2})


def test_interrupted_apply_says_what_was_done_and_a_rerun_finishes(bus_of):
    a, b = bus_of(), bus_of()
    configured(a)
    entries = fleet.check_document(fleet.read_bus(a, [1, 2, 3]))

    def planned():
        out = []
        for ident, entry in entries.items():
            out += fleet.plan(entry, ident, fleet.PROCEDURES.read_map(b, ident)[0])[0]
        return out

    writes = planned()
    dev = b.port.device

    def fail_after_first(w):
        dev.inject(2, "silent")           # ID 2 stops answering: its read-back will fail

    done = []
    with pytest.raises(NoReply):
        fleet.execute(b, writes, done, on_write=fail_after_first)
    assert [(w.target, w.register.name, w.status) for w in done] == [
        (1, "speed-limit", "verified"), (1, "acceleration", "verified"), (2, "current-limit", "sent")]
    dev.clear_faults()
    rest = planned()
    assert [(w.target, w.register.name) for w in rest] == [(3, "long-stroke-limit"), (3, "alarm-led")]
    mark = len(dev.received)
    fleet.execute(b, rest, [])
    assert len(stores(b, mark)) == 2
    assert fleet.diff(entries, fleet.check_document(fleet.read_bus(b, [1, 2, 3]))) == []


# -- setup -------------------------------------------------------------------------------------

def test_setup_one_actuator_at_a_time_with_config_and_resume(bus_of, tmp_path):
    src = bus_of("1")
    src.port.device.actuator(1).set("speed-limit", 321)
    config = fleet.check_document(fleet.read_bus(src, [1]))[1]
    bus = bus_of("0")
    dev = bus.port.device
    # four new actuators on the bench, all factory ID 0; the third one sits at 115200 baud
    bench = [Actuator(0, 0), Actuator(1, 0), Actuator(2, 0, 115200), Actuator(3, 0)]
    wired = []
    state_path = str(tmp_path / "setup.json")
    state = fleet.SetupState.load(state_path, [1, 2, 3, 4])
    for n, target in enumerate(state.pending()[:2]):
        dev.actuators = [bench[n]]                  # "connect the next actuator alone"
        wired.append(bench[n])
        found = fleet.find_alone(bus, range(0, 6), (57600, 115200), prefer=[0, target])
        state.mark_done(target, fleet.setup_one(bus, target, found=found, config=config))
    # a crash here; a second run resumes with ID 3
    state2 = fleet.SetupState.load(state_path, [1, 2, 3, 4])
    assert state2.pending() == [3, 4] and state2.done[1]["from_id"] == 0
    for n, target in enumerate(state2.pending(), start=2):
        dev.actuators = [bench[n]]
        found = fleet.find_alone(bus, range(0, 6), (57600, 115200), prefer=[0, target])
        state2.mark_done(target, fleet.setup_one(bus, target, found=found, config=config))
    assert [a.ident for a in bench] == [1, 2, 3, 4]
    assert all(a.get("speed-limit") == 321 for a in bench)
    assert state2.done[3]["from_baud"] == 115200
    assert json.load(open(state_path))["done"]["4"]["config"] == 1


def test_setup_refuses_two_actuators(bus_of):
    bus = bus_of("0,5")
    with pytest.raises(fleet.TwoAnswer, match=r"2 actuators answer at 57600 baud \(IDs 0, 5\)"):
        fleet.find_alone(bus, range(0, 8), (57600,))
    bus = bus_of("0,0")
    bus.port.device.actuators[1].supply = 6.0    # its replies carry another error byte: they collide
    with pytest.raises(fleet.TwoAnswer, match="garbled reply from ID 0"):
        fleet.find_alone(bus, range(0, 3), (57600,))
    bus = bus_of("9")
    with pytest.raises(fleet.NotFound, match="no actuator answers"):
        fleet.find_alone(bus, range(0, 3), (57600, 19200))


def test_port_lost_during_apply(bus_of):
    from zkzap.errors import PortError

    a, b = bus_of(), bus_of()
    configured(a)
    entries = fleet.check_document(fleet.read_bus(a, [1, 2, 3]))
    writes = []
    for ident, entry in entries.items():
        writes += fleet.plan(entry, ident, fleet.PROCEDURES.read_map(b, ident)[0])[0]
    done = []
    with pytest.raises(PortError):
        fleet.execute(b, writes, done, on_write=lambda w: b.port.close() if len(done) == 3 else None)
    assert [w.status for w in done] == ["verified"] * 3
    assert writes[3].status == "sending" and writes[4].status == "planned"


def test_return_mode_changes_are_protected_and_keep_the_link_usable(bus_of):
    a, b = bus_of(), bus_of()
    a.port.device.actuator(1).set("feedback-return-mode", 2)
    a.port.device.actuator(2).set("feedback-return-mode", 0)
    a.port.device.actuator(1).set("speed-limit", 600)
    entries = fleet.check_document(fleet.read_bus(a, [1, 3]))
    entries[2] = fleet.check_document({"format": fleet.FORMAT, "actuators": {"2": fleet.entry_from_values(
        {"feedback-return-mode": 0, "id": 2}, baud=57600)}})[2]
    cur = {i: fleet.PROCEDURES.read_map(b, i)[0] for i in (1, 2)}
    assert [w.register.name for w in fleet.plan(entries[1], 1, cur[1])[0]] == ["speed-limit"]
    with pytest.raises(UsageError, match="--only feedback-return-mode: .*--force"):
        fleet.plan(entries[1], 1, cur[1], only=[R["feedback-return-mode"]])
    mode = R["feedback-return-mode"]
    writes = (fleet.plan(entries[1], 1, cur[1], only=[R["speed-limit"], mode], force=True)[0]
              + fleet.plan(entries[2], 2, cur[2], only=[mode], force=True)[0])
    assert [w.register.name for w in writes] == ["speed-limit", "feedback-return-mode", "feedback-return-mode"]
    done = []
    with pytest.raises(PermissionNeeded):                   # mode 0 stops the actuator answering: force
        fleet.execute(b, writes, [])
    fleet.execute(b, writes, done, allow=FORCE)
    assert [w.status for w in done] == ["verified", "verified", "unverifiable"]     # mode 0 cannot be read back
    assert b.return_mode == 1 and b.read(3, R["speed-limit"]) == 1023       # the link still talks mode 1
    assert b.port.device.actuator(2).get(mode) == 0 and b.port.device.actuator(1).get(mode) == 2
