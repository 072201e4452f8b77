"""The bus against its model, at size: random buses and operations through the library and the
command line (tests/busmodel.py), every answer checked against the simulator's ground truth.
Prints the operations run, the wrong values found (the target is 0; how many of them on a bus
where two actuators share an ID at one rate, see docs/reference/timing.md), the doubts and
errors the bus raised or flagged instead, and the real time per operation (on a virtual clock:
windows that close in silence cost none). A violation prints the seed that reproduces it.

    python benchmarks/bus_truth.py                  # 100,000 operations
    python benchmarks/bus_truth.py --ops 2000 --seed 7
"""

from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests"))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common import add_quick  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ops", type=int, default=100_000, help="operations in all (default 100,000)")
    ap.add_argument("--steps", type=int, default=200, help="operations on each random bus")
    ap.add_argument("--seed", type=int, default=0, help="the first bus's seed")
    ap.add_argument("--no-cli", action="store_true", help="through the library only")
    add_quick(ap, ops=400, steps=40)
    args = ap.parse_args()
    import busmodel

    ops = wrong = errors = doubts = buses = shared = 0
    seen = []
    seed = args.seed
    t = time.perf_counter()
    while ops < args.ops:
        world = busmodel.World(seed, cli=not args.no_cli)
        buses += 1
        try:
            for _ in range(min(args.steps, args.ops - ops)):
                world.step()
        except busmodel.Violation as e:
            wrong += 1
            dupes = world.dupes()
            if dupes:
                shared += 1
            seen.append(str(e).splitlines()[0] + f" (seed {seed}{', shared ID' if dupes else ''})")
        finally:
            ops += world.ops
            errors += world.errors
            doubts += sum(d.doubts for d in world.bus.link.devices)
            world.close()
        seed += 1
    took = time.perf_counter() - t
    print(f"operations      {ops}")
    print(f"random buses    {buses} (seeds {args.seed}..{seed - 1})")
    print(f"wrong values    {wrong}   (target 0; {shared} on a bus where two actuators share an ID)")
    print(f"doubts flagged  {doubts}")
    print(f"errors raised   {errors}")
    print(f"time per op     {took / max(ops, 1) * 1e6:.0f} us ({took:.1f} s)")
    for line in seen[:20]:
        print("  " + line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
