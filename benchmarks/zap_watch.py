"""zap watch: achieved poll rate against the wire limit, over a real pty to the bus simulator.

    python benchmarks/zap_watch.py                       # 57600 baud, 4 actuators, 3 s per case
    python benchmarks/zap_watch.py --baud 115200 --ids 1-8 --seconds 5

Starts ``zkzap sim zap --ids ... --pty`` (it prints its pty on the first line) and runs the
library's poller (:class:`zkzap.api.watch.Watcher`, what ``zap watch`` runs) as fast as it
can, for a few register sets: one register, an adjacent block (present-position .. moving),
and registers far apart (two Loads per ID). The wire limit is the bytes of every Load and
its reply at 10 bits a byte plus the actuators' 2 ms turnaround per transaction. Target:
achieved >= 0.8x the wire limit. The simulator hears a command the moment it arrives over the
pty (it does not wait out the command's own bytes), so the achieved rate can exceed the wire
limit; the ratio to the simulator's own timing (reply bytes plus turnaround) is printed too
and shows the host's overhead alone. A last case runs the ``zap watch`` command itself (one
process, JSON Lines to a pipe) and reads its achieved rate from the summary line.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick, until_ready  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))

TARGET = 0.8
CASES = (
    ("one register", ["present-position"]),
    ("adjacent block", ["present-position", "present-current", "moving"]),
    ("far apart (2 Loads)", ["model-number", "present-position"]),
)


def tool(name):
    exe = os.path.join(os.path.dirname(sys.executable), name)
    return [exe] if os.path.exists(exe) else [sys.executable, "-m", "zkzap"]


def start_sim(ids, baud, protocol="ir"):
    env = dict(os.environ, NO_COLOR="1")
    p = subprocess.Popen(tool("zkzap") + ["sim", "zap", "--ids", ids, "--baud", str(baud), "--protocol", protocol],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    port = p.stdout.readline().strip()
    if not port:
        p.kill()
        raise SystemExit(f"simulator did not start: {p.stderr.read()[-500:]}")
    return p, port


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baud", type=int, default=57600)
    ap.add_argument("--ids", default="1-4")
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--timeout", type=float, default=None,
                    help="reply timeout in seconds (default: derived from the baud rate)")
    add_quick(ap, seconds=0.3, timeout=1.0)
    args = ap.parse_args(argv)

    from zkzap.codec import zap
    from zkzap.api.watch import TURNAROUND, Watcher
    from zkzap.link.port import wire_time
    from zkzap.link.port import open_port
    from zkzap.link.zap_bus import ZapBus
    from zkzap.sim.zap_actuators import parse_ids

    ids = [i for i, _ in parse_ids(args.ids)]
    sim, port = start_sim(args.ids, args.baud)
    worst = None
    try:
        with ZapBus(open_port(port, args.baud, timeout=0), timeout=args.timeout) as bus:
            until_ready(lambda: bus.echo(ids[0]))              # warm up, once it answers
            for label, names in CASES:
                regs = [zap.REGISTER_BY_NAME[n] for n in names]
                w = Watcher(bus, ids, regs, duration=args.seconds, retries=2)
                rows = sum(1 for _ in w.rows())
                ratio = w.achieved / w.limit()
                worst = ratio if worst is None else min(worst, ratio)
                bad = sum(h.failed for h in w.health.values())
                model = 1.0 / (len(ids) * sum(wire_time(7 + n, args.baud) + TURNAROUND for _, n, _ in w.reads))
                print(f"{label:22s} {len(ids)} IDs at {args.baud}: {w.achieved:7.1f} polls/s, wire limit "
                      f"{w.limit():7.1f}/s -> {ratio:.2f}x  "
                      f"target >= {TARGET}x {'met' if ratio >= TARGET else 'NOT met'}"
                      f"  (simulator's own timing {w.achieved / model:.2f}x; {rows} rows, {bad} failed reads)")
        env = dict(os.environ, NO_COLOR="1")
        cmd = tool("zap") + ["watch", "present-position", "present-current", "moving", "--ids", args.ids,
                             "--duration", str(args.seconds), "-p", port, "-b", str(args.baud)]
        if args.timeout is not None:
            cmd += ["--timeout", str(args.timeout)]
        t0 = time.perf_counter()
        r = subprocess.run(cmd, capture_output=True, text=True, env=env)
        dt = time.perf_counter() - t0
        m = re.search(r"([\d.]+) polls/s \(.*wire limit ([\d.]+)/s\)", r.stderr)
        if m:
            ratio = float(m.group(1)) / float(m.group(2))
            print(f"{'zap watch (command)':22s} {len(ids)} IDs at {args.baud}: {m.group(1):>7s} polls/s, wire limit "
                  f"{m.group(2):>7s}/s -> {ratio:.2f}x  ({len(r.stdout.splitlines())} rows in {dt:.1f} s with "
                  f"start-up)  target >= {TARGET}x {'met' if ratio >= TARGET else 'NOT met'}")
        else:
            print(f"zap watch failed (exit {r.returncode}): {r.stderr[-300:]}")
    finally:
        sim.terminate()
        sim.wait(5)
    return 0 if worst is not None and (worst >= TARGET or args.quick) else 1


if __name__ == "__main__":
    sys.exit(main())
