"""zkzap.sim: simulators started from Python with typed arguments; the pytest plugin."""

from __future__ import annotations

import subprocess
import sys

import pytest

from zkzap import Bus, Ecu
from zkzap.sim import INSTANCES, start, start_zap, start_zk


@pytest.mark.parametrize("transport", ["inprocess", "pty", "tcp"])
def test_zap_every_transport(transport):
    with start_zap(ids=[3, (4, 115200)], return_mode=2, transport=transport) as sim:
        prefix = {"inprocess": "sim://zap?instance=", "pty": "/dev/", "tcp": "socket://127.0.0.1:"}[transport]
        assert sim.url.startswith(prefix)
        with Bus(sim, return_mode=2) as bus:
            assert bus.store(3, "goal-speed", 700) is not None      # mode 2 acknowledges writes
            assert bus.load(3, "goal-speed") == 700
            if transport != "tcp":                                  # a socket has no baud rate
                assert bus.ping(4) is None                          # it talks at 115200
        assert sim.device.actuator(3).get("goal-speed") == 700
    assert sim.key not in INSTANCES


@pytest.mark.parametrize("transport", ["pty", "tcp"])
def test_zk_server_reaches_another_process(transport):
    with start_zk(speed=10, transport=transport) as sim:
        p = subprocess.run([sys.executable, "-m", "zkzap", "zk", "monitor", "-p", sim.url, "--count", "3",
                            "-f", "jsonl"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert len(p.stdout.splitlines()) == 3


def test_typed_arguments_are_checked():
    with pytest.raises(ValueError, match="protocol_version"):
        start_zk(protocol_version=99)
    with pytest.raises(ValueError, match="baud"):
        start_zap(baud=1234)
    with pytest.raises(ValueError, match="kind"):
        start("can")


def test_faults_typed_and_as_text():
    with start_zap(ids=[1, 2], faults=["2:silent"]) as sim, Bus(sim, retries=0) as bus:
        assert bus.ping(1) is not None and bus.ping(2) is None
        sim.inject(1, "overload")
        assert bus.echo(1, check=False).errors == ["overload"]


def test_fixtures_from_the_plugin(zap_sim, zk_sim):
    """The pytest11 plugin's fixtures: what a user's own test suite gets."""
    with Bus(zap_sim) as bus:
        assert bus[1].present_voltage == 12.0
    with Ecu(zk_sim) as ecu:
        assert next(iter(ecu.status()))["kind"] == "status"


def test_plugin_is_registered_by_entry_point():
    from importlib.metadata import entry_points

    names = {ep.value for ep in entry_points(group="pytest11")}
    assert "zkzap.pytest_plugin" in names
