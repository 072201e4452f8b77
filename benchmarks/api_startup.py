#!/usr/bin/env python3
"""Start-up of the library: ``python -c "from zkzap import Bus"`` against ``python -c "import
serial"``, interleaved, medians. Target: <= 1.2 x (the API pulls in no click, rich or optional
extra; pyserial itself is imported only when a port opens).

    python benchmarks/api_startup.py [--runs 40] [--json] [--no-fail]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick  # noqa: E402

TARGET = 1.2


def timed(argv, env):
    t0 = time.perf_counter()
    subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, check=True)
    return time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-fail", action="store_true")
    add_quick(ap, runs=2, warmup=0, no_fail=True)
    args = ap.parse_args(argv)
    env = dict(os.environ)
    for var in ("PYTHONDONTWRITEBYTECODE", "PYTHONPROFILEIMPORTTIME", "PYTHONDEVMODE", "PYTHONTRACEMALLOC"):
        env.pop(var, None)
    commands = {"serial": [sys.executable, "-c", "import serial"],
                "api": [sys.executable, "-c", "from zkzap import Bus"],
                "api-ecu": [sys.executable, "-c", "from zkzap import Ecu"]}
    times = {k: [] for k in commands}
    for i in range(args.warmup + args.runs):
        names = list(commands)
        names = names[i % len(names):] + names[:i % len(names)]
        for name in names:
            t = timed(commands[name], env)
            if i >= args.warmup:
                times[name].append(t)
    med = {k: statistics.median(v) for k, v in times.items()}
    ratios = {k: med[k] / med["serial"] for k in ("api", "api-ecu")}
    ok = ratios["api"] <= TARGET
    if args.json:
        print(json.dumps({"median_s": med, "ratio": ratios, "target": TARGET, "ok": ok}))
    else:
        print(f"{args.runs} interleaved runs, medians; python {sys.executable}")
        print(f"  baseline  python -c 'import serial'          {med['serial'] * 1000:7.1f} ms")
        print(f"  api       python -c 'from zkzap import Bus'  {med['api'] * 1000:7.1f} ms  ratio "
              f"{ratios['api']:.3f}  (target <= {TARGET})  {'ok' if ok else 'MISSED'}")
        print(f"  api-ecu   python -c 'from zkzap import Ecu'  {med['api-ecu'] * 1000:7.1f} ms  ratio "
              f"{ratios['api-ecu']:.3f}")
    return 0 if ok or args.no_fail else 1


if __name__ == "__main__":
    sys.exit(main())
