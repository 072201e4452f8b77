"""The console's consent rules are the command line's: stored writes, ID and baud changes and
engine starts ask on a real port only; a setting that changes how an actuator is reached needs
force on every port."""

from __future__ import annotations

import pytest

from zkzap.codec import zap, zk
from zkzap.web.consent import ENGINE, FORCE, MOVE, STORED, Needed, Policy

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
    (SIM, zap.store(1, "feedback-return-mode", 2), (FORCE,), None),
    (REAL, zap.store(1, "id", 5, force=True), (FORCE,), STORED),
    (REAL, zap.symmetric_store("goal-position", [(1, 10), (2, 20)])[0], (), None),
])
def test_mightyzap_writes(url, packet, granted, expected):
    assert needs(Policy(url).zap_packets, [packet], granted) == expected


def test_identity_changes_and_check_moves():
    assert needs(Policy(SIM).zap_identity, "ID", ()) == FORCE
    assert needs(Policy(SIM).zap_identity, "ID", (FORCE,)) is None
    assert needs(Policy(REAL).zap_identity, "baud rate (to 115200)", (FORCE,)) == STORED
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
