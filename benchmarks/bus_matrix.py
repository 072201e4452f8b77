#!/usr/bin/env python3
"""The whole command x bus matrix: every zap command on every simulated bus, checked against the
half-duplex discipline (the long tail of tests/e2e/test_zap_bus_matrix.py, which covers it lean).

    python benchmarks/bus_matrix.py                        # 8 latencies x gap x echo x 3 modes
    python benchmarks/bus_matrix.py --latency 40,140 --mode 1

For every bus (``zkzap sim zap --pty`` with IDs 1 and 2: a turnaround of each latency, bytes 1
ms apart or not, an echoing adapter or not, return mode 0, 1 or 2) it runs every command that
the mode allows as one ``zap batch`` with ``--capture`` (the default late window: nothing is
widened here), then checks the capture (tests/e2e/buscheck.py): no request while a reply was
due, every reply the answer to the request before it, exactly one request per transaction;
and the simulator's report: no collision. Then a scan of IDs 0-4 must find and identify both
actuators. Prints one row per bus and the totals; exits 1 when any bus fails (``--no-fail``).
A bus at 140 ms answers within 10 ms of the window's end: on a loaded machine a simulator
held up that long misses it, which shows here as a retry (the benchmark measures; the tests,
tests/e2e/test_zap_bus_matrix.py, give such buses a wider window).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(ROOT, "cli"))
sys.path.insert(0, os.path.join(ROOT, "tests", "e2e"))

sys.path.insert(0, HERE)
from buscheck import LINES, check_capture  # noqa: E402
from common import add_quick  # noqa: E402

LATENCIES = (2, 18, 22, 25, 40, 60, 100, 140)
def tool(name):
    exe = os.path.join(os.path.dirname(sys.executable), name)
    return [exe] if os.path.exists(exe) else [sys.executable, "-m", "zkzap"]


def run_bus(latency, gap, echo, mode, tmp):
    env = dict(os.environ, NO_COLOR="1")
    err = open(os.path.join(tmp, "sim.err"), "w+")
    sim = subprocess.Popen(tool("zkzap") + ["sim", "zap", "--pty", "--ids", "1,2", "--turnaround", str(latency),
                                            "--gap", str(gap), "--return-mode", str(mode)] + (["--echo"] if echo else []),
                           stdout=subprocess.PIPE, stderr=err, text=True, env=env)
    port = sim.stdout.readline().strip()
    row = {"bus": f"{latency:3d} ms gap {gap} {'echo  ' if echo else 'direct'} mode {mode}", "ok": False}
    try:
        lines = [text.format(tmp=tmp) for name, (text, any_mode) in LINES.items()
                 if (any_mode or mode != 0) and name != "check-still"]
        with open(os.path.join(tmp, "lines.txt"), "w") as f:
            f.write("".join(x + "\n" for x in lines))
        cap = os.path.join(tmp, "run.pcapng")
        t0 = time.perf_counter()
        p = subprocess.run(tool("zap") + ["batch", os.path.join(tmp, "lines.txt"), "-p", port, "--return-mode",
                                          str(mode), "--yes", "--capture", cap], capture_output=True, text=True, env=env)
        row["seconds"] = time.perf_counter() - t0
        records = [json.loads(x) for x in p.stdout.splitlines()]
        failed = [r["command"] for r in records if r["exit"]]
        row["commands"] = f"{len(records) - len(failed)}/{len(lines)}"
        try:
            pairs, retries = check_capture(cap, mode)
            row["transactions"] = len(pairs)
            row["retries"] = retries
            row["unanswered"] = sum(p.reply is None for p in pairs)
            discipline = None
        except AssertionError as e:
            discipline = str(e)
        err.flush()
        err.seek(0)
        collisions = sum("collision" in line for line in err.read().splitlines())
        row["collisions"] = collisions
        s = subprocess.run(tool("zap") + ["scan", "--ids", "0-4", "-p", port, "--return-mode", str(mode)],
                           capture_output=True, text=True, env=env)
        found = [json.loads(x) for x in s.stdout.splitlines()]
        row["scan"] = [(r["id"], r["status"], r["return_mode"]) for r in found] == [(1, "ok", mode), (2, "ok", mode)]
        row["ok"] = (not failed and discipline is None and row.get("retries") == 0 and not row.get("unanswered")
                     and collisions == 0 and row["scan"])
        row["problem"] = "; ".join(x for x in [discipline, ", ".join(failed) and f"failed: {', '.join(failed)}"] if x)
    finally:
        sim.terminate()
        sim.wait(5)
        err.close()
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--latency", default=",".join(map(str, LATENCIES)), help="latencies (ms), comma separated")
    ap.add_argument("--mode", default="0,1,2", help="return modes, comma separated")
    ap.add_argument("--gap", default="0,1", help="ms between reply bytes, comma separated")
    ap.add_argument("--echo", default="no,yes", help="behind an echoing adapter: no, yes or both (no,yes)")
    ap.add_argument("--no-fail", action="store_true")
    add_quick(ap, latency="40", mode="1", gap="1", echo="yes", no_fail=True)
    args = ap.parse_args(argv)
    latencies = [int(x) for x in args.latency.split(",")]
    modes = [int(x) for x in args.mode.split(",")]
    gaps = [int(x) for x in args.gap.split(",")]
    echoes = [x.strip() == "yes" for x in args.echo.split(",")]
    rows = []
    for latency, gap, echo, mode in itertools.product(latencies, gaps, echoes, modes):
        with tempfile.TemporaryDirectory() as tmp:
            row = run_bus(latency, gap, echo, mode, tmp)
        rows.append(row)
        print(f"{row['bus']}: {'ok  ' if row['ok'] else 'FAIL'} commands {row.get('commands')}, "
              f"{row.get('transactions', '?')} transactions, {row.get('retries', '?')} retries, "
              f"{row.get('collisions', '?')} collisions, scan {'ok' if row.get('scan') else 'FAIL'}, "
              f"{row.get('seconds', 0):.1f} s" + (f"  {row['problem']}" if row.get("problem") else ""), flush=True)
    good = sum(r["ok"] for r in rows)
    print(f"{good} of {len(rows)} buses kept the discipline with every command answered")
    return 0 if good == len(rows) or args.no_fail else 1


if __name__ == "__main__":
    sys.exit(main())
