"""``zap decode --binary`` against the floor, side by side in one run.

    python benchmarks/zap_decode.py                  # 1,000,000 packets, best of 3
    python benchmarks/zap_decode.py --packets 200000 --repeat 5

The capture (generated on first use into benchmarks/data/) is a bus sniffed in both directions:
a host polling present-position of IDs 1..4 (Load Data requests) and the actuators' replies,
every rod wandering. Each command runs as its own process with stdout to /dev/null,
alternating zkzap and the floor (floor_zap_decode.py: whole packets assumed, checksum, five raw
numbers); the best time of each is kept. Targets: JSON Lines <= 1.0x, CSV <= 1.5x the floor.
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

TARGETS = {"jsonl": 1.0, "csv": 1.5}


def zap_capture(count=1_000_000, seed=1):
    """Path of a cached capture of ``count`` packets: requests and replies in turn."""
    from zkzap.codec import zap

    path = os.path.join(captures.DATA, f"zap-poll-{count}-{seed}.bin")
    if os.path.exists(path):
        return path
    os.makedirs(captures.DATA, exist_ok=True)
    requests = {i: zap.load(i, "present-position") for i in range(1, 5)}
    out = []
    for ident, pos in captures._positions(count // 2, seed):
        out.append(requests[ident])
        out.append(zap.packet(ident, 0x00, pos.to_bytes(2, "little")))
    with open(path + ".tmp", "wb") as f:
        f.write(b"".join(out))
    os.replace(path + ".tmp", path)
    return path


def zap_command():
    exe = os.path.join(os.path.dirname(sys.executable), "zap")
    if os.path.exists(exe):
        return [exe]
    return [sys.executable, "-c", "import sys; from zkzap.commands import zap_main; sys.argv[0] = 'zap'; zap_main()"]


def timed(cmd):
    t0 = time.perf_counter()
    with open(os.devnull, "wb") as null:
        p = subprocess.run(cmd, stdout=null, stderr=subprocess.PIPE)
    dt = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({p.returncode}): {p.stderr.decode()[-500:]}")
    return dt


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--packets", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--formats", default="jsonl,csv")
    add_quick(ap, packets=500, repeat=1)
    args = ap.parse_args(argv)
    path = zap_capture(args.packets)
    n = args.packets
    print(f"zap decode --binary vs the floor: {n:,} packets (requests and replies), best of {args.repeat}")
    print(f"{'format':6} {'zkzap s':>8} {'floor s':>8} {'ratio':>6} {'target':>7}")
    ok = True
    for fmt in args.formats.split(","):
        ours, base = [], []
        for _ in range(args.repeat):
            ours.append(timed(zap_command() + ["decode", "--binary", path, "-f", fmt]))
            base.append(timed([sys.executable, os.path.join(HERE, "floor_zap_decode.py"), path, "--format", fmt]))
        ratio = min(ours) / min(base)
        ok = ok and ratio <= TARGETS[fmt]
        print(f"{fmt:6} {min(ours):8.2f} {min(base):8.2f} {ratio:5.2f}x  <= {TARGETS[fmt]}  "
              f"{'met' if ratio <= TARGETS[fmt] else 'NOT met'}")
    return 0 if ok or args.quick else 1


if __name__ == "__main__":
    sys.exit(main())
