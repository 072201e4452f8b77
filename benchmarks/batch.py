#!/usr/bin/env python3
"""One process for many transactions: ``zap batch`` against the same loop on the API and against
separate ``zap load`` commands, side by side over one real pty to the bus simulator.

    python benchmarks/batch.py [--count 1000] [--commands 50] [--rounds 5] [--baud 57600] [--json]

Starts ``zkzap sim zap --ids 1 --pty`` and measures, in one run:

1. the floor: the rawest loop a host can run on that pty (write the request to the descriptor,
   read until the reply's 9 bytes are in; no framing, no checks), ``--count`` times: what this
   machine, its pty and the simulator allow;
2. the API loop: ``Bus(pty).load(1, "present-position")`` ``--count`` times in this process;
3. ``zap batch FILE -p PTY`` with ``--count`` lines ``load present-position --id 1`` in one
   process, timed two ways: **per transaction** (from its first record to its last, as a
   reader of its output sees them: a record is written while the next line's request is on the
   wire, so the span holds the lines' transactions and nothing else) and **whole run** (the
   process from its start: Python, its imports, the check of every line, then the lines);
4. ``--commands`` separate ``zap load present-position --id 1 -p PTY`` processes.

The floor, the API loop and the batch run interleaved ``--rounds`` times (medians; the spread
of the rounds is printed too). The targets: the API loop and the batch per transaction each
>= 0.9 x the line's limit (the request and the reply on the wire plus a 12Lf's 2 ms turnaround,
one transaction after the other), the batch per transaction >= 0.9 x the API loop, the batch's
whole run >= 10 x separate commands. The batch's whole run against the line's limit is printed
beside them: its start-up is the same 0.1 s whatever the count (``benchmarks/startup.py``
measures it), so that ratio says as much about ``--count`` as about the batch. Exits 1 when a
target is missed (``--no-fail`` to only report).
"""

from __future__ import annotations

import argparse
import json
import os
import select
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


def floor(port, baud, count, timeout=1.0):
    """Load Data round trips per second of the rawest loop on ``port``: the request written to
    the descriptor, the reply read until its 9 bytes are in."""
    import serial

    from zkzap.codec import zap

    pkt = zap.load(1, zap.REGISTER_BY_NAME["present-position"], 2)
    with serial.Serial(port, baud, timeout=0) as s:
        fd = s.fd

        def one():
            os.write(fd, pkt)
            got = 0
            while got < 9:
                if not select.select([fd], [], [], timeout)[0]:
                    raise TimeoutError("no reply")
                got += len(os.read(fd, 64))

        until_ready(one)
        t0 = time.perf_counter()
        for _ in range(count):
            one()
        return count / (time.perf_counter() - t0)


def batch_run(cmd, env, count):
    """(per transaction, whole run) rates of ``zap batch``: from its first record to its last,
    and from its start to its end."""
    with tempfile.TemporaryFile() as err:     # a file, not a pipe: the records are read alone
        t0 = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, env=env)
        stamps = []
        fd = p.stdout.fileno()
        while True:
            chunk = os.read(fd, 65536)
            if not chunk:
                break
            now = time.perf_counter()
            stamps += [now] * chunk.count(b"\n")
        p.wait()
        took = time.perf_counter() - t0
        err.seek(0)
        message = err.read()[-500:].decode(errors="replace")
    if p.returncode != 0 or len(stamps) != count:
        raise SystemExit(f"batch failed (exit {p.returncode}, {len(stamps)} records): {message}")
    per = (count - 1) / (stamps[-1] - stamps[0]) if count > 1 and stamps[-1] > stamps[0] else float("nan")
    return per, count / took


def spread(values):
    return f"{min(values):.1f}-{max(values):.1f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=1000, help="reads in each loop and lines in the batch")
    ap.add_argument("--commands", type=int, default=50, help="separate zap load processes")
    ap.add_argument("--baud", type=int, default=57600)
    ap.add_argument("--rounds", type=int, default=5, help="interleaved rounds of floor, API loop and batch (medians)")
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
    floors, apis, pers, wholes = [], [], [], []
    timeout = ["--timeout", str(args.timeout)] if args.timeout is not None else []
    batch_cmd = tool("zap") + ["batch", f.name, "-p", port, "-b", str(args.baud), *timeout]
    try:
        for _ in range(args.rounds):            # interleaved: all three see the same machine load
            floors.append(floor(port, args.baud, args.count))
            with Bus(port, baud=args.baud, timeout=args.timeout) as bus:
                until_ready(lambda: bus.load(1, "present-position"))      # warm up, once it answers
                t0 = time.perf_counter()
                for _ in range(args.count):
                    bus.load(1, "present-position")
                apis.append(args.count / (time.perf_counter() - t0))
            per, whole = batch_run(batch_cmd, env, args.count)
            pers.append(per)
            wholes.append(whole)
        fl, api = statistics.median(floors), statistics.median(apis)
        per, whole = statistics.median(pers), statistics.median(wholes)

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
    ratios = {"api/line": api / line, "batch/line": per / line, "batch/api": per / api,
              "batch/commands": whole / commands}
    context = {"floor/line": fl / line, "api/floor": api / fl, "batch/floor": per / fl,
               "batch whole run/line": whole / line}
    ok = all(ratios[k] >= v for k, v in TARGETS.items())
    if args.json:
        print(json.dumps({"reads_per_s": {"floor": fl, "api": api, "batch": per, "batch_whole_run": whole,
                                          "commands": commands, "line": line},
                          "rounds": {"floor": floors, "api": apis, "batch": pers, "batch_whole_run": wholes},
                          "ratio": ratios, "context": context, "target": TARGETS, "ok": ok}))
    else:
        print(f"{args.count} reads of present-position at {args.baud} baud over a pty "
              f"(the line's limit: {line:.1f} reads/s; medians of {args.rounds} rounds, their spread)")
        print(f"  floor (raw loop on the pty)          {fl:8.1f} reads/s  ({spread(floors)})")
        print(f"  API loop (one process)               {api:8.1f} reads/s  ({spread(apis)})")
        print(f"  zap batch, per transaction           {per:8.1f} reads/s  ({spread(pers)})")
        print(f"  zap batch, whole run (start-up too)  {whole:8.1f} reads/s  ({spread(wholes)})")
        print(f"  separate zap load ({args.commands:4d} runs)        {commands:8.1f} reads/s")
        for k, v in TARGETS.items():
            print(f"  {k:20} ratio {ratios[k]:7.3f}  (target >= {v})  {'ok' if ratios[k] >= v else 'MISSED'}")
        for k, v in context.items():
            print(f"  {k:20} ratio {v:7.3f}")
    return 0 if ok or args.no_fail else 1


if __name__ == "__main__":
    sys.exit(main())
