"""mightyZAP transactions against the actuator-bus simulator over a real pty.

    python benchmarks/transactions.py                  # 57600 baud
    python benchmarks/transactions.py --count 5000 --scans 5

Starts ``zkzap sim zap`` (it prints its pty on the first line), then measures:

1. Load Data round trips per second through the library (``ZapBus.transact`` of a
   present-position read, the command ``zap load`` runs), against the line's limit at that
   baud rate (request and reply on the wire, 10 bits a byte, plus a 12Lf's 2 ms turnaround);
   target >= 0.9 x the limit;
2. ``zap load present-position`` as a command, one process per read (what a shell loop gets);
3. full 0..253 ``zap scan`` runs at one baud rate, as commands (``--scans`` of each: the median
   and the best), each of which must find and identify every actuator: a fast bus (target <=
   1.6 s); one actuator 22, 40 or 60 ms late among fast ones (<= 3.5 s) and one 140 ms late
   (<= 5 s); six consecutive IDs at 20 ms with bytes 1 ms apart behind an echoing adapter
   (<= 3.5 s); and, for reference, every actuator at 20 ms with bytes 1 ms apart, with and
   without the echo, and a bus at 40 ms (bytes 1 ms apart or not). benchmarks/slow_buses.py runs
   the other commands on slow buses.

Exits 1 when a target is missed (``--no-fail`` to only report).
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
from common import add_quick, until_ready  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))

IDS = "1,2,3,50,100,200,253"
#: (label, --ids, simulator options, target seconds or None)
BUSES = [
    ("2 ms actuators", IDS, (), 1.6),
    ("one 22 ms late (ID 100)", IDS, ("--fault", "100:delay=20"), 3.5),
    ("one 40 ms late (ID 100)", IDS, ("--fault", "100:delay=38"), 3.5),
    ("one 60 ms late (ID 100)", IDS, ("--fault", "100:delay=58"), 3.5),
    ("one 140 ms late (ID 100)", IDS, ("--fault", "100:delay=138"), 5.0),
    ("IDs 1-6 at 20 ms, bytes 1 ms apart, echoing adapter", "1-6", ("--turnaround", "20", "--gap", "1", "--echo"),
     3.5),
    ("all at 20 ms, bytes 1 ms apart", IDS, ("--turnaround", "20", "--gap", "1"), None),
    ("the same, echoing adapter", IDS, ("--turnaround", "20", "--gap", "1", "--echo"), None),
    ("all at 40 ms", IDS, ("--turnaround", "40"), None),
    ("all at 40 ms, bytes 1 ms apart", IDS, ("--turnaround", "40", "--gap", "1"), None),
]


def tool(name):
    exe = os.path.join(os.path.dirname(sys.executable), name)
    return [exe] if os.path.exists(exe) else [sys.executable, "-m", "zkzap"]


def start_sim(ids, baud, extra=(), stderr=subprocess.DEVNULL):
    env = dict(os.environ, NO_COLOR="1")
    p = subprocess.Popen(tool("zkzap") + ["sim", "zap", "--ids", ids, "-b", str(baud), *extra],
                         stdout=subprocess.PIPE, stderr=stderr, text=True, env=env)
    port = p.stdout.readline().strip()
    if not port:
        p.kill()
        raise SystemExit("simulator did not start")
    return p, port


def timeline(bus, pkt, count, baud):
    """Where a transaction's time goes, from ``count`` more round trips with their reads and
    writes timed: ``reply_late_ms``, how much later than the line allows the reply's last byte
    was read (the simulator and the pty: the line allows request and reply on the wire plus the
    2 ms turnaround), and ``host_ms``, from that read to the next request's write (the library)."""
    events = []
    read, write = bus._read, bus._write

    def timed_read(n, deadline):
        data = read(n, deadline)
        if data:
            events.append(("r", time.monotonic()))
        return data

    def timed_write(p):
        t0 = write(p)
        events.append(("w", t0))
        return t0

    bus._read, bus._write = timed_read, timed_write
    try:
        for _ in range(count):
            bus.transact(pkt)
    finally:
        del bus._read, bus._write
    model = (len(pkt) + 9) * 10 / baud + 0.002
    late, host = [], []
    writes = [i for i, e in enumerate(events) if e[0] == "w"]
    for a, b in zip(writes, writes[1:]):
        reads = [e[1] for e in events[a + 1:b] if e[0] == "r"]
        if reads:
            late.append((reads[-1] - events[a][1] - model) * 1000)
            host.append((events[b][1] - reads[-1]) * 1000)
    return {"reply_late_ms": statistics.median(late), "host_ms": statistics.median(host)}


