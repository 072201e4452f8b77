"""Every command that controls the engine leaves it safe when a signal ends it, at any moment.

The commands are found by walking the command tree: those that declare ``--abort`` (the shared
option of engine sessions), kept when what they would send controls the engine — the codec's
``ControlFrame.controls_engine`` on their own dry run. Each runs as a real subprocess against
the ECU simulator on a pty and gets a signal that ends a program (every one of
``zkzap.signals.STOP_SIGNALS`` is sent to some command: SIGINT, SIGTERM, SIGHUP, SIGQUIT,
SIGUSR1, ...) at a seeded moment (during start-up, or after its first record); afterwards the
ECU itself is asked, through its status frames, what state it was left in: standby or stop,
never run. The shell running an engine command is one more command of the walk.
"""

from __future__ import annotations

import random
import signal
import subprocess
import threading
import time

import pytest

from zkzap import Ecu, signals
from zkzap.api.session import abort_frames
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
#: The shell, running an engine command from its stdin: one more engine-controlling command.
SHELL = (("shell", "zk"), None)
RUNS = ENGINE_COMMANDS + [SHELL]
#: Every named signal that ends a program, and one real-time signal; each run of the walk gets
#: one in turn, and ``zk send control --for`` gets every one (test_every_signal_...).
SIGNALS = [s for s in signals.STOP_SIGNALS if not hasattr(signal, "SIGRTMIN") or s < signal.SIGRTMIN
           if s != getattr(signal, "SIGBREAK", None)]
if hasattr(signal, "SIGRTMIN"):
    SIGNALS.append(signal.SIGRTMIN + 2)


def _signal_for(path):
    return SIGNALS[(RUNS.index(next(r for r in RUNS if r[0] == path)) + 5) % len(SIGNALS)]


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


def test_the_signals_are_every_one_that_ends_a_program():
    assert {signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1, signal.SIGUSR2,
            signal.SIGALRM} <= set(SIGNALS)


@pytest.mark.parametrize("path,cmd", RUNS, ids=[" ".join(p) for p, _ in RUNS])
def test_a_signal_at_any_moment_leaves_the_ecu_in_standby_or_stop(cli, start_sim, tmp_path, path, cmd):
    values = _values(tmp_path)
    if cmd is None:                                             # the shell, fed one engine command
        argv = list(path)
        line = "send control --state run --throttle 30 --for 0 --yes -f jsonl\n"
    else:
        args = invocation(cmd, values, values)
        if not _controls_engine(cli, path, cmd, args):
            pytest.skip(f"{' '.join(path)} with these values does not control the engine")
        argv = [*path, *invocation(cmd, values, dict(values, for_s="0", yes=True, fmt="jsonl"))]
        line = None
    rng = random.Random(" ".join(path))                         # seeded: the same moments every run
    _signal_ends_it_safely(start_sim, tmp_path, argv, _signal_for(path), rng, line)


