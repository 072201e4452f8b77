"""An output that stops taking data never holds up engine control, nor the abort.

Every engine-controlling command of the walk (tests/e2e/test_engine_ends_safe.py: the commands
that declare ``--abort`` and control the engine, and the shell running one) runs against an
in-process ECU simulator served on a pty, with one of its outputs stalled — stdout a pipe
nobody reads, or ``-o``, ``--raw-log`` or ``--capture`` a FIFO nobody opens (each run gets one
in turn). Once the engine is under control and the output is stalled, a signal that ends a
program is sent (in turn too): the ECU must receive the abort (standby or stop, throttle 0)
within its loss-of-signal time (the dead-man time of the ECU itself), and the command must
end, saying what it could not write.
"""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import time

import pytest

from zkzap import signals
from zkzap.codec import zk
from zkzap.sim import start_zk
from zkzap.sim.zk_ecu import LOSS_OF_SIGNAL_S

from cmdargs import has, invocation

from .test_engine_ends_safe import RUNS, _controls_engine, _values, spawn

#: The stalls, in turn: the option (None: stdout) and what it names.
STALLS = [None, "--output", "--raw-log", "--capture"]
SIGS = [signal.SIGTERM, signal.SIGHUP, signal.SIGINT, signal.SIGQUIT, signal.SIGUSR1]


def _stall_for(index, cmd):
    have = [s for s in STALLS if s is None or s == "--capture" or cmd is None and s == "--raw-log"
            or (cmd is not None and has(cmd, s.lstrip("-").replace("-", "_")))]
    return have[index % len(have)]


def _aborted_since(ecu, n) -> bool:
    """An abort (ID 1, standby or stop, throttle 0) among the control frames after the first ``n``."""
    with ecu.lock:
        recs = list(ecu.device.received)[n:]
    return any(r.get("id") == 1 and r.get("state") in ("standby", "stop") and not r.get("throttle_pct")
               for r in recs)


def _controlled(ecu) -> bool:
    """The last control frame the ECU received controls the engine."""
    with ecu.lock:
        last = ecu.device._last_frame
    return last is not None and zk.ControlFrame(last).controls_engine


def _until_controlled(ecu, proc, timeout=30.0):
    end = time.monotonic() + timeout
    while not _controlled(ecu):
        assert proc.poll() is None, f"exited {proc.returncode}: {proc.stderr.read()}"
        assert time.monotonic() < end, "the engine never came under control"
        time.sleep(0.02)


def _abort_follows(ecu, act, what):
    """Do ``act()``; the ECU must receive the abort within its loss-of-signal time."""
    with ecu.lock:
        n = len(ecu.device.received)
    start = time.monotonic()
    act()
    while not _aborted_since(ecu, n):
        took = time.monotonic() - start
        assert took < LOSS_OF_SIGNAL_S, f"no abort within {took:.2f} s of {what}"
        time.sleep(0.005)


@pytest.mark.parametrize("index", range(len(RUNS)), ids=[" ".join(p) for p, _ in RUNS])
def test_a_stalled_output_never_holds_up_the_abort(cli, tmp_path, index):
    path, cmd = RUNS[index]
    values = _values(tmp_path)
    stall = _stall_for(index, cmd)
    sig = SIGS[index % len(SIGS)]
    fifo = tmp_path / "stalled.fifo"
    os.mkfifo(fifo)
    if cmd is None:                                             # the shell, fed one engine command
        argv = list(path)
        line = "send control --state run --throttle 30 --for 0 --yes -f jsonl" + (
            f" {stall} {fifo}" if stall in ("--output", "--raw-log") else "") + "\n"
    else:
        args = invocation(cmd, values, values)
        if not _controls_engine(cli, path, cmd, args):
            pytest.skip(f"{' '.join(path)} with these values does not control the engine")
        argv = [*path, *invocation(cmd, values, dict(values, for_s="0", yes=True, fmt="jsonl"))]
        if stall in ("--output", "--raw-log"):
            argv += [stall, str(fifo)]
        line = None
    if stall == "--capture":
        argv += ["--capture", str(fifo)]
    with start_zk(speed=10, transport="pty") as ecu:
        proc, watchdog = spawn([*argv, "-p", ecu.url], line,
                               stdout=subprocess.PIPE if stall is None else subprocess.DEVNULL)
        if stall is None:
            fcntl.fcntl(proc.stdout.fileno(), fcntl.F_SETPIPE_SZ, 4096)   # full after a few records
        try:
            _until_controlled(ecu, proc)
            time.sleep(0.5)            # stdout's pipe is full, or the FIFO's open is waiting
            assert proc.poll() is None, proc.stderr.read()
            _abort_follows(ecu, lambda: proc.send_signal(sig), signals.name(sig))
            if line is not None:
                proc.stdin.close()       # the shell's input ends (Ctrl-C took it back to its prompt)
            proc.wait(timeout=30)        # stdout unread to the end: communicate() would read it
            err = proc.stderr.read()
        finally:
            watchdog.cancel()
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        # Ctrl-C stops the shell's command and the shell goes on, to the end of its input
        assert proc.returncode == (0 if cmd is None and sig == signal.SIGINT else signals.status(sig)), err
        assert "Traceback" not in err
        assert "stalled" in err and "writes not made" in err, err
        with ecu.lock:
            assert ecu.device.effective_sw() in ("standby", "stop")


@pytest.mark.parametrize("index", range(len(RUNS)), ids=[" ".join(p) for p, _ in RUNS])
def test_a_closed_stdout_ends_the_session_with_its_abort(cli, tmp_path, index):
    """The reader of stdout goes away (``| head -1``; SIGPIPE, which Python turns into EPIPE):
    the session ends quietly (exit 0), and the abort reaches the ECU within its loss-of-signal
    time of the close."""
    path, cmd = RUNS[index]
    if path == ("zk", "batch"):
        pytest.skip("a batch's line writes to the batch, which writes its record when the line ends")
    values = _values(tmp_path)
    if cmd is None:
        argv, line = list(path), "send control --state run --throttle 30 --for 0 --yes -f jsonl\n"
    else:
        args = invocation(cmd, values, values)
        if not _controls_engine(cli, path, cmd, args):
            pytest.skip(f"{' '.join(path)} with these values does not control the engine")
        argv, line = [*path, *invocation(cmd, values, dict(values, for_s="0", yes=True, fmt="jsonl"))], None
    with start_zk(speed=10, transport="pty") as ecu:
        proc, watchdog = spawn([*argv, "-p", ecu.url], line, stdout=subprocess.PIPE)
        try:
            _until_controlled(ecu, proc)
            proc.stdout.read(1)
            _abort_follows(ecu, proc.stdout.close, "the close")      # the reader goes away
            if line is not None:
                proc.stdin.close()
            proc.wait(timeout=30)
            err = proc.stderr.read()
        finally:
            watchdog.cancel()
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        assert "Traceback" not in err
        assert proc.returncode in (0, 130) if cmd is None else proc.returncode == 0, err
