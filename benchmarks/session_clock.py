#!/usr/bin/env python3
"""One clock on a simulator faster than real time: rates, spans and dates of a ZK session.

Runs ``zk send control --state run --throttle 30 --for SECONDS --rate HZ`` on
``sim://zk?speed=SPEED`` (the installed ``zk``, as a user runs it) with ``--capture``, ``-o
run.mcap`` and ``--logbook``, then prints:

- control frames sent (from the capture) against SECONDS x HZ, the ratio (target >= 0.9);
- status frames against SECONDS x the ECU's 20 Hz;
- the MCAP control and status channels' spans of log time, and their ratio (target 1.0 +- 0.05:
  both on the session's clock);
- the logbook's ``ended`` against the moment the run ended, in seconds (target <= 1: never in
  the future).

Exits 1 when a target is missed (``--no-fail`` to only report; ``--quick``, a 2 s run, checks
no target).

    python benchmarks/session_clock.py [--seconds 50] [--rate 20] [--speed 10] [--json] [--quick]
"""

from __future__ import annotations

import argparse
import calendar
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)                                   # common.py, beside this script
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))
from common import add_quick  # noqa: E402


def _zk():
    path = os.path.join(os.path.dirname(sys.executable), "zk")
    return path if os.path.exists(path) else "zk"


def _epoch(text):
    return calendar.timegm(time.strptime(text[:19], "%Y-%m-%dT%H:%M:%S"))


def measure(seconds, rate, speed):
    from mcap.reader import make_reader

    from zkzap.link.capture import CaptureFrames
    from zkzap.link.pcapng import INBOUND, OUTBOUND

    with tempfile.TemporaryDirectory() as d:
        cap, mcap, book = (os.path.join(d, n) for n in ("run.pcapng", "run.mcap", "book.db"))
        env = {k: v for k, v in os.environ.items() if not k.startswith("ZKZAP_")}
        subprocess.run([_zk(), "send", "control", "--state", "run", "--throttle", "30", "--for", str(seconds),
                        "--rate", str(rate), "--end", "hold", "-p", f"sim://zk?speed={speed}", "--capture", cap,
                        "-o", mcap, "--logbook", book], check=True, env=env, stderr=subprocess.DEVNULL)
        ended_real = time.time()
        frames = CaptureFrames(cap, "zk")
        control = sum(1 for _, direction, f in frames if direction == OUTBOUND)
        frames.reader.close()
        frames = CaptureFrames(cap, "zk")
        status = sum(1 for _, direction, f in frames if direction == INBOUND)
        frames.reader.close()
        spans = {}
        with open(mcap, "rb") as f:
            for _, channel, message in make_reader(f).iter_messages():
                kind = channel.topic.split("/")[2]
                lo, hi = spans.get(kind, (message.log_time, message.log_time))
                spans[kind] = (min(lo, message.log_time), max(hi, message.log_time))
        out = subprocess.run([_zk(), "logbook", book, "-f", "json"], check=True, env=env, capture_output=True,
                             text=True).stdout
        run = json.loads(out)["runs"][0]
    span = {k: (hi - lo) / 1e9 for k, (lo, hi) in spans.items()}
    return {
        "control_frames": control, "control_expected": round(seconds * rate),
        "control_ratio": control / (seconds * rate),
        "status_frames": status, "status_expected": round(seconds * 20),
        "mcap_control_span_s": span.get("control"), "mcap_status_span_s": span.get("status"),
        "mcap_span_ratio": span["control"] / span["status"] if span.get("status") and "control" in span else None,
        "logbook_ended_ahead_s": _epoch(run["ended"]) - ended_real, "logbook_duration_s": run["duration_s"],
    }


def _num(value, spec):
    """``value`` formatted, or "n/a" (a channel with no message: a run starved of time)."""
    return "n/a" if value is None else format(value, spec)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=50.0)
    ap.add_argument("--rate", type=float, default=20.0)
    ap.add_argument("--speed", type=float, default=10.0)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-fail", action="store_true")
    add_quick(ap, seconds=2.0)
    a = ap.parse_args(argv)
    m = measure(a.seconds, a.rate, a.speed)
    ok = (m["control_ratio"] >= 0.9 and m["mcap_span_ratio"] is not None and abs(m["mcap_span_ratio"] - 1) <= 0.05
          and m["logbook_ended_ahead_s"] <= 1.0)
    if a.json:
        print(json.dumps(dict(m, ok=ok)))
    else:
        print(f"speed {a.speed:g}, --for {a.seconds:g} at {a.rate:g} Hz")
        print(f"  control frames {m['control_frames']} of {m['control_expected']}: {m['control_ratio']:.3f}x "
              f"(target >= 0.9)")
        print(f"  status frames {m['status_frames']} of about {m['status_expected']}")
        print(f"  MCAP span control {_num(m['mcap_control_span_s'], '.2f')} s / status "
              f"{_num(m['mcap_status_span_s'], '.2f')} s: {_num(m['mcap_span_ratio'], '.3f')}x (target 1.0)")
        print(f"  logbook ended {m['logbook_ended_ahead_s']:+.1f} s from the real end (target <= +1; "
              f"duration {m['logbook_duration_s']:g} s of session time)")
    return 0 if ok or a.no_fail or a.quick else 1


if __name__ == "__main__":
    sys.exit(main())
