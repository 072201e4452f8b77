"""Slow buses, command by command: what a user sees on actuators that answer late.

    python benchmarks/slow_buses.py                 # full 0..253 scans, 20 echoes
    python benchmarks/slow_buses.py --scans 3

Starts ``zkzap sim zap`` on a pty for each bus and runs the commands as a user would (one
process each, default options: the 150 ms late window, nothing widened):

1. IDs 1 and 2, ID 2 answering 22 ms late (``--fault 2:delay=20``): a full ``zap scan``
   (target <= 3.5 s, both found and identified);
2. IDs 1-6 at a 20 ms turnaround, bytes 1 ms apart, behind an echoing adapter: a full scan
   (target <= 3.5 s, all six identified);
3. IDs 1 and 2 at a 40 ms turnaround, bytes 1 ms apart: ``zap echo --count N`` (echoes lost,
   ``rtt_ms`` against the line's own time: request and reply on the wire, the turnaround, the
   gaps), ``zap backup`` without ``--ids``, ``zap diff FILE bus``, and the latency the library
   learned (``Bus.latencies``) against the simulated 40 ms;
4. two actuators sharing ID 1 (``--ids 1,1``) and ID 2: ``zap backup`` must refuse (exit 1,
   naming ID 1) and ``zap watch`` must name the garbled replies (exit 6), never say "no reply".

The simulator reports every collision on its stderr (``collision at ...``): none may come from
the echoes or the API loop; a scan's first pass, which moves on early and then asks again,
may meet late replies on the line (counted, shown).
Prints one line per measurement; exits 1 when a check or target fails (``--no-fail``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick  # noqa: E402
from transactions import start_sim, tool  # noqa: E402

BAUD = 57600
BYTE_S = 10 / BAUD


def run(args, env):
    t0 = time.perf_counter()
    p = subprocess.run(args, capture_output=True, text=True, env=env, timeout=300)
    return p, time.perf_counter() - t0


def with_sim(ids, extra, body):
    """``body(port, tmp, collisions)`` with a simulator of ``ids``; ``collisions()`` counts the
    collisions it has reported so far (its stderr), which the result carries too."""
    with tempfile.TemporaryDirectory() as tmp:
        err_path = os.path.join(tmp, "sim.err")

        def collisions():
            time.sleep(0.2)                       # the simulator's last lines
            with open(err_path) as f:
                return sum("collision" in line for line in f)

        with open(err_path, "w") as err:
            sim, port = start_sim(ids, BAUD, extra, stderr=err)
            try:
                out = body(port, tmp, collisions)
            finally:
                sim.terminate()
                sim.wait(5)
        return out, collisions()


def scan_bus(label, ids, extra, want, target, args, env, failures):
    def body(port, _tmp, _collisions):
        times, good = [], True
        for _ in range(args.scans):
            p, dt = run(tool("zap") + ["scan", "-p", port, "--ids", args.scan_ids, "-f", "jsonl"], env)
            times.append(dt)
            recs = [json.loads(x) for x in p.stdout.splitlines() if x.strip()]
            good = good and [(r["id"], r["status"], r["model"] is not None) for r in recs] == \
                [(i, "ok", True) for i in want]
        return times, good

    (times, good), collisions = with_sim(ids, extra, body)
    med = statistics.median(times)
    met = args.scan_ids != "0-253" or med <= target
    print(f"{label}: scan of IDs {args.scan_ids} median {med:.2f} s (best {min(times):.2f} s, target <= "
          f"{target:g} s {'met' if met else 'NOT met'}); "
          f"{'every actuator found and identified' if good else 'INCOMPLETE'}; {collisions / args.scans:.1f} "
          "collisions a scan (first passes, which move on early, then ask again)")
    if not (good and met):
        failures.append(label)


def slow_commands(args, env, failures):
    label = "IDs 1,2 at 40 ms, bytes 1 ms apart"
    turnaround, gap = 0.040, 0.001

    def body(port, tmp, collisions):
        out = {}
        p, _ = run(tool("zap") + ["echo", "--id", "1", "--count", str(args.echoes), "-p", port, "-f", "jsonl"], env)
        rtts = [json.loads(x)["rtt_ms"] for x in p.stdout.splitlines() if x.strip()]
        out["echo"] = (p.returncode, len(rtts), rtts)
        out["echo_collisions"] = collisions()
        fleet = os.path.join(tmp, "fleet.json")
        p, dt = run(tool("zap") + ["backup", "-p", port, "-o", fleet], env)
        found = len(json.load(open(fleet))["actuators"]) if p.returncode == 0 else 0
        out["backup"] = (p.returncode, found, dt, p.stderr.strip().splitlines()[-1:] if p.stderr else [])
        p, dt = run(tool("zap") + ["diff", fleet, "bus", "-p", port, "-f", "jsonl"], env)
        out["diff"] = (p.returncode, dt, p.stdout.count("\n"))
        sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cli"))
        from zkzap import Bus

        before = collisions()
        with Bus(port) as bus:
            for _ in range(args.echoes):
                bus.echo(1)
                bus.load(2, "present-position")
            out["learned"] = bus.latencies.get(1)
        out["api_collisions"] = collisions() - before
        return out

    out, collisions = with_sim("1,2", ("--turnaround", "40", "--gap", "1"), body)
    code, answered, rtts = out["echo"]
    # request 7 bytes, reply 7 bytes with a gap after each but the last, the turnaround between
    line_ms = (7 * BYTE_S + turnaround + 7 * BYTE_S + 6 * gap) * 1000
    avg = statistics.mean(rtts) if rtts else float("nan")
    print(f"{label}: zap echo --count {args.echoes}: {args.echoes - answered} of {args.echoes} lost (exit {code}); "
          f"rtt_ms mean {avg:.2f} (min {min(rtts, default=0):.2f}, max {max(rtts, default=0):.2f}), "
          f"the line's own {line_ms:.2f} ms")
    code_b, found, dt_b, tail = out["backup"]
    print(f"{label}: zap backup (no --ids): exit {code_b}, {found} actuators backed up in {dt_b:.2f} s")
    code_d, dt_d, rows = out["diff"]
    print(f"{label}: zap diff FILE bus: exit {code_d}, {rows} differences, {dt_d:.2f} s")
    learned = out["learned"]
    if learned:
        print(f"{label}: learned latency of ID 1 {learned['latency_ms']:.2f} ms (variation "
              f"{learned['variation_ms']:.2f} ms, {learned['samples']} answers, {learned['late']} late); simulated "
              f"{turnaround * 1000:.0f} ms turnaround + the first reply byte {BYTE_S * 1000:.2f} ms")
    print(f"{label}: collisions: {out['echo_collisions']} during the echoes, {out['api_collisions']} during "
          f"{args.echoes} Echo + Load pairs from the API, {collisions} in all (the rest: the first passes of the "
          "scans that find the fleet for backup and diff)")
    ok = (code == 0 and answered == args.echoes and code_b == 0 and found == 2 and code_d == 0
          and out["echo_collisions"] == 0 and out["api_collisions"] == 0
          and learned is not None and latency_fits(learned["latency_ms"], turnaround * 1000, args))
    if not ok:
        failures.append(label)


def latency_fits(learned_ms: float, turnaround_ms: float, args) -> bool:
    """Whether the learned latency is the simulated turnaround: within 10 ms of it over the
    default run's echoes. The quick run's figures mean nothing (its two replies, on a machine
    shared with the test suite, may each be held up by the scheduler for any time): there it
    is only never shorter than the turnaround (a host held up makes a reply look later, never
    sooner), within a millisecond of rounding."""
    if args.echoes <= 5:
        return learned_ms > turnaround_ms - 1.0
    return abs(learned_ms - turnaround_ms) < 10.0


def shared_id(args, env, failures):
    label = "two actuators sharing ID 1, and ID 2"

    def body(port, tmp, _collisions):
        b, _ = run(tool("zap") + ["backup", "-p", port, "--ids", "0-4", "--scan", "-o", os.path.join(tmp, "f.json")],
                   env)
        w, _ = run(tool("zap") + ["watch", "present-position", "--ids", "1", "--duration", "0.5", "-p", port,
                                  "-f", "jsonl"], env)
        return b, w, os.path.exists(os.path.join(tmp, "f.json"))

    (b, w, written), _ = with_sim("1,1,2", (), body)
    last = lambda p: (p.stderr.strip().splitlines() or [""])[-1]  # noqa: E731
    print(f"{label}: zap backup: exit {b.returncode}, {'a file written' if written else 'nothing written'}: "
          f"{last(b)}")
    print(f"{label}: zap watch: exit {w.returncode}: {last(w)}")
    if not (b.returncode == 1 and not written and "ID 1" in b.stderr and w.returncode == 6
            and "garbled" in w.stderr):
        failures.append(label)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scans", type=int, default=3, help="scans per bus (median and best shown)")
    ap.add_argument("--scan-ids", default="0-253", help="the IDs a scan probes (the targets are for 0-253)")
    ap.add_argument("--echoes", type=int, default=20, help="echoes on the 40 ms bus")
    ap.add_argument("--no-fail", action="store_true")
    add_quick(ap, scans=1, scan_ids="0-10", echoes=2)
    args = ap.parse_args(argv)
    env = dict(os.environ, NO_COLOR="1")
    failures: list = []
    scan_bus("IDs 1,2, ID 2 22 ms late", "1,2", ("--fault", "2:delay=20"), [1, 2], 3.5, args, env, failures)
    scan_bus("IDs 1-6 at 20 ms, bytes 1 ms apart, echoing adapter", "1-6",
             ("--turnaround", "20", "--gap", "1", "--echo"), [1, 2, 3, 4, 5, 6], 3.5, args, env, failures)
    slow_commands(args, env, failures)
    shared_id(args, env, failures)
    print(f"{'every check passed' if not failures else 'FAILED: ' + '; '.join(failures)}")
    return 0 if not failures or args.no_fail else 1


if __name__ == "__main__":
    sys.exit(main())
