"""The telemetry bridges at the ECU's fastest rate: CPU and lag of ``zk monitor`` at 100 Hz with
MQTT, MAVLink and an MCAP log on, against plain JSON Lines.

    python benchmarks/bridges.py                      # 3 rounds of 10 s each
    python benchmarks/bridges.py --seconds 20 --rounds 5

Starts ``zkzap sim zk --rate 100`` on a pty (a separate process, as a real ECU would be), a
Mosquitto broker on a free loopback port with a subscriber, and a UDP socket as the ground
station. Each round runs, interleaved:

1. ``zk monitor -p PTY --duration S -f jsonl`` (stdout read by this script), and
2. ``zk monitor -p PTY --duration S -o run.mcap --mqtt mqtt://.../bench --mavlink udpout:...``

and takes the CPU time (user + system) of that process alone (``wait4``). Lag: the frames the
monitor recorded against the 100 per second the ECU sent, the longest gap between two records,
the MQTT latency (record time to the subscriber's arrival), the bridges' drop counters. Target:
the bridged run uses <= 2x the CPU of plain JSON Lines and never lags (no drops, no gap).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))


def tool(name):
    exe = os.path.join(os.path.dirname(sys.executable), name)
    return [exe] if os.path.exists(exe) else [sys.executable, "-m", "zkzap"]


def free_port(kind=socket.SOCK_STREAM):
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_broker(work):
    exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    if not os.access(exe, os.X_OK):
        raise SystemExit("mosquitto is not installed (apt-get install mosquitto)")
    port = free_port()
    conf = os.path.join(work, "mosquitto.conf")
    with open(conf, "w") as f:
        import pwd

        f.write(f"listener {port} 127.0.0.1\nallow_anonymous true\nuser {pwd.getpwuid(os.getuid()).pw_name}\n")
    p = subprocess.Popen([exe, "-c", conf], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
            return p, port
        except OSError:
            time.sleep(0.02)
    p.kill()
    raise SystemExit("mosquitto did not start")


class Subscriber:
    def __init__(self, port):
        import paho.mqtt.client as mqtt

        self.latencies = []
        self.count = 0
        ready = threading.Event()
        c = self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="zkzap-bench", clean_session=True)
        c.on_connect = lambda cl, *a: cl.subscribe("bench/status/#", qos=0)
        c.on_subscribe = lambda *a: ready.set()
        c.on_message = self._on_message
        c.connect("127.0.0.1", port)
        c.loop_start()
        ready.wait(10)

    def _on_message(self, client, userdata, msg):
        now = time.time()
        rec = json.loads(msg.payload)
        t = rec["time"]
        import calendar

        sent = calendar.timegm(time.strptime(t[:19], "%Y-%m-%dT%H:%M:%S")) + int(t[20:23]) / 1000
        self.latencies.append(now - sent)
        self.count += 1

    def take(self):
        out, self.latencies, self.count = self.latencies, [], 0
        return out

    def close(self):
        self.client.disconnect()
        self.client.loop_stop()


def ground_station(stop):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(0.2)
    got = {"datagrams": 0}

    def run():
        while not stop.is_set():
            try:
                s.recv(4096)
                got["datagrams"] += 1
            except socket.timeout:
                pass
        s.close()

    threading.Thread(target=run, daemon=True).start()
    return s.getsockname()[1], got


def run_monitor(args):
    """(cpu seconds, stdout, stderr) of one ``zk monitor`` process."""
    env = dict(os.environ, NO_COLOR="1")
    p = subprocess.Popen(tool("zk") + ["monitor", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    out_chunks, err_chunks = [], []
    t_out = threading.Thread(target=lambda: out_chunks.append(p.stdout.read()))
    t_err = threading.Thread(target=lambda: err_chunks.append(p.stderr.read()))
    t_out.start()
    t_err.start()
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    t_out.join()
    t_err.join()
    if p.returncode != 0:
        raise SystemExit(f"zk monitor {' '.join(args)}: exit {p.returncode}: {err_chunks[0].decode()[-800:]}")
    return usage.ru_utime + usage.ru_stime, out_chunks[0].decode(), err_chunks[0].decode()


def gaps(ts):
    return max((b - a for a, b in zip(ts, ts[1:])), default=0.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=3)
    add_quick(ap, seconds=1.5, rounds=1)
    a = ap.parse_args()

    from mcap.reader import make_reader

    work = tempfile.mkdtemp(prefix="zkzap-bench-")
    sim = subprocess.Popen(tool("zkzap") + ["sim", "zk", "--rate", "100"], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    pty = sim.stdout.readline().strip()
    broker, mport = start_broker(work)
    sub = Subscriber(mport)
    stop = threading.Event()
    uport, gcs = ground_station(stop)
    mcap = os.path.join(work, "run.mcap")
    plain_cpu, bridged_cpu, plain_start, bridged_start = [], [], [], []
    plain_args = ["-f", "jsonl"]
    lat, worst_gap, dropped, fps = [], 0.0, 0, []
    try:
        bridged_args = ["-o", mcap, "--mqtt", f"mqtt://127.0.0.1:{mport}/bench", "--mavlink", f"udpout:127.0.0.1:{uport}"]
        for r in range(a.rounds):
            # start-up and shut-down alone: the same commands for half a second
            plain_start.append(run_monitor(["-p", pty, "--duration", "0.5", *plain_args])[0])
            bridged_start.append(run_monitor(["-p", pty, "--duration", "0.5", *bridged_args])[0])
            time.sleep(0.3)
            sub.take()                                  # not this run's latencies
            cpu, out, _ = run_monitor(["-p", pty, "--duration", str(a.seconds), *plain_args])
            plain_cpu.append(cpu)
            n_plain = out.count("\n")
            cpu, _, err = run_monitor(["-p", pty, "--duration", str(a.seconds), *bridged_args])
            bridged_cpu.append(cpu)
            with open(mcap, "rb") as f:
                ts = sorted(m.log_time / 1e9 for _, _, m in make_reader(f).iter_messages(log_time_order=False))
            worst_gap = max(worst_gap, gaps(ts))
            fps.append(len(ts) / a.seconds)
            dropped += sum(int(x) for x in re.findall(r"(\d+) dropped", err))
            time.sleep(0.3)
            lats = sub.take()
            lat += lats
            print(f"round {r + 1}: plain {plain_cpu[-1]:.2f} s CPU ({n_plain} records), bridged "
                  f"{bridged_cpu[-1]:.2f} s CPU ({len(ts)} records in MCAP, {len(lats)} via MQTT)", flush=True)
    finally:
        stop.set()
        sub.close()
        broker.terminate()
        sim.terminate()
        broker.wait(10)
        sim.wait(10)
        shutil.rmtree(work, ignore_errors=True)
    ratio = statistics.median(bridged_cpu) / statistics.median(plain_cpu)
    lat.sort()
    p50 = lat[len(lat) // 2] * 1000 if lat else float("nan")
    p99 = lat[int(len(lat) * 0.99)] * 1000 if lat else float("nan")
    print(f"CPU, median of {a.rounds} x {a.seconds:g} s at 100 Hz: plain JSON Lines {statistics.median(plain_cpu):.2f} s, "
          f"MQTT+MAVLink+MCAP {statistics.median(bridged_cpu):.2f} s: {ratio:.2f}x (target <= 2x: "
          f"{'met' if ratio <= 2 else 'NOT met'})")
    med = statistics.median
    steady_plain = (med(plain_cpu) - med(plain_start)) / (a.seconds - 0.5)
    steady_bridged = (med(bridged_cpu) - med(bridged_start)) / (a.seconds - 0.5)
    print(f"start-up and shut-down: plain {med(plain_start):.2f} s, bridged {med(bridged_start):.2f} s CPU; "
          f"steady state: plain {steady_plain * 1000:.1f} ms/s, bridged {steady_bridged * 1000:.1f} ms/s CPU: "
          f"{steady_bridged / steady_plain:.2f}x")
    print(f"lag: {min(fps):.1f}..{max(fps):.1f} records/s of 100, longest gap {worst_gap * 1000:.0f} ms, "
          f"{dropped} dropped by the bridges, MQTT latency p50 {p50:.1f} ms p99 {p99:.1f} ms, "
          f"{gcs['datagrams']} MAVLink datagrams")


if __name__ == "__main__":
    main()