@pytest.mark.parametrize("sig", SIGNALS, ids=[signals.name(s) for s in SIGNALS])
def test_every_signal_that_ends_a_program_ends_the_session_safely(start_sim, tmp_path, sig):
    argv = ["zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "0", "--yes", "-f", "jsonl"]
    _signal_ends_it_safely(start_sim, tmp_path, argv, sig, random.Random(signals.name(sig)), None)


def test_an_ecu_that_reads_the_abort_late_is_left_in_standby(start_sim, tmp_path):
    """The simulator is not scheduled while the session sends its abort and exits: once it runs
    again it first sends the status frames of the time before it read the abort (still run),
    then standby. The ECU is judged by the state it settles in, and the capture shows that
    nothing but the abort left the port after it."""
    argv = ["zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "0", "--yes", "-f", "jsonl"]
    _signal_ends_it_safely(start_sim, tmp_path, argv, signal.SIGTERM, random.Random("lagging"), None, lagging=True)


def spawn(argv, line=None, *, stdout=subprocess.DEVNULL, env=None):
    """``zkzap ARGV`` as a process (fed ``line`` on a stdin kept open, the shell's way), killed
    by a watchdog after 60 s; returns it and the watchdog (to cancel)."""
    proc = subprocess.Popen([executable("zkzap"), *argv], stdin=subprocess.DEVNULL if line is None else subprocess.PIPE,
                            stdout=stdout, stderr=subprocess.PIPE, text=True, env=env or clean_env())
    if line is not None:
        proc.stdin.write(line)                                  # kept open: the shell waits for more
        proc.stdin.flush()
    watchdog = threading.Timer(60, proc.kill)
    watchdog.daemon = True
    watchdog.start()
    return proc, watchdog


def _signal_ends_it_safely(start_sim, tmp_path, argv, sig, rng, line, *, lagging=False):
    """Run ``argv`` (fed ``line`` on a stdin kept open), send ``sig`` at a moment ``rng`` picks,
    and check the exit status, the frames sent after the abort and the state the ECU was left
    in. ``lagging``: the simulator's process is stopped from just before the signal until the
    ECU is opened again (a loaded machine that did not schedule it: it reads the abort late)."""
    capture = tmp_path / "wire.pcapng"
    early = rng.random() < 0.3 and not lagging                  # during start-up, or once it runs
    moment = rng.uniform(0.0, 0.3 if early else 0.6)
    url, sim = start_sim(["zk", "--pty", "--speed", "10"])
    opened = (lambda: sim.send_signal(signal.SIGCONT)) if lagging else None
    env = clean_env(PYTHONPROFILEIMPORTTIME="1") if early else clean_env()
    proc, watchdog = spawn([*argv, "--capture", str(capture), "-p", url], line, env=env)
    try:
        if early:
            # from the moment the zkzap package is imported its handlers are in place (before
            # that the interpreter itself is starting up): a moment of the start-up
            while proc.stderr.readline().split("|")[-1].strip() != "zkzap":
                pass
        else:
            _until_in_control(capture, proc)                    # ready: it controls the engine
        time.sleep(moment)
        if lagging:
            sim.send_signal(signal.SIGSTOP)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    if lagging and proc.returncode != signals.status(sig):
        sim.send_signal(signal.SIGCONT)                         # failing: the simulator runs on to its end
    assert proc.returncode == signals.status(sig), (signals.name(sig), moment, err)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    if sig in signals.INTERRUPT_SIGNALS and not early:          # Ctrl-C in control: the rundown is recorded
        assert "rundown recorded" in err or "recording the rundown" in err, (signals.name(sig), moment, err)
    _nothing_but_the_abort_after_it(capture, (signals.name(sig), moment, err))
    states = _left_in(url, opened=opened)
    assert _confirmed(states), (signals.name(sig), moment, states, err)


#: The host's state commands (status ID 1's SW state) an ECU may be left in.
SAFE = ("standby", "stop")
#: Every frame an abort sends (``zkzap.api.session.abort_frames``: both kinds, any version, with
#: the pump-off): the only frames that may leave the port once the abort went out.
ABORT_FRAMES = {f for kind in SAFE for version in (None, 3) for pump in (False, True)
                for f in abort_frames(kind, version, pump=pump)}


def _nothing_but_the_abort_after_it(capture, why):
    """The capture of a session a signal ended: once an abort frame went out after a frame
    that controlled the engine, every frame the host sent is an abort frame (no control
    frame with the old setpoint, from whatever thread or loop, follows the abort)."""
    from zkzap.link.capture import CaptureFrames
    from zkzap.link.pcapng import OUTBOUND

    if not capture.exists():
        return                           # ended during start-up, before its port was opened
    frames = CaptureFrames(str(capture), "zk", "control")
    sent = [(t, f) for t, d, f in frames if d == OUTBOUND]
    frames.reader.close()
    controlled = aborted = None
    for t, f in sent:
        if f in ABORT_FRAMES:
            if controlled is not None and aborted is None:
                aborted = t
        elif aborted is not None:
            pytest.fail(f"{f.hex(' ')} sent at {t:.3f} s, after the abort at {aborted:.3f} s: {why}")
        elif zk.ControlFrame(f).controls_engine:
            controlled = t
    if controlled is not None:
        assert aborted is not None, f"the engine was controlled (at {controlled:.3f} s) and no abort went out: {why}"


#: How many status ID 1 frames in a row must say standby or stop.
CONFIRM = 8


def _confirmed(states) -> bool:
    return len(states) >= CONFIRM and all(s in SAFE for s in states[-CONFIRM:])


def _left_in(url, *, within=10.0, opened=None):
    """The host states the ECU reports (status ID 1), read until :data:`CONFIRM` of them in a
    row are standby or stop (at most ``within`` s; ``opened()`` is called once the port is
    open): what it was left in. The first ones may be a loaded machine's backlog: a simulator that saw the abort late (its process was not
    scheduled) first sends the status frames of the model time before it, which still say
    run; the abort's effect follows them. A state command that is not the abort (a run frame
    after it) keeps the ECU in run for good, and that is never confirmed."""
    states = []
    end = time.monotonic() + within
    with Ecu(url, baud=115200) as ecu:
        if opened is not None:
            opened()
        for rec in ecu.status(duration=within):
            if rec.id == 1:
                states.append(rec.sw_state_name)
                if _confirmed(states):
                    break
            if time.monotonic() > end:
                break
    return states or ["silent"]


def test_a_terminal_that_hangs_up_leaves_the_ecu_in_standby_and_the_status_of_sighup():
    """The terminal closes under the live dashboard (ssh dropped): SIGHUP ends the session with
    its abort, and the writes to the dead terminal afterwards (the dashboard's last frame, the
    summary) end the program quietly with 129."""
    import os
    import pty

    from zkzap.sim import start_zk

    with start_zk(speed=10, transport="pty") as ecu:
        master, slave = pty.openpty()
        proc = subprocess.Popen([executable("zk"), "send", "control", "--state", "run", "--throttle", "30",
                                 "--for", "0", "--yes", "-p", ecu.url], stdin=slave, stdout=slave, stderr=slave,
                                start_new_session=True, env=clean_env())
        os.close(slave)
        try:
            end = time.monotonic() + 30
            while True:
                with ecu.lock:
                    last = ecu.device._last_frame
                if last is not None and zk.ControlFrame(last).controls_engine:
                    break
                assert proc.poll() is None and time.monotonic() < end, "never controlled the engine"
                time.sleep(0.02)
            time.sleep(0.5)
            os.read(master, 1 << 20)
            os.close(master)                                    # the terminal goes away
            proc.send_signal(signal.SIGHUP)                     # what the kernel sends its session
            assert proc.wait(timeout=30) == 129
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        with ecu.lock:
            assert ecu.device.effective_sw() == "standby"
