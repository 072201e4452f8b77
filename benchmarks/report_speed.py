#!/usr/bin/env python3
"""Time of a PNG report of a long run: reading the records, and drawing them, with the lines
decimated for drawing (each pixel column's minimum and maximum: ``zkzap.io.report.decimate``)
and, for the ratio, without. The run is synthetic: ``--rows`` status records at 100 Hz of an
engine cycled through start, running and cool-down ``--cycles`` times.

    python benchmarks/report_speed.py [--rows 1000000] [--cycles 500] [--no-plain]
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cli"))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick  # noqa: E402


def write_run(path, rows, cycles):
    per = max(rows // max(cycles, 1), 10)
    states = ("ignition", "running", "running", "running", "cooling")
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "id", "rpm", "egt_c", "thrust_kg", "throttle_pct", "fuel_flow_l_min", "power_voltage_v",
                    "pump_voltage_v", "engine_state_name"])
        for i in range(rows):
            phase = (i % per) / per
            x = math.sin(phase * math.pi)
            w.writerow([f"{i * 0.01:.2f}", 1 + i % 3, round(40000 + 110000 * x), round(300 + 380 * x),
                        f"{12 * x:.2f}", f"{100 * x:.1f}", f"{0.6 * x:.3f}", "11.6", f"{9 * x:.2f}",
                        states[min(int(phase * len(states)), len(states) - 1)]])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--cycles", type=int, default=500)
    ap.add_argument("--no-plain", action="store_true", help="skip the drawing without decimation")
    add_quick(ap, rows=20_000, cycles=10)
    args = ap.parse_args()
    from zkzap.io import report as R

    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "run.csv")
        write_run(path, args.rows, args.cycles)
        t0 = time.perf_counter()
        run = R.load_run(path)
        t1 = time.perf_counter()
        R.render(os.path.join(d, "run.png"), "png", [run])
        t2 = time.perf_counter()
        print(f"{len(run.t):,} records, {len(run.states):,} state changes: read {t1 - t0:.2f} s, "
              f"drawn decimated {t2 - t1:.2f} s")
        if not args.no_plain:
            bins, R.DRAW_BINS = R.DRAW_BINS, 1 << 40
            try:
                t3 = time.perf_counter()
                R.render(os.path.join(d, "plain.png"), "png", [run])
                t4 = time.perf_counter()
            finally:
                R.DRAW_BINS = bins
            print(f"drawn whole {t4 - t3:.2f} s; decimated/whole {(t2 - t1) / (t4 - t3):.3f}")


if __name__ == "__main__":
    main()
