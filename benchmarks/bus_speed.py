"""The bus's speed against an earlier revision, side by side in one run: full scans of a fast
bus and of buses with one actuator 22-140 ms late, Load Data round trips, set-id and set-baud,
through the library of each revision on the same simulators over real ptys.

    python benchmarks/bus_speed.py                       # against 4b1cb72, 3 rounds
    python benchmarks/bus_speed.py --base main --rounds 5

The earlier revision is checked out into a temporary git worktree (removed afterwards); each
measurement runs in a process of its own with that revision's ``cli/`` first on the path, the
two revisions in turn (which goes first alternates by round), against a fresh simulator of the
current revision started for the pair (``zkzap sim zap`` on a pty). Prints each figure's median
for both and the ratio current/earlier (above 1: slower now). Exits 1 when a ratio of a scan or
of the round trips passes ``--limit`` (1.10: 10 % slower), unless ``--no-fail``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)

from common import add_quick  # noqa: E402
from transactions import IDS, start_sim  # noqa: E402

#: (label, --ids, simulator options, what is measured, checked against --limit)
CASES = [
    ("scan, 2 ms actuators", IDS, (), "scan", True),
    ("scan, one 22 ms late", IDS, ("--fault", "100:delay=20"), "scan", True),
    ("scan, one 60 ms late", IDS, ("--fault", "100:delay=58"), "scan", True),
    ("scan, one 140 ms late", IDS, ("--fault", "100:delay=138"), "scan", True),
    ("Load round trip (ms)", "1", (), "load", True),
    ("set-id 1 -> 9 and back", "1,2", (), "set-id", False),
    ("set-baud 115200 and back", "1,2", (), "set-baud", False),
]

#: What one process measures (the same text for both revisions: only the public API).
PROBE = r"""
import json, sys, time
from zkzap import Bus
what, port, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
with Bus(port, allow=True) as bus:
    bus.echo(1)
    t = time.perf_counter()
    if what == "scan":
        recs = list(bus.scan(range(254)))
        ok = all(r["status"] == "ok" and r["model"] is not None for r in recs)
        out = {"s": time.perf_counter() - t, "found": len(recs), "ok": ok}
    elif what == "load":
        for _ in range(n):
            bus.load(1, "present-position")
        out = {"s": (time.perf_counter() - t) / n * 1000.0, "ok": True}
    elif what == "set-id":
        bus.set_id(1, 9)
        bus.set_id(9, 1)
        out = {"s": time.perf_counter() - t, "ok": True}
    else:
        bus.set_baud(1, 115200)
        bus.baud = 115200
        bus.set_baud(1, 57600)
        out = {"s": time.perf_counter() - t, "ok": True}
print(json.dumps(out))
"""


def measure(tree, what, ids, extra, loads):
    sim, port = start_sim(ids, 57600, extra)
    try:
        env = dict(os.environ, PYTHONPATH=os.path.join(tree, "cli"), NO_COLOR="1")
        r = subprocess.run([sys.executable, "-c", PROBE, what, port, str(loads)], capture_output=True, text=True,
                           env=env, timeout=300)
        if r.returncode:
            return {"s": float("nan"), "ok": False, "error": r.stderr.strip().splitlines()[-1:]}
        return json.loads(r.stdout)
    finally:
        sim.kill()
        sim.wait()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default="4b1cb72", help="the earlier revision (default 4b1cb72)")
    ap.add_argument("--current", help="measure this revision as the current one (default: the working tree)")
    ap.add_argument("--rounds", type=int, default=3, help="measurements of each figure per revision")
    ap.add_argument("--loads", type=int, default=400, help="Load round trips per measurement")
    ap.add_argument("--limit", type=float, default=1.10, help="the largest ratio allowed (default 1.10)")
    ap.add_argument("--no-fail", action="store_true", help="only report")
    ap.add_argument("--only", help="run only the cases whose label contains this text")
    add_quick(ap, rounds=1, loads=20, only="actuators", base="HEAD")
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="zkzap-base-")
    base = os.path.join(tmp, "tree")
    subprocess.run(["git", "-C", ROOT, "worktree", "add", "-q", "--detach", base, args.base], check=True)
    current = ROOT
    if args.current:
        current = os.path.join(tmp, "current")
        subprocess.run(["git", "-C", ROOT, "worktree", "add", "-q", "--detach", current, args.current], check=True)
    worse = []
    try:
        print(f"{'':30} {args.base:>10} {'current':>10} {'ratio':>7}")
        for label, ids, extra, what, checked in CASES:
            if args.only and args.only not in label:
                continue
            runs = {"base": [], "current": []}
            for i in range(args.rounds):
                order = [("base", base), ("current", current)]
                for name, tree in (order if i % 2 == 0 else order[::-1]):
                    got = measure(tree, what, ids, extra, args.loads)
                    if not got["ok"]:
                        print(f"  {label}: {name}: {got}", file=sys.stderr)
                    runs[name].append(got["s"])
            old, new = statistics.median(runs["base"]), statistics.median(runs["current"])
            ratio = new / old if old else float("nan")
            unit = "" if "ms" in label else " s"
            print(f"{label:30} {old:>8.3f}{unit:2} {new:>8.3f}{unit:2} {ratio:>6.2f}x")
            if checked and ratio > args.limit:
                worse.append(label)
    finally:
        for tree in {base, current} - {ROOT}:
            subprocess.run(["git", "-C", ROOT, "worktree", "remove", "--force", tree], check=False)
        shutil.rmtree(tmp, ignore_errors=True)
    if worse and not args.quick:
        print(f"slower than {args.limit:.2f}x: {', '.join(worse)}")
        return 0 if args.no_fail else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
