"""mightyZAP transactions against the actuator-bus simulator over a real pty.

    python benchmarks/transactions.py                  # 57600 baud, 2000 round trips
    python benchmarks/transactions.py --baud 115200 --count 5000

Starts ``zkzap sim zap --ids 1,2,3`` (it prints its pty on the first line), then measures:

1. Load Data round trips per second through the library (``ZapBus.transact`` of a
   present-position read, the command ``zap load`` runs), next to the wire's own limit at
   that baud rate (request + reply bytes, 10 bits each);
2. ``zap load present-position`` as a command, one process per read (what a shell loop gets);
3. full 0..253 ``zap scan`` runs at one baud rate, as commands (best of ``--scans``), against
   four buses: 2 ms actuators (target <= 1.5 s), some actuators answering 18 ms late (target
   <= 3 s), every actuator at a 20 ms turnaround with bytes 1 ms apart, and the same behind an
   echoing adapter; each must find every actuator.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick, until_ready  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))


def tool(name):
    exe = os.path.join(os.path.dirname(sys.executable), name)
    return [exe] if os.path.exists(exe) else [sys.executable, "-m", "zkzap"]


def start_sim(ids, baud, extra=()):
    env = dict(os.environ, NO_COLOR="1")
    p = subprocess.Popen(tool("zkzap") + ["sim", "zap", "--ids", ids, "-b", str(baud), *extra],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    port = p.stdout.readline().strip()
    if not port:
        p.kill()
        raise SystemExit(f"simulator did not start: {p.stderr.read()[-500:]}")
    return p, port


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baud", type=int, default=57600)
    ap.add_argument("--count", type=int, default=2000, help="library round trips")
    ap.add_argument("--commands", type=int, default=20, help="zap load processes")
    ap.add_argument("--scans", type=int, default=3, help="scans per bus (best kept)")
    ap.add_argument("--scan-ids", default="0-253", help="the IDs a scan probes (the targets are for 0-253)")
    ap.add_argument("--timeout", type=float, default=None,
                    help="reply timeout of the round trips in seconds (default: derived from the baud rate)")
    add_quick(ap, count=20, commands=2, scans=1, scan_ids="0-10", timeout=1.0)
    args = ap.parse_args(argv)

    from zkzap.codec import zap
    from zkzap.link.port import open_port
    from zkzap.link.zap_bus import ZapBus

    sim, port = start_sim("1,2,3", args.baud)
    try:
        pkt = zap.load(1, "present-position")
        with ZapBus(open_port(port, args.baud, timeout=0), timeout=args.timeout) as bus:
            until_ready(lambda: bus.transact(pkt))              # warm up, once it answers
            t0 = time.perf_counter()
            for _ in range(args.count):
                bus.transact(pkt)
            dt = time.perf_counter() - t0
        wire = (len(pkt) + 9) * 10 / args.baud
        print(f"Load Data round trips over a pty at {args.baud} baud: {args.count / dt:,.0f}/s "
              f"({dt / args.count * 1e3:.2f} ms each; the wire alone needs {wire * 1e3:.2f} ms)")

        env = dict(os.environ, NO_COLOR="1")
        cmd = tool("zap") + ["load", "present-position", "--id", "1", "-p", port, "-b", str(args.baud)]
        if args.timeout is not None:
            cmd += ["--timeout", str(args.timeout)]
        t0 = time.perf_counter()
        for _ in range(args.commands):
            subprocess.run(cmd, check=True, capture_output=True, env=env)
        dt = time.perf_counter() - t0
        print(f"zap load as a command: {args.commands / dt:.1f}/s ({dt / args.commands * 1e3:.0f} ms per process)")

    finally:
        sim.terminate()
        sim.wait(5)
    buses = [
        ("2 ms actuators", "1,2,3,50,100,200,253", (), 1.5),
        ("some 18 ms late", "1,2,3,50,100,200,253", ("--fault", "3:delay=18", "--fault", "100:delay=18",
                                                     "--fault", "253:delay=18"), 3.0),
        ("all 20 ms, bytes 1 ms apart", "1,2,3,50,100,200,253", ("--turnaround", "20", "--gap", "1"), None),
        ("the same, echoing adapter", "1,2,3,50,100,200,253", ("--turnaround", "20", "--gap", "1", "--echo"), None),
    ]
    env = dict(os.environ, NO_COLOR="1")
    for label, ids, extra, target in buses:
        sim, port = start_sim(ids, args.baud, extra)
        try:
            cmd = tool("zap") + ["scan", "-p", port, "-b", str(args.baud), "--ids", args.scan_ids, "-f", "jsonl"]
            best, found = None, []
            for _ in range(args.scans):
                t0 = time.perf_counter()
                r = subprocess.run(cmd, capture_output=True, text=True, env=env)
                dt = time.perf_counter() - t0
                got = [line for line in r.stdout.splitlines() if line.strip()]
                if best is None or dt < best:
                    best, found = dt, got
            lo, _, hi = args.scan_ids.partition("-")
            want = sum(1 for i in ids.split(",") if int(lo) <= int(i) <= int(hi or lo))
            full = args.scan_ids == "0-253"
            verdict = "" if target is None or not full else \
                f"  target <= {target:g} s {'met' if best <= target else 'NOT met'}"
            print(f"{'full 0..253' if full else 'IDs ' + args.scan_ids} scan at {args.baud} baud, {label}: "
                  f"{best:.2f} s, {len(found)}/{want} found{verdict}")
        finally:
            sim.terminate()
            sim.wait(5)
    return 0


if __name__ == "__main__":
    sys.exit(main())
