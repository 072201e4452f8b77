"""zkzap against its peers, side by side in one run.

    pip install '.[bench]'                 # pymavlink, dynamixel-sdk
    python benchmarks/peers.py             # 1,000,000 messages / 200,000 packets
    python benchmarks/peers.py --frames 200000 --packets 50000

1. Capture to JSON: ``zk decode --binary CAPTURE -f jsonl`` on the ECU-model capture of
   ``--frames`` status frames, against pymavlink's ``mavlogdump.py --format json`` on a .tlog
   of as many MAVLink 2 telemetry messages (HEARTBEAT, ATTITUDE, VFR_HUD, SYS_STATUS,
   GLOBAL_POSITION_INT), both generated here. Target: zkzap >= 6x mavlogdump's messages/s.
2. Library stream decoding: mightyZAP feedback packets (present-position replies of 4 IDs,
   ``FF FF FF ID 04 00 LL HH CHK``) through ``ZapFramer``, against Dynamixel SDK's Protocol
   1.0 ``rxPacket`` on the equivalent status packets (``FF FF ID 04 00 LL HH CHK``), both
   reading from an in-memory port (a BytesIO as the port's serial object). Like for like,
   both return checked raw packets: zkzap reading what is there (4 KiB at a time) and, the
   stricter figure, one packet per read as rxPacket does. Target: >= 2x rxPacket's packets/s.
   Also shown: ZapFramer + ZapDecoder, which builds a named record per packet (kind, id,
   error, error names, params, value): more work than rxPacket does.
"""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import captures  # noqa: E402
from zk_decode import timed, zk_command  # noqa: E402
from common import add_quick  # noqa: E402

def mavlogdump():
    exe = os.path.join(os.path.dirname(sys.executable), "mavlogdump.py")
    if not os.path.exists(exe):
        raise SystemExit("mavlogdump.py not found: pip install pymavlink (or '.[bench]')")
    return [sys.executable, exe]


def capture_vs_mavlogdump(n, repeat):
    cap = captures.zk_capture(n, "engine")
    tlog = captures.mavlink_tlog(n)
    check = subprocess.run(mavlogdump() + ["--format", "json", tlog], capture_output=True)
    got = check.stdout.count(b"\n")
    if check.returncode or got != n:
        raise SystemExit(f"mavlogdump printed {got} messages of {n}: {check.stderr.decode()[-300:]}")
    # CPU seconds (timed gives CPU and wall), as zk_decode.py compares
    ours = min(timed(zk_command() + ["decode", "--binary", cap, "-f", "jsonl"])[0] for _ in range(repeat))
    theirs = timed(mavlogdump() + ["--format", "json", tlog])[0]
    return ours, theirs


def zap_stream(data, chunk, records=False):
    from zkzap.codec.framing import ZapFramer
    from zkzap.codec.zap import ZapDecoder

    port = io.BytesIO(data)
    framer = ZapFramer()
    decode = ZapDecoder().decode
    read = port.read
    feed = framer.feed
    n = 0
    last = None
    while True:
        block = read(chunk)
        if not block:
            break
        packets = feed(block)
        n += len(packets)
        if records:
            for p in packets:
                last = decode(p)
        elif packets:
            last = packets[-1]
    for p in framer.flush():
        last = decode(p) if records else p
        n += 1
    return n, last


def dxl_stream(data, count):
    from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

    port = PortHandler("memory")
    port.ser = io.BytesIO(data)
    port.is_open = True
    handler = PacketHandler(1.0)
    n = 0
    last = None
    for _ in range(count):
        pkt, result = handler.rxPacket(port)
        if result != COMM_SUCCESS:
            raise SystemExit(f"rxPacket: {handler.getRxPacketError(result) if result > 0 else result}")
        last = pkt
        n += 1
    return n, last


def best(fn, repeat):
    times = []
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=1_000_000, help="ZK frames / MAVLink messages")
    ap.add_argument("--packets", type=int, default=200_000, help="mightyZAP / Dynamixel packets")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-mavlink", action="store_true")
    add_quick(ap, frames=500, packets=500, repeat=1)
    args = ap.parse_args(argv)

    if not args.skip_mavlink:
        n = args.frames
        ours, theirs = capture_vs_mavlogdump(n, args.repeat)
        ratio = (n / ours) / (n / theirs)
        print(f"capture -> JSON, {n:,} messages, CPU time: zk decode {ours:.2f} s ({n / ours:,.0f}/s), "
              f"mavlogdump.py {theirs:.2f} s ({n / theirs:,.0f}/s): {ratio:.1f}x  "
              f"target >= 6x {'met' if ratio >= 6 else 'NOT met'}")

    k = args.packets
    zap_data = b"".join(captures.zap_feedback_packets(k))
    dxl_data = b"".join(captures.dxl_feedback_packets(k))
    size = len(zap_data) // k
    t_dxl, (n_dxl, last_dxl) = best(lambda: dxl_stream(dxl_data, k), args.repeat)
    runs = [("ZapFramer, 4 KiB reads", 4096, False), ("ZapFramer, one packet per read", size, False),
            ("ZapFramer + ZapDecoder records, 4 KiB reads", 4096, True)]
    print(f"feedback packets, {k:,}: Dynamixel SDK rxPacket {k / t_dxl:,.0f} packets/s")
    for label, chunk, records in runs:
        t, (n, last) = best(lambda: zap_stream(zap_data, chunk, records), args.repeat)
        assert n == n_dxl == k, (n, n_dxl)
        verdict = f"target >= 2x {'met' if t_dxl / t >= 2 else 'NOT met'}" if not records else "(more work)"
        print(f"  zkzap {label}: {k / t:,.0f} packets/s, {t_dxl / t:.1f}x  {verdict}")
    print(f"  last zkzap record: {last}")
    print(f"  last rxPacket: {last_dxl}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
