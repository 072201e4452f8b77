"""``zk decode --binary`` against the floor, side by side in one run.

    python benchmarks/zk_decode.py                  # 1,000,000 frames, best of 3
    python benchmarks/zk_decode.py --frames 200000 --repeat 5

Captures (generated on first use into benchmarks/data/, see captures.py): ``engine`` is a
test-stand run of the ECU model, status IDs 1..10 in turn with sensor noise (the realistic
case: frames repeat, as they do in real captures); ``distinct`` has random payloads (the worst
case for the line memo: hardly a frame repeats).

Each command runs as its own process with stdout to /dev/null, alternating zkzap and the
floor; the ratio is the median, over the pairs of runs side by side, of CPU time (user +
system of the process), which other work on a shared machine disturbs far less than wall
time. The best times are printed too, CPU and wall. zkzap writes every named field (about 10 per frame plus the frame's hex) in
JSON Lines or CSV; the floor (floor_zk_decode.py) assumes aligned 7-byte frames and writes
five raw numbers. Targets: JSON Lines <= 1.0x the floor on both captures; CSV <= 1.5x on the
distinct capture, <= 1.0x on the engine one.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import captures  # noqa: E402
from common import add_quick  # noqa: E402

def zk_command():
    exe = os.path.join(os.path.dirname(sys.executable), "zk")
    if os.path.exists(exe):
        return [exe]
    return [sys.executable, "-c", "import sys; from zkzap.commands import zk_main; sys.argv[0] = 'zk'; zk_main()"]


def timed(cmd, env=None):
    """(CPU seconds, wall seconds) of one run of ``cmd``."""
    with open(os.devnull, "wb") as null:
        t0 = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=null, stderr=subprocess.PIPE, env=env)
        err = p.stderr.read()
        _pid, status, usage = os.wait4(p.pid, 0)
        dt = time.perf_counter() - t0
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({p.returncode}): {err.decode()[-500:]}")
    return usage.ru_utime + usage.ru_stime, dt


def normal_env():
    """The environment of a normal start: bytecode caches written (by a warm-up run) and read
    afterwards, no profiling or debugging modes."""
    env = dict(os.environ)
    for var in ("PYTHONDONTWRITEBYTECODE", "PYTHONPROFILEIMPORTTIME", "PYTHONDEVMODE", "PYTHONTRACEMALLOC"):
        env.pop(var, None)
    return env


def compare(capture, fmt, repeat):
    zk = zk_command() + ["decode", "--binary", capture, "-f", fmt]
    floor = [sys.executable, os.path.join(HERE, "floor_zk_decode.py"), capture, "--format", fmt]
    env = normal_env()
    timed(zk, env)                                    # warm-up: bytecode caches
    ours, base = [], []
    for _ in range(repeat):
        ours.append(timed(zk, env))
        base.append(timed(floor, env))
    # each zkzap run against the floor run next to it: the median of those pairs' ratios holds
    # when the machine's speed drifts during the run
    pairs = sorted(o[0] / b[0] for o, b in zip(ours, base))
    return min(ours), min(base), pairs[len(pairs) // 2]


TARGETS = {("engine", "jsonl"): 1.0, ("distinct", "jsonl"): 1.0, ("engine", "csv"): 1.0, ("distinct", "csv"): 1.5}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--captures", default="engine,distinct", help="engine, distinct or both (comma-separated)")
    ap.add_argument("--formats", default="jsonl,csv")
    add_quick(ap, frames=500, repeat=1)
    args = ap.parse_args(argv)
    n = args.frames
    print(f"zk decode --binary vs the floor: {n:,} status frames, best of {args.repeat}")
    print(f"load average {os.getloadavg()[0]:.2f}; ratio: the median of paired CPU-time ratios; times: best")
    print(f"{'capture':9} {'format':6} {'zkzap cpu':>9} {'floor cpu':>9} {'ratio':>6} {'zkzap wall':>10} "
          f"{'floor wall':>10} {'wall ratio':>10} {'zkzap frames/s':>15}  target")
    for kind in args.captures.split(","):
        path = captures.zk_capture(n, kind)
        for fmt in args.formats.split(","):
            (ours, ours_wall), (base, base_wall), ratio = compare(path, fmt, args.repeat)
            target = TARGETS.get((kind, fmt), 1.0)
            print(f"{kind:9} {fmt:6} {ours:9.2f} {base:9.2f} {ratio:5.2f}x {ours_wall:10.2f} {base_wall:10.2f} "
                  f"{ours_wall / base_wall:9.2f}x {n / ours_wall:15,.0f}  <= {target}x "
                  f"{'met' if ratio <= target else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
