"""The permission policy through the public API: one decision on the typed frame
(zap.Command.needs, zk.ControlFrame.needs), enforced where every frame goes out (ZapBus.command,
ZkLink.write), so every public write keeps the command line's rules.

On a real port (here: a simulator served over a pty, opened by its path like any device) a
stored write, a factory reset or system write and an engine start need consent; everywhere,
the simulator too, identity changes, undocumented addresses, instructions and values, partial
registers and their broadcasts need force. Refused frames are never sent.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st

from zkzap import Bus, Ecu, Permission, PermissionNeeded
from zkzap.api import fleet
from zkzap.codec import zap, zk
from zkzap.codec.permissions import CONSENT, FORCE
from zkzap.sim import start_zap, start_zk


@pytest.fixture(scope="module")
def real():
    """A bus on a device path (a pty): nothing waives a permission here."""
    with start_zap(ids=[1, 7], transport="pty") as sim:
        yield sim


@pytest.fixture
def bus(real):
    with Bus(real.url) as b:
        yield b


#: (what the user wrote, the call, the permissions it needs on a real port)
WRITES = [
    ("bus.store(1, 'id', 7)", lambda b, a: b.store(1, "id", 7, allow=a), Permission.STORED | Permission.IDENTITY),
    ("bus[7].id = 5", lambda b, a: b[7].store("id", 5, allow=a), Permission.STORED | Permission.IDENTITY),
    ("bus.store(254, 'id', 3)", lambda b, a: b.store(254, "id", 3, allow=a),
     Permission.STORED | Permission.IDENTITY | Permission.BROADCAST),
    ("bus.store(1, 'baud-rate', 16)", lambda b, a: b.store(1, "baud-rate", 16, allow=a),
     Permission.STORED | Permission.IDENTITY),
    ("bus.store(1, 'protocol-type', 1)", lambda b, a: b.store(1, "protocol-type", 1, allow=a),
     Permission.STORED | Permission.IDENTITY),
    ("bus.store(1, 'long-stroke-limit', 3000)", lambda b, a: b.store(1, "long-stroke-limit", 3000, allow=a),
     Permission.STORED),
    ("bus.send(1, 'speed-limit', 500)", lambda b, a: b.send(1, "speed-limit", 500, allow=a), Permission.STORED),
    ("bus.store(1, 0x05, 3)", lambda b, a: b.store(1, 0x05, 3, allow=a), Permission.UNDOCUMENTED | Permission.STORED),
    ("bus.store(1, 0x87, 100)", lambda b, a: b.store(1, 0x87, 100, allow=a), Permission.PARTIAL),
    ("bus.store(1, 'lock', 1)", lambda b, a: b.store(1, "lock", 1, allow=a), Permission.UNDOCUMENTED),
    ("bus.command(system-write)", lambda b, a: b.command(zap.packet(1, 0xF9, b"\x01"), allow=a), Permission.FACTORY),
    ("bus.command(alarm-led 30)", lambda b, a: b.command(zap.packet(1, zap.STORE_DATA, b"\x11\x1e"), allow=a),
     Permission.UNDOCUMENTED | Permission.STORED),
    ("bus.factory_reset(1)", lambda b, a: b.factory_reset(1, allow=a), Permission.FACTORY),
    ("bus.factory_reset(254)", lambda b, a: b.factory_reset(254, allow=a), Permission.FACTORY | Permission.BROADCAST),
    ("bus.sync_move(id)", lambda b, a: b.sync_move({1: 5, 7: 6}, "id", allow=a), Permission.STORED | Permission.IDENTITY),
]


@pytest.mark.parametrize("what,call,needs", WRITES, ids=[w for w, _, _ in WRITES])
def test_every_write_needs_its_permissions_and_sends_nothing_without(bus, what, call, needs):
    for p in (p for p in Permission if p and p & needs):
        sent = bus.link.sent
        with pytest.raises(PermissionNeeded) as e:
            call(bus, needs & ~p)                 # everything but one of them
        assert e.value.missing == p and e.value.code == 2 and p.name in str(e.value)
        assert bus.link.sent == sent, f"{what}: sent without {p.name}"


@pytest.mark.parametrize("what,call,needs", WRITES[5:8], ids=[w for w, _, _ in WRITES[5:8]])
def test_given_the_permissions_the_write_goes_out(bus, what, call, needs):
    sent = bus.link.sent
    call(bus, needs)
    assert bus.link.sent > sent


def test_a_simulator_waives_consent_never_force():
    with start_zap(ids=[1], virtual=True) as sim, Bus(sim) as b:      # set-id's census in no time
        b.store(1, "long-stroke-limit", 3000)                  # STORED: waived
        b.factory_reset(1)                                     # FACTORY: waived
        with pytest.raises(PermissionNeeded) as e:
            b.store(1, "id", 7)
        assert e.value.missing == Permission.IDENTITY and e.value.simulated
        with pytest.raises(PermissionNeeded):
            b[1].id = 5                                         # attribute writes: the same rule
        assert b.set_id(1, 3) == 3                              # the checked way: set_id


def test_the_session_and_the_call_give_permissions(real):
    with Bus(real.url, allow=Permission.STORED) as b:
        b.store(1, "long-stroke-limit", 3001)
        assert b.allow == Permission.STORED
        with pytest.raises(PermissionNeeded):
            b.store(1, "id", 1)
        b.store(1, "id", 1, force=True)                        # force: every FORCE permission
    with Bus(real.url, allow=["stored", "identity"]) as b:     # names read too
        b.store(1, "id", 1)
    with pytest.raises(ValueError, match="unknown permission 'sorted'"):
        Bus(real.url, allow=["sorted"])


def test_set_id_and_set_baud_need_only_the_stored_permission(real):
    with Bus(real.url) as b:
        with pytest.raises(PermissionNeeded) as e:
            b.set_id(7, 8)
        assert e.value.missing == Permission.STORED
    with Bus(real.url, allow=Permission.STORED) as b:
        assert b.set_id(7, 8) == 8
        b.store(8, "id", 7, force=True)                         # back, without a second census
        assert b.load(7, "id") == 7


def test_fleet_writes_keep_the_rules(real):
    with Bus(real.url) as b:
        values, _ = fleet.PROCEDURES.read_map(b.link, 1)
        entry = fleet.check_document(fleet.read_bus(b.link, [1]), "bus")[1]
        entry.values[zap.REGISTER_BY_NAME["speed-limit"]] = values["speed-limit"] - 1
        writes, _ = fleet.plan(entry, 1, values)
        with pytest.raises(PermissionNeeded):
            fleet.execute(b.link, writes, done := [])
        assert done == []                                       # checked whole before the first write
        fleet.execute(b.link, writes, done, allow=Permission.STORED)
        assert [w.status for w in done] == ["verified"]


@pytest.fixture(scope="module")
def loop_bus():
    """A ZapBus on a device path as far as the policy knows (the line itself is a loop)."""
    from zkzap.link.port import open_port
    from zkzap.link.zap_bus import ZapBus

    b = ZapBus(open_port("loop://", 57600, timeout=0.01), retries=0, timeout=0.002, url="/dev/ttyFAKE")
    yield b
    b.close()


@settings(max_examples=150, deadline=None)
@given(ident=st.integers(0, 254), code=st.sampled_from(sorted(zap.INSTRUCTION_BY_CODE) + [0x11, 0x00]),
       params=st.binary(max_size=6), allow=st.sampled_from([Permission.NONE, CONSENT, FORCE, CONSENT | FORCE]))
def test_any_packet_is_sent_exactly_when_its_needs_are_given(loop_bus, ident, code, params, allow):
    pkt = zap.packet(ident, code, params)
    needs = zap.Command(pkt).permissions
    b = loop_bus
    b.allow = allow
    sent = b.sent
    if needs & ~allow:
        with pytest.raises(PermissionNeeded):
            b.command(pkt, check=False, optional=True)
        assert b.sent == sent
    else:
        try:
            b.command(pkt, check=False, optional=True)
        except Exception as e:  # noqa: BLE001 - whatever the line answers: it was sent all the same
            assert not isinstance(e, PermissionNeeded)
        assert b.sent > sent


def test_ecu_engine_starts_need_the_engine_permission_on_a_real_port():
    with start_zk(speed=50, transport="pty") as sim:
        with Ecu(sim.url) as ecu:
            with pytest.raises(PermissionNeeded) as e:
                ecu.send("control", state="run", throttle_pct=30)
            assert e.value.missing == Permission.ENGINE
            with pytest.raises(PermissionNeeded):
                list(ecu.hold("action", 0.1, action="test-pump"))
            with pytest.raises(PermissionNeeded):
                ecu.run_profile([(0, 0, "standby"), (0.2, 30, "run"), (0.4, 0, "standby")])
            assert ecu.sent == 0 and not ecu.controlling          # nothing went out
            ecu.send("control", state="standby")                  # harmless: no permission
            ecu.send("control", state="run", throttle_pct=10, allow=Permission.ENGINE)
        with Ecu(sim.url, allow=Permission.ENGINE) as ecu:
            ecu.send("control", state="run", throttle_pct=10)
    with start_zk(speed=50) as sim, Ecu(sim.url) as ecu:        # sim://: waived
        ecu.send("control", state="run", throttle_pct=10)


def test_the_frame_says_what_it_needs():
    assert zk.ControlFrame.build("control", sw="run", throttle_pct=5).permissions == Permission.ENGINE
    assert zk.ControlFrame.build("control", sw="standby", throttle_pct=0).needs() == {}
    cmd = zap.Command(zap.store(1, "goal-position", 2000))
    assert cmd.needs() == {} and cmd.permissions == Permission.NONE
    assert set(zap.Command(zap.store(1, 0x87, 1)).needs()) == {Permission.PARTIAL}


@settings(max_examples=150, deadline=None)
@given(cmd=st.integers(0, 8), low=st.integers(0, 15), b2=st.integers(0, 255), allow=st.booleans())
def test_any_control_frame_is_sent_exactly_when_its_needs_are_given(cmd, low, b2, allow):
    from zkzap.link.port import open_port
    from zkzap.link.zk_port import ZkLink

    frame = zk.control_frame(cmd, low, b2)
    needs = zk.ControlFrame(frame).permissions
    link = ZkLink(open_port("loop://", 115200, timeout=0.01), "/dev/ttyFAKE",
                  allow=Permission.ENGINE if allow else None)
    try:
        if needs and not allow:
            with pytest.raises(PermissionNeeded):
                link.write(frame)
            assert link.frames_out == 0 and link.read() == b""
        else:
            link.write(frame)
            assert link.frames_out == 1 and link.controlled == zk.ControlFrame(frame).controls_engine
    finally:
        link.close()
