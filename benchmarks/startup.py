#!/usr/bin/env python3
"""Start-up time of the CLI against a baseline of ``python3 -c "import click"``.

Prints the median wall time of each command over interleaved runs (baseline, dry-run compose,
--help, baseline, ...) and the ratios to the baseline, with the targets:

    zkzap zk send control --state run --throttle 50 -n   <= 1.15 x baseline
    zkzap --help                                         <= 1.3  x baseline

The baseline uses the same interpreter as the installed ``zkzap`` script, so the ratio measures
what zkzap adds on top of importing click. Exits 1 when a target is missed (``--no-fail`` to
only report). Only public tools: subprocess and time.perf_counter.

    python benchmarks/startup.py [--runs 40] [--zkzap PATH] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick  # noqa: E402

TARGETS = {"dry-run": 1.15, "help": 1.3}


def find_zkzap(given=None):
    if given:
        return given
    here = os.path.join(os.path.dirname(sys.executable), "zkzap")
    return here if os.path.exists(here) else shutil.which("zkzap")


def interpreter_of(script):
    """The Python a console script runs with (its #! line), else this one."""
    try:
        with open(script, "rb") as f:
            first = f.readline().decode("utf-8", "replace").strip()
    except OSError:
        return sys.executable
    if first.startswith("#!"):
        parts = first[2:].split()
        if parts and os.path.exists(parts[0]) and "python" in os.path.basename(parts[0]):
            return parts[0]
    return sys.executable


def timed(argv, env):
    t0 = time.perf_counter()
    subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, check=True)
    return time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=40, help="interleaved rounds (default 40)")
    ap.add_argument("--warmup", type=int, default=3, help="unmeasured rounds first (default 3)")
    ap.add_argument("--zkzap", help="path of the zkzap script (default: beside this Python, else PATH)")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of a report")
    ap.add_argument("--no-fail", action="store_true", help="exit 0 even when a target is missed")
    add_quick(ap, runs=2, warmup=0, no_fail=True)
    args = ap.parse_args(argv)

    exe = find_zkzap(args.zkzap)
    if not exe:
        print("startup: zkzap is not installed (pip install -e .)", file=sys.stderr)
        return 2
    python = interpreter_of(exe)
    env = dict(os.environ)
    # a normal start: bytecode caches written by the warm-up runs and read afterwards (an
    # installed wheel has them precompiled); no import profiling or dev-mode checks
    for var in ("PYTHONDONTWRITEBYTECODE", "PYTHONPROFILEIMPORTTIME", "PYTHONDEVMODE", "PYTHONTRACEMALLOC"):
        env.pop(var, None)
    commands = {
        "baseline": [python, "-c", "import click"],
        "dry-run": [exe, "zk", "send", "control", "--state", "run", "--throttle", "50", "-n"],
        "help": [exe, "--help"],
    }
    times = {name: [] for name in commands}
    for i in range(args.warmup + args.runs):
        # rotate the order so that no command always follows the same one
        names = list(commands)
        names = names[i % len(names):] + names[:i % len(names)]
        for name in names:
            t = timed(commands[name], env)
            if i >= args.warmup:
                times[name].append(t)

    med = {name: statistics.median(ts) for name, ts in times.items()}
    ratios = {name: med[name] / med["baseline"] for name in TARGETS}
    ok = all(ratios[n] <= TARGETS[n] for n in TARGETS)
    if args.json:
        print(json.dumps({"runs": args.runs, "median_s": med, "ratio": ratios, "target": TARGETS, "ok": ok}))
    else:
        print(f"{args.runs} interleaved runs, medians; python {python}")
        print(f"  baseline  python -c 'import click'      {med['baseline'] * 1000:7.1f} ms")
        labels = {"dry-run": "zkzap zk send control ... -n", "help": "zkzap --help"}
        for name in TARGETS:
            mark = "ok" if ratios[name] <= TARGETS[name] else "MISSED"
            print(f"  {name:8}  {labels[name]:32}{med[name] * 1000:7.1f} ms  ratio {ratios[name]:.3f}"
                  f"  (target <= {TARGETS[name]})  {mark}")
    return 0 if ok or args.no_fail else 1


if __name__ == "__main__":
    sys.exit(main())
