"""What a pcapng capture costs, side by side in one run.

    python benchmarks/capture.py                  # 200,000 status frames, best of 3
    python benchmarks/capture.py --frames 50000 --repeat 5

1. Decoding: ``zk decode CAPTURE`` against ``zk decode --binary RAW`` of the same frames (the
   capture holds them as 64-byte chunks, as a port read at 115200 baud returns them, with
   times and directions; its records carry ``time``, ``t`` and ``dir`` too). Printed as a ratio.
2. The tap: reading the same bytes through ``open_port`` from ``loop://`` with and without
   ``capture=``, in 64-byte reads (the time per chunk added by writing one pcapng block).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick  # noqa: E402


def zk_command():
    exe = os.path.join(os.path.dirname(sys.executable), "zk")
    return [exe] if os.path.exists(exe) else [sys.executable, "-m", "zkzap.commands"]


def timed(cmd):
    t0 = time.perf_counter()
    with open(os.devnull, "wb") as null:
        p = subprocess.run(cmd, stdout=null, stderr=subprocess.PIPE)
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {p.stderr.decode()[-400:]}")
    return time.perf_counter() - t0


def make(d, frames):
    import random

    from zkzap.codec import zk
    from zkzap.link.pcapng import INBOUND, Writer

    rng = random.Random(1)
    data = b"".join(zk.encode_status(i % 10 + 1, 6, rpm=rng.randrange(0, 160000, 10)) for i in range(frames))
    raw = os.path.join(d, "run.bin")
    with open(raw, "wb") as f:
        f.write(data)
    cap = os.path.join(d, "run.pcapng")
    w = Writer(cap)
    i = w.interface("zk", "bench", 115200)
    ts = 1.7e9
    for k in range(0, len(data), 64):
        w.packet(i, ts, data[k:k + 64], INBOUND)
        ts += 64 * 10 / 115200
    w.close()
    return raw, cap, data


def tap_cost(data, d, chunk=64):
    from zkzap.link.port import close_port, open_port

    out = {}
    for name, capture in (("plain", ()), ("tapped", (os.path.join(d, "tap.pcapng"), "zk"))):
        p = open_port("loop://", 115200, timeout=0, capture=capture)
        t0 = time.perf_counter()
        n = 0
        for k in range(0, len(data), 4096):
            p.write(data[k:k + 4096])
            while True:
                b = p.read(chunk)
                if not b:
                    break
                n += 1
        out[name] = (time.perf_counter() - t0) / max(1, n)
        close_port(p)
    from zkzap.link import capture as cap

    cap.finish()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=3)
    add_quick(ap, frames=500, repeat=1)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        raw, cap, data = make(d, args.frames)
        ours, base = [], []
        for _ in range(args.repeat):
            ours.append(timed(zk_command() + ["decode", cap]))
            base.append(timed(zk_command() + ["decode", "--binary", raw]))
        a, b = min(ours), min(base)
        print(f"zk decode of a capture vs the raw bytes, {args.frames} frames: {a:.2f} s vs {b:.2f} s "
              f"= {a / b:.2f}x ({args.frames / a:,.0f} frames/s from the capture)")
        cost = tap_cost(data[:7 * 50_000], d)
        print(f"tap: {cost['plain'] * 1e6:.1f} us per 64-byte read plain, {cost['tapped'] * 1e6:.1f} us tapped "
              f"(+{(cost['tapped'] - cost['plain']) * 1e6:.1f} us per chunk written to the capture)")


if __name__ == "__main__":
    main()
