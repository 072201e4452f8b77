"""The console asks for the library's permissions, decided on the typed frames: stored writes,
factory resets and engine starts on a real port only; a direct write of an identity register, an
undocumented address or value on every port. What a page grants is the library's allow=."""

from __future__ import annotations

import pytest

from zkzap import Bus, Permission, PermissionNeeded
from zkzap.codec import permissions, zap, zk
from zkzap.sim import start_zap
from zkzap.web.consent import ENGINE, FORCE, MOVE, STORED, Needed, Policy, force_values, needs_force

REAL, SIM = "socket://127.0.0.1:9", "sim://zap?ids=1"


def needs(fn, *args):
    try:
        fn(*args)
    except Needed as e:
        return e.permission
    return None


@pytest.mark.parametrize("url,packet,granted,expected", [
    (REAL, zap.store(1, "goal-position", 100), (), None),                  # volatile: never asks
    (REAL, zap.store(1, "long-stroke-limit", 3000), (), STORED),
    (REAL, zap.store(1, "long-stroke-limit", 3000), (STORED,), None),
    (SIM, zap.store(1, "long-stroke-limit", 3000), (), None),
    ("loop://", zap.factory_reset(1, False, False), (), None),
    (REAL, zap.factory_reset(1, False, False), (), STORED),
    (SIM, zap.store(1, "protocol-type", 1), (), FORCE),                   # force on every port
    (SIM, zap.store(1, "feedback-return-mode", 2), (), None),            # a stored setting, not identity
    (REAL, zap.store(1, "feedback-return-mode", 2), (), STORED),
    (SIM, zap.store(1, "feedback-return-mode", 0), (), FORCE),           # Echo only: it stops answering
    (REAL, zap.store(1, "feedback-return-mode", 0), (), FORCE),
    (REAL, zap.store(1, "feedback-return-mode", 0), (FORCE,), STORED),
    (SIM, zap.factory_reset(1, True, False), (), FORCE),                   # it moves to ID 0
    (REAL, zap.factory_reset(1, True, False), (FORCE,), STORED),
    (REAL, zap.store(1, "id", 5, force=True), (), FORCE),                 # force is asked first
    (REAL, zap.store(1, "id", 5, force=True), (FORCE,), STORED),
    (SIM, zap.store(1, 0x97, 1, force=True), (), FORCE),                  # IR Robot's undocumented lock
    (REAL, zap.symmetric_store("goal-position", [(1, 10), (2, 20)])[0], (), None),
])
def test_mightyzap_writes(url, packet, granted, expected):
    assert needs(Policy(url).zap_packets, [packet], granted) == expected


def test_grants_are_the_library_permissions():
    assert Policy.allow(()) == Permission.NONE
    assert Policy.allow((STORED,)) == Permission.STORED | Permission.FACTORY
    assert Policy.allow((FORCE,)) == permissions.FORCE and Policy.allow((ENGINE,)) == Permission.ENGINE
    assert Policy("loop://").simulated and not Policy(REAL).simulated
    assert [r.name for r in zap.REGISTERS if needs_force(r)] == ["protocol-type"]   # id, baud: the checked ways
    # the values the page marks are the library's rule, from the same table
    assert {r.name: force_values(r) for r in zap.REGISTERS if force_values(r)} == \
        {"protocol-type": [0, 1], "feedback-return-mode": [0]}


def test_the_page_marks_exactly_what_the_library_refuses():
    """For every writable register and every value of its domain the page knows (its choices, or
    the ends of its range), the page marks force exactly where the library refuses the write
    without it (PermissionNeeded naming a FORCE permission): one table for both."""
    for reg in zap.REGISTERS:
        if not reg.writable or reg.name in ("id", "baud-rate"):
            continue
        for value in (sorted(reg.choices) if reg.choices else sorted({reg.lo, reg.hi})):
            pkt = zap.store(1, reg, value)
            asked = needs(Policy(SIM).zap_packets, [pkt], ())
            assert (asked == FORCE) == needs_force(reg, value) == (value in force_values(reg)), (reg.name, value)


def test_the_library_refusal_is_the_question():
    """A write the bus refuses (nothing sent) becomes the page's question; granted, it goes out."""
    policy = Policy(SIM)
    with start_zap(ids=[1]) as sim, Bus(sim) as bus:
        with pytest.raises(PermissionNeeded) as refused:
            bus.store(1, "protocol-type", 1)
        asked = policy.needed(refused.value)
        assert asked.permission == FORCE and "protocol-type" in asked.text and "Tick 'force'" in asked.text
        bus.store(1, "protocol-type", 1, allow=policy.allow((FORCE,)))
        assert bus.load(1, "protocol-type") == 1
    with pytest.raises(Needed) as e, Policy(REAL).asking():
        permissions.require(zap.Command(zap.store(1, "long-stroke-limit", 3000)).needs(), Permission.NONE,
                            simulated=False, frame=zap.store(1, "long-stroke-limit", 3000))
    assert e.value.permission == STORED and "long-stroke-limit" in e.value.text


def test_check_moves():
    assert needs(Policy(REAL).zap_check, [1, 2], True, ()) == MOVE
    assert needs(Policy(REAL).zap_check, [1], False, ()) is None
    assert needs(Policy(SIM).zap_check, [1], True, ()) is None


@pytest.mark.parametrize("url,frame,expected", [
    (REAL, zk.ControlFrame.build("control", sw="run", throttle_pct=20).frame, ENGINE),
    (REAL, zk.ControlFrame.build("mode", sw="run", rpm_factor=2).frame, ENGINE),
    (REAL, zk.ControlFrame.build("control", sw="standby", throttle_pct=0).frame, None),
    (REAL, zk.ControlFrame.build("action", param="rate-50hz").frame, None),
    (REAL, zk.ControlFrame.build("action", param="test-pump").frame, ENGINE),
    ("sim://zk", zk.ControlFrame.build("control", sw="run", throttle_pct=20).frame, None),
])
def test_zk_frames(url, frame, expected):
    assert needs(Policy(url).zk_frames, [frame], ()) == expected
