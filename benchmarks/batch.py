#!/usr/bin/env python3
"""One process for many transactions: ``zap batch`` against the same loop on the API and against
separate ``zap load`` commands, side by side over one real pty to the bus simulator.

    python benchmarks/batch.py [--count 1000] [--commands 50] [--baud 57600] [--json]

Starts ``zkzap sim zap --ids 1 --pty`` and measures, in one run:

1. the API loop: ``Bus(pty).load(1, "present-position")`` ``--count`` times in this process;
2. ``zap batch FILE -p PTY`` with ``--count`` lines ``load present-position --id 1`` (one
   process: its start-up, the check of every line, and the lines);
3. ``--commands`` separate ``zap load present-position --id 1 -p PTY`` processes.

The API loop and the batch run interleaved ``--rounds`` times (medians). Prints reads per
second of each and the ratios, with the targets: the API loop and the batch each >= 0.9 x the
line's limit (the request and the reply on the wire plus a 12Lf's 2 ms turnaround, one
transaction after the other), batch >= 0.9 x the API loop, batch >= 10 x separate commands.
Exits 1 when a target is missed (``--no-fail`` to only report).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick, until_ready  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))

TARGETS = {"api/line": 0.9, "batch/line": 0.9, "batch/api": 0.9, "batch/commands": 10.0}


def tool(name):
    exe = os.path.join(os.path.dirname(sys.executable), name)
    return [exe] if os.path.exists(exe) else [sys.executable, "-m", "zkzap"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=1000, help="reads in the API loop and lines in the batch")
    ap.add_argument("--commands", type=int, default=50, help="separate zap load processes")
    ap.add_argument("--baud", type=int, default=57600)
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds of API loop and batch (medians)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-fail", action="store_true")
    ap.add_argument("--timeout", type=float, default=None,
                    help="reply timeout in seconds (default: derived from the baud rate)")
    add_quick(ap, count=20, commands=2, rounds=1, no_fail=True, timeout=1.0)
    args = ap.parse_args(argv)

    from zkzap import Bus

    env = dict(os.environ, NO_COLOR="1")
    sim = subprocess.Popen(tool("zkzap") + ["sim", "zap", "--ids", "1", "--pty", "--baud", str(args.baud)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    port = sim.stdout.readline().strip()
    if not port:
        sim.kill()
        raise SystemExit(f"simulator did not start: {sim.stderr.read()[-500:]}")
    with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as f:
        f.write("load present-position --id 1\n" * args.count)
    apis, batches = [], []
    timeout = ["--timeout", str(args.timeout)] if args.timeout is not None else []
    try:
        for _ in range(args.rounds):            # interleaved: both see the same machine load
            with Bus(port, baud=args.baud, timeout=args.timeout) as bus:
                until_ready(lambda: bus.load(1, "present-position"))      # warm up, once it answers
                t0 = time.perf_counter()
                for _ in range(args.count):
                    bus.load(1, "present-position")
                apis.append(args.count / (time.perf_counter() - t0))
            t0 = time.perf_counter()
            p = subprocess.run(tool("zap") + ["batch", f.name, "-p", port, "-b", str(args.baud), *timeout],
                               capture_output=True, text=True, env=env)
            took = time.perf_counter() - t0
            if p.returncode != 0 or len(p.stdout.splitlines()) != args.count:
                raise SystemExit(f"batch failed (exit {p.returncode}): {p.stderr[-500:]}")
            batches.append(args.count / took)
        api, batch = statistics.median(apis), statistics.median(batches)

        t0 = time.perf_counter()
        for _ in range(args.commands):
            subprocess.run(tool("zap") + ["load", "present-position", "--id", "1", "-p", port, "-b",
                                          str(args.baud), *timeout], capture_output=True, check=True, env=env)
        commands = args.commands / (time.perf_counter() - t0)
    finally:
        os.unlink(f.name)
        sim.terminate()
        sim.wait(5)

    # the line's limit: Load Data (9 bytes) and its reply (9 bytes) on the wire, plus the turnaround
    line = 1.0 / ((9 + 9) * 10 / args.baud + 0.002)
    ratios = {"api/line": api / line, "batch/line": batch / line, "batch/api": batch / api,
              "batch/commands": batch / commands}
    ok = all(ratios[k] >= v for k, v in TARGETS.items())
    if args.json:
        print(json.dumps({"reads_per_s": {"api": api, "batch": batch, "commands": commands, "line": line},
                          "ratio": ratios,
                          "target": TARGETS, "ok": ok}))
    else:
        print(f"{args.count} reads of present-position at {args.baud} baud over a pty "
              f"(the line's limit: {line:.1f} reads/s)")
        print(f"  API loop (one process)          {api:8.1f} reads/s")
        print(f"  zap batch (one process)         {batch:8.1f} reads/s")
        print(f"  separate zap load ({args.commands:4d} runs)   {commands:8.1f} reads/s")
        for k, v in TARGETS.items():
            print(f"  {k:16} ratio {ratios[k]:7.2f}  (target >= {v})  {'ok' if ratios[k] >= v else 'MISSED'}")
    return 0 if ok or args.no_fail else 1


if __name__ == "__main__":
    sys.exit(main())
