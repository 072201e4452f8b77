"""Peak memory of ``zk decode --binary``: a 10x larger capture must not need more memory.

    python benchmarks/memory.py                     # 1,000,000 vs 10,000,000 frames
    python benchmarks/memory.py --frames 200000 --formats jsonl

Each run is its own process (stdout to /dev/null); its peak resident set size is read from the
kernel's accounting of that child alone. Target: peak RSS on the 10x capture <= 1.2x the
smaller one's. Decoding is streaming (64 KiB reads, one block of lines per read) and every
cache is bounded, so the figure should not grow with the input.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import captures  # noqa: E402
from zk_decode import zk_command  # noqa: E402
from common import add_quick  # noqa: E402

PROBE = r"""
import resource, subprocess, sys
with open("/dev/null", "wb") as null:
    rc = subprocess.run(sys.argv[1:], stdout=null, stderr=subprocess.DEVNULL).returncode
print(rc, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def peak_rss_kib(cmd):
    out = subprocess.run([sys.executable, "-c", PROBE, *cmd], capture_output=True, text=True, check=True).stdout
    rc, kib = out.split()
    if rc != "0":
        raise SystemExit(f"{' '.join(cmd)} exited {rc}")
    return int(kib)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--factor", type=int, default=10)
    ap.add_argument("--formats", default="jsonl,csv")
    add_quick(ap, frames=2000, factor=2)
    args = ap.parse_args(argv)
    small = captures.zk_capture(args.frames, "engine")
    large = captures.zk_capture(args.frames * args.factor, "engine")
    print(f"peak RSS of zk decode --binary: {args.frames:,} vs {args.frames * args.factor:,} frames")
    for fmt in args.formats.split(","):
        a = peak_rss_kib(zk_command() + ["decode", "--binary", small, "-f", fmt])
        b = peak_rss_kib(zk_command() + ["decode", "--binary", large, "-f", fmt])
        ratio = b / a
        print(f"  {fmt:5}: {a / 1024:6.1f} MiB vs {b / 1024:6.1f} MiB: {ratio:.2f}x  "
              f"target <= 1.2x {'met' if ratio <= 1.2 else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
