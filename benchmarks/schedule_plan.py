#!/usr/bin/env python3
"""Cost of ``zk profile -n`` (Schedule.plan) against the schedule's duration.

Builds the same schedule shape — a start, throttle steps, linear ramps and RPM targets — scaled
to 10^2 s and to 10^8 s and prints the median time of plan() for each and the ratio long/short,
with the target: the ratio stays <= 2 (the cost follows the rows and the levels a ramp crosses,
not the control periods; stepping through every period, as before, would make it 10^6).
Exits 1 when the target is missed (``--no-fail`` to only report).

    python benchmarks/schedule_plan.py [--runs 9] [--rate 200] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cli"))

from zkzap.api.schedule import Schedule  # noqa: E402
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick  # noqa: E402

TARGET = 2.0


def schedule(scale):
    rows = [(0, "0,run"), (20, "0"), (25, "30"), (35, "60"), (45, "100"), (55, "rpm=90000"), (65, "rpm=120000"),
            (75, "0"), (80, "0,standby"), (100, "0,standby")]
    return "\n".join(f"{t * scale:g},{v}" for t, v in rows) + "\n"


def median_time(text, rate, runs, interpolate):
    times = []
    for _ in range(runs):
        s = Schedule.parse(text, name="bench", interpolate=interpolate)
        t0 = time.perf_counter()
        s.plan(rate)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=9)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-fail", action="store_true")
    add_quick(ap, runs=1, no_fail=True)
    a = ap.parse_args(argv)
    out = {}
    for interpolate in ("step", "linear"):
        short = median_time(schedule(1), a.rate, a.runs, interpolate)
        long = median_time(schedule(10 ** 6), a.rate, a.runs, interpolate)
        out[interpolate] = {"short_s": short, "long_s": long, "ratio": long / short}
    if a.json:
        print(json.dumps({"target": TARGET, **out}))
    else:
        for k, v in out.items():
            print(f"plan {k:6}  100 s: {v['short_s'] * 1e3:8.3f} ms   10^8 s: {v['long_s'] * 1e3:8.3f} ms   "
                  f"ratio {v['ratio']:.2f} (target <= {TARGET:g})")
    missed = [k for k, v in out.items() if v["ratio"] > TARGET]
    return 1 if missed and not a.no_fail else 0


if __name__ == "__main__":
    sys.exit(main())
