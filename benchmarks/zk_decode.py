"""``zk decode --binary`` against the floor, side by side in one run.

    python benchmarks/zk_decode.py                  # 1,000,000 frames, best of 3
    python benchmarks/zk_decode.py --frames 200000 --repeat 5

Captures (generated on first use into benchmarks/data/, see captures.py): ``engine`` is a
test-stand run of the ECU model, status IDs 1..10 in turn with sensor noise (the realistic
case: frames repeat, as they do in real captures); ``distinct`` has random payloads (the worst
case for the line memo: hardly a frame repeats).

Each command runs as its own process with stdout to /dev/null, alternating zkzap and the
floor, and the best time of each is kept. zkzap writes every named field (about 10 per frame
plus the frame's hex) in JSON Lines or CSV; the floor (floor_zk_decode.py) assumes aligned
7-byte frames and writes five raw numbers. Target: zkzap's time <= 1.0x the floor's.
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


def zk_command():
    exe = os.path.join(os.path.dirname(sys.executable), "zk")
    if os.path.exists(exe):
        return [exe]
    return [sys.executable, "-c", "import sys; from zkzap.commands import zk_main; sys.argv[0] = 'zk'; zk_main()"]


def timed(cmd, env=None):
    t0 = time.perf_counter()
    with open(os.devnull, "wb") as null:
        p = subprocess.run(cmd, stdout=null, stderr=subprocess.PIPE, env=env)
    dt = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({p.returncode}): {p.stderr.decode()[-500:]}")
    return dt


def compare(capture, fmt, repeat):
    zk = zk_command() + ["decode", "--binary", capture, "-f", fmt]
    floor = [sys.executable, os.path.join(HERE, "floor_zk_decode.py"), capture, "--format", fmt]
    ours, base = [], []
    for _ in range(repeat):
        ours.append(timed(zk))
        base.append(timed(floor))
    return min(ours), min(base)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--captures", default="engine,distinct", help="engine, distinct or both (comma-separated)")
    ap.add_argument("--formats", default="jsonl,csv")
    args = ap.parse_args(argv)
    n = args.frames
    print(f"zk decode --binary vs the floor: {n:,} status frames, best of {args.repeat}")
    print(f"{'capture':9} {'format':6} {'zkzap s':>8} {'floor s':>8} {'ratio':>6} {'zkzap frames/s':>15} "
          f"{'floor frames/s':>15}  target <= 1.0x")
    worst = 0.0
    for kind in args.captures.split(","):
        path = captures.zk_capture(n, kind)
        for fmt in args.formats.split(","):
            ours, base = compare(path, fmt, args.repeat)
            ratio = ours / base
            worst = max(worst, ratio) if kind == "engine" else worst
            print(f"{kind:9} {fmt:6} {ours:8.2f} {base:8.2f} {ratio:5.2f}x {n / ours:15,.0f} {n / base:15,.0f}  "
                  f"{'met' if ratio <= 1.0 else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
