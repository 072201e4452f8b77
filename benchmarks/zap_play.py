"""zap play: how late the goals leave, over a real pty to the bus simulator.

    python benchmarks/zap_play.py                     # 6 actuators, 57600 baud, 50 Hz, 5 rounds of 4 s
    python benchmarks/zap_play.py --ids 1-8 --baud 115200 --rate 100
    python benchmarks/zap_play.py --protocol modbus    # 17Lf actuators: the rate the line carries (14 Hz)

Starts ``zkzap sim zap --ids ...`` (its pty on the first line) and plays, with the library's
player (:class:`zkzap.api.motion.Player`, what ``zap play`` runs), a linear path of every
actuator across the stroke and back, interpolated at ``--rate``: one sync move per step, and
the log reads in between (goal vs present, current, voltage). A step's lateness is the time
from its due time to when its first byte is handed to the port. Each round prints p50, p99
and max lateness and the log rows read; the target is p99 <= 2 ms at 57600 baud for 6
actuators at 50 Hz. A line plays the same path without log reads (the schedule alone); the
last one runs ``zap cycle``'s poller (:class:`zkzap.api.cycle.Cycler`) on the first actuator:
its polls per second against the wire limit (target >= 0.8x, as ``zap watch``). With
``--protocol modbus`` the same over Modbus RTU (one answered write per actuator and step: the
default rate is then what the line carries, when less than 50 Hz).
"""

from __future__ import annotations

import argparse
import io
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick, until_ready  # noqa: E402
from zap_watch import start_sim  # noqa: E402 - the simulator on a pty, as zap_watch.py starts it

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))

TARGET_MS = 2.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baud", type=int, default=57600)
    ap.add_argument("--ids", default="1-6")
    ap.add_argument("--rate", type=float, default=None, help="steps per second (default 50, or what the line "
                    "carries when less)")
    ap.add_argument("--protocol", choices=("ir", "modbus"), default="ir")
    ap.add_argument("--seconds", type=float, default=4.0, help="length of the path played each round")
    ap.add_argument("--rounds", type=int, default=5)
    add_quick(ap, seconds=0.4, rounds=1)
    args = ap.parse_args(argv)

    from zkzap.api import motion
    from zkzap.link.port import open_port
    from zkzap.link.zap_bus import ZapBus
    from zkzap.sim.zap_actuators import parse_ids

    ids = [i for i, _ in parse_ids(args.ids)]
    every = '"' + ",".join(map(str, ids)) + '"'
    half = args.seconds / 2
    text = f"t,id,position\n0,{every},200\n{half:g},{every},3400\n{args.seconds:g},{every},200\n"
    wire = motion.wire_for(args.protocol)
    rows = motion.read_path(io.StringIO(text), name="path", protocol=wire)
    plan = motion.plan(rows, baud=args.baud, interpolate="linear", rate=args.rate, protocol=wire)
    print(plan.note)
    sim, port = start_sim(args.ids, args.baud, args.protocol)
    if args.protocol == "modbus":
        from zkzap.link.modbus_bus import ModbusBus as ZapBus  # noqa: F811 - the same transactions, Modbus RTU
    worst = None
    rate = plan.rate
    try:
        with ZapBus(open_port(port, args.baud, timeout=0)) as bus:
            until_ready(lambda: bus.echo(ids[0]))
            for n in range(args.rounds + 1):
                log = n < args.rounds
                player = motion.Player(bus, plan, log=log, settle=0.5)
                got = sum(1 for _ in player.rows())
                s = player.summary()
                if log:
                    worst = s["lateness_p99_ms"] if worst is None else max(worst, s["lateness_p99_ms"])
                label = f"round {n + 1}" if log else "no log reads"
                print(f"{label:13s} {len(ids)} IDs at {args.baud} baud, {rate:g} Hz: {s['steps']} steps, lateness "
                      f"p50 {s['lateness_p50_ms']:.3f} ms, p99 {s['lateness_p99_ms']:.3f} ms, max "
                      f"{s['lateness_max_ms']:.3f} ms; {got} log rows ({got / max(1, s['steps']):.2f} a step), "
                      f"{s['read_failures']} unanswered")
            from zkzap.api.cycle import Cycler

            c = Cycler(bus, ids[0], 200, 3400, dwell=0.1, cycles=max(1, args.rounds))
            n = sum(1 for _ in c.run())
            ratio = c.achieved / c.wire_limit()
            print(f"zap cycle     ID {ids[0]} at {args.baud} baud: {n} cycles, {c.achieved:.1f} polls/s, wire limit "
                  f"{c.wire_limit():.1f}/s -> {ratio:.2f}x  target >= 0.8x {'met' if ratio >= 0.8 else 'NOT met'}")
    finally:
        sim.terminate()
        sim.wait(5)
    met = worst is not None and worst <= TARGET_MS
    print(f"worst p99 {worst:.3f} ms: target <= {TARGET_MS:g} ms {'met' if met else 'NOT met'}")
    return 0 if (met and ratio >= 0.8) or args.quick else 1


if __name__ == "__main__":
    sys.exit(main())
