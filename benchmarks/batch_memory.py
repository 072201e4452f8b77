#!/usr/bin/env python3
"""A ``zk batch`` line's memory does not grow with what it prints: the peak RSS of a batch whose
one line is ``monitor --count N -f jsonl`` on the in-process simulator, for a small and a large
N, and their ratio.

    python benchmarks/batch_memory.py [--small 2000] [--large 20000] [--json]

A line that prints more than 64 KiB has its record streamed as it prints; a batch that kept it
would need memory in proportion (the records and their parsed copy). The target: the large run's
peak at most 1.3 x the small one's (the interpreter and its imports are most of both). Exits 1
when it is missed (``--no-fail`` to only report).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
CLI = os.path.join(os.path.dirname(HERE), "cli")
TARGET = 1.3

#: Runs the batch in a child and prints its peak RSS (kB) and the records' sizes.
CHILD = r"""
import json, resource, sys
sys.argv = ["zk", "batch", sys.argv[1], "-p", "sim://zk?speed=500"]
from zkzap import commands
code = None
try:
    commands.zk_main()
except SystemExit as e:
    code = e.code
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"exit": code, "peak_kb": peak}), file=sys.stderr)
"""


def run(count, tmp):
    path = os.path.join(tmp, f"batch-{count}.txt")
    with open(path, "w") as f:
        f.write(f"monitor --count {count} -f jsonl\n")
    env = dict(os.environ, PYTHONPATH=CLI + os.pathsep + os.environ.get("PYTHONPATH", ""))
    p = subprocess.run([sys.executable, "-c", CHILD, path], capture_output=True, text=True, env=env, timeout=600)
    rec = json.loads(p.stdout.splitlines()[0])
    stats = json.loads(p.stderr.strip().splitlines()[-1])
    if stats["exit"] not in (0, None) or len(rec["result"]) != count:
        raise SystemExit(f"batch of {count} records failed: {p.stderr[-400:]}")
    return stats["peak_kb"], len(p.stdout)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--small", type=int, default=2000)
    ap.add_argument("--large", type=int, default=20000)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-fail", action="store_true")
    add_quick(ap, small=200, large=2000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        small_kb, small_out = run(args.small, tmp)
        large_kb, large_out = run(args.large, tmp)
    ratio = large_kb / small_kb
    result = {"small": {"records": args.small, "output_bytes": small_out, "peak_rss_kb": small_kb},
              "large": {"records": args.large, "output_bytes": large_out, "peak_rss_kb": large_kb},
              "ratio": round(ratio, 3), "target": TARGET}
    if args.json:
        print(json.dumps(result))
    else:
        print(f"zk batch, one monitor line: {args.small} records ({small_out / 1e6:.1f} MB out) peak RSS "
              f"{small_kb / 1024:.1f} MiB; {args.large} records ({large_out / 1e6:.1f} MB out) "
              f"{large_kb / 1024:.1f} MiB; ratio {ratio:.2f} (target <= {TARGET})")
    return 0 if ratio <= TARGET or args.no_fail else 1


if __name__ == "__main__":
    sys.exit(main())