def expected(ids):
    out = []
    for part in ids.split(","):
        lo, _, hi = part.partition("-")
        out.extend(range(int(lo), int(hi or lo) + 1))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baud", type=int, default=57600)
    ap.add_argument("--count", type=int, default=2000, help="library round trips")
    ap.add_argument("--commands", type=int, default=20, help="zap load processes")
    ap.add_argument("--scans", type=int, default=3, help="scans per bus (median and best shown)")
    ap.add_argument("--scan-ids", default="0-253", help="the IDs a scan probes (the targets are for 0-253)")
    ap.add_argument("--timeout", type=float, default=None,
                    help="reply timeout of the round trips in seconds (default: derived from the baud rate)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-fail", action="store_true")
    add_quick(ap, count=20, commands=2, scans=1, scan_ids="0-10", timeout=1.0)
    args = ap.parse_args(argv)

    from zkzap.codec import zap
    from zkzap.link.port import open_port
    from zkzap.link.zap_bus import ZapBus

    results = {}
    sim, port = start_sim("1,2,3", args.baud)
    try:
        pkt = zap.load(1, "present-position")
        with ZapBus(open_port(port, args.baud, timeout=0), timeout=args.timeout) as bus:
            until_ready(lambda: bus.transact(pkt))              # warm up, once it answers
            t0 = time.perf_counter()
            for _ in range(args.count):
                bus.transact(pkt)
            dt = time.perf_counter() - t0
            parts = timeline(bus, pkt, max(20, args.count // 5), args.baud)
        line = 1.0 / ((len(pkt) + 9) * 10 / args.baud + 0.002)
        results["library"] = {"per_s": args.count / dt, "line_per_s": line, "ratio": args.count / dt / line,
                              **parts}

        env = dict(os.environ, NO_COLOR="1")
        cmd = tool("zap") + ["load", "present-position", "--id", "1", "-p", port, "-b", str(args.baud)]
        if args.timeout is not None:
            cmd += ["--timeout", str(args.timeout)]
        t0 = time.perf_counter()
        for _ in range(args.commands):
            subprocess.run(cmd, check=True, capture_output=True, env=env)
        results["command"] = {"per_s": args.commands / (time.perf_counter() - t0)}
    finally:
        sim.terminate()
        sim.wait(5)
    env = dict(os.environ, NO_COLOR="1")
    scans = []
    for label, ids, extra, target in BUSES:
        want = expected(ids)
        sim, port = start_sim(ids, args.baud, extra)
        try:
            cmd = tool("zap") + ["scan", "-p", port, "-b", str(args.baud), "--ids", args.scan_ids, "-f", "jsonl"]
            lo, _, hi = args.scan_ids.partition("-")
            want = [i for i in want if int(lo) <= i <= int(hi or lo)]
            times, complete = [], True
            for _ in range(args.scans):
                t0 = time.perf_counter()
                r = subprocess.run(cmd, capture_output=True, text=True, env=env)
                times.append(time.perf_counter() - t0)
                got = [json.loads(x) for x in r.stdout.splitlines() if x.strip()]
                identified = [x["id"] for x in got if x["status"] == "ok" and x["model"] is not None]
                complete = complete and identified == want
        finally:
            sim.terminate()
            sim.wait(5)
        scans.append({"bus": label, "median_s": statistics.median(times), "best_s": min(times), "target_s": target,
                      "complete": complete})
    results["scans"] = scans
    full = args.scan_ids == "0-253"
    ok = args.quick or results["library"]["ratio"] >= 0.9 and all(
        s["complete"] and (s["target_s"] is None or not full or s["median_s"] <= s["target_s"]) for s in scans)
    if args.json:
        print(json.dumps(results))
    else:
        lib = results["library"]
        print(f"Load Data round trips over a pty at {args.baud} baud: {lib['per_s']:,.0f}/s "
              f"({1000 / lib['per_s']:.2f} ms each); the line's limit {lib['line_per_s']:.0f}/s: "
              f"{lib['ratio']:.2f}x (target >= 0.9x); a reply's last byte read {lib['reply_late_ms']:.2f} ms after "
              f"the line allows (the simulator and the pty), the next request written {lib['host_ms']:.2f} ms "
              "after it (the library)")
        print(f"zap load as a command: {results['command']['per_s']:.1f}/s")
        for s in scans:
            verdict = "" if s["target_s"] is None or not full else \
                f"  target <= {s['target_s']:g} s {'met' if s['median_s'] <= s['target_s'] else 'NOT met'}"
            scope = "full 0..253" if full else "IDs " + args.scan_ids
            print(f"{scope} scan at {args.baud} baud, {s['bus']}: median {s['median_s']:.2f} s, best "
                  f"{s['best_s']:.2f} s, {'every actuator found and identified' if s['complete'] else 'INCOMPLETE'}"
                  f"{verdict}")
    return 0 if ok or args.no_fail else 1


if __name__ == "__main__":
    sys.exit(main())
