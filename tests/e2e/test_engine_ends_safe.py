"""Every command that controls the engine leaves it safe when a signal ends it, at any moment.

The commands are found by walking the command tree: those that declare ``--abort`` (the shared
option of engine sessions), kept when what they would send controls the engine — the codec's
``ControlFrame.controls_engine`` on their own dry run. Each runs as a real subprocess against
the ECU simulator on a pty and gets SIGINT or SIGTERM at a seeded moment (during start-up, or
after its first record); afterwards the ECU itself is asked, through its status frames, what
state it was left in: standby or stop, never run.
"""

from __future__ import annotations

import random
import signal
import subprocess
import threading
import time

import pytest

from zkzap import Ecu
from zkzap.codec import zk

from cmdargs import has, invocation
from cmdtree import commands

from .conftest import clean_env, executable


def _values(tmp_path):
    schedule = tmp_path / "run.csv"
    schedule.write_text("time_s,throttle_pct,state\n0,30,run\n600,0,standby\n")
    batch = tmp_path / "lines.txt"
    batch.write_text("send control --state run --throttle 30 --for 0\n")
    return {"sw": "run", "throttle_pct": "30", "param": "pump-on", "rpm_factor": "3", "target_rpm": "60000",
            "cmd_id": "1", "assignments": ["sw=run", "throttle_pct=300"], "accel_curve": "40",
            "ignition_voltage_v": "3.2", "pressure_hpa": "1013", "schedule": str(schedule), "file": str(batch)}


ENGINE_COMMANDS = [(path, cmd) for path, cmd in commands() if has(cmd, "abort")]


def _controls_engine(cli, path, cmd, args) -> bool:
    """What the command would send, by its own dry run, controls the engine."""
    if not has(cmd, "dry_run"):
        return True                     # a batch: its line above does
    r = cli(*path, *args, "-n", "-f", "jsonl") if path[-1] == "profile" else cli(*path, *args, "-n")
    assert r.exit_code == 0, r
    hexes = [part for line in r.stdout.splitlines() for part in
             (line.split('"frame":"')[1].split('"')[0].split(" + ") if '"frame"' in line else [line])]
    return any(zk.ControlFrame(bytes.fromhex(h)).controls_engine for h in hexes)


def _until_in_control(capture, proc, timeout=30.0):
    """Until the command's --capture holds a frame it sent that controls the engine."""
    from zkzap.link.capture import CaptureFrames
    from zkzap.link.pcapng import OUTBOUND

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            pytest.fail(f"exited {proc.returncode} before controlling the engine: {proc.stderr.read()}")
        try:
            frames = CaptureFrames(str(capture), "zk", "control")
            sent = [f for _, d, f in frames if d == OUTBOUND]
            frames.reader.close()
        except Exception:                                       # not written yet, or half a block
            sent = []
        if any(zk.ControlFrame(f).controls_engine for f in sent):
            return
        time.sleep(0.02)
    pytest.fail(f"no frame controlling the engine within {timeout} s")


def test_the_walk_finds_the_engine_commands():
    names = {" ".join(p) for p, _ in ENGINE_COMMANDS}
    assert {"zk send control", "zk send rpm", "zk profile", "zk batch"} <= names
    assert "zk monitor" not in names and "zk check" not in names


@pytest.mark.parametrize("path,cmd", ENGINE_COMMANDS, ids=[" ".join(p) for p, _ in ENGINE_COMMANDS])
def test_a_signal_at_any_moment_leaves_the_ecu_in_standby_or_stop(cli, start_sim, tmp_path, path, cmd):
    values = _values(tmp_path)
    args = invocation(cmd, values, values)
    if not _controls_engine(cli, path, cmd, args):
        pytest.skip(f"{' '.join(path)} with these values does not control the engine")
    rng = random.Random(" ".join(path))                         # seeded: the same moments every run
    sig = rng.choice([signal.SIGINT, signal.SIGTERM])
    early = rng.random() < 0.3                                  # during start-up, or once it runs
    moment = rng.uniform(0.0, 0.3 if early else 0.6)
    url, _ = start_sim(["zk", "--pty", "--speed", "10"])
    run = invocation(cmd, values, dict(values, for_s="0", yes=True, fmt="jsonl"))
    env = clean_env(PYTHONPROFILEIMPORTTIME="1") if early else clean_env()
    capture = tmp_path / "wire.pcapng"
    proc = subprocess.Popen([executable("zkzap"), *path, *run, "-p", url, "--capture", str(capture)],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, env=env)
    watchdog = threading.Timer(60, proc.kill)
    watchdog.daemon = True
    watchdog.start()
    try:
        if early:
            # from the moment the zkzap package is imported its handlers are in place (before
            # that the interpreter itself is starting up): a moment of the start-up
            while proc.stderr.readline().split("|")[-1].strip() != "zkzap":
                pass
        else:
            _until_in_control(capture, proc)                    # ready: it controls the engine
        time.sleep(moment)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == (130 if sig == signal.SIGINT else 143), (moment, err)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    with Ecu(url, baud=115200) as ecu:                          # what the ECU says it was left in
        state = next(rec for rec in ecu.status() if rec.id == 1).sw_state_name
    assert state in ("standby", "stop"), (moment, err)
