"""Synthetic captures for the benchmarks: a ZK ECU status stream from an engine-run model, a
mightyZAP feedback stream, and a MAVLink .tlog of the same number of messages.

The ZK capture models what an ECU sends on a test stand: the status IDs 1..10 in turn at the
configured rate, while a run goes through start, idle, throttle steps and cool-down, with sensor
noise on every analogue value (rpm +-30, EGT +-2 degC, pressure, current, flows). Values are
encoded with the codec's own encoder, so every frame is a valid, realistic frame. ``distinct``
mode instead draws every payload at random (worst case for any per-frame cache).
"""

from __future__ import annotations

import os
import random
import struct
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))

from zkzap.codec import zap, zk  # noqa: E402

#: Where generated captures are kept (git-ignored); ZKZAP_BENCH_DATA puts them elsewhere.
DATA = os.environ.get("ZKZAP_BENCH_DATA") or os.path.join(HERE, "data")

# (seconds, throttle %) steps of one run; rpm follows throttle with a first-order lag
PROFILE = [(20, 0), (15, 0), (30, 20), (30, 40), (30, 60), (30, 80), (20, 100), (30, 50), (30, 0), (40, 0)]
IDLE_RPM = 35000
MAX_RPM = 120000


def zk_engine_frames(count, seed=1, rate_hz=50):
    """``count`` status frames (IDs 1..10 in turn) of repeated engine runs, as bytes objects."""
    rng = random.Random(seed)
    g = rng.gauss
    enc = zk.encode_status
    dt = 1.0 / rate_hz
    frames = []
    t = 0.0
    rpm = 0.0
    egt = 20.0
    fuel_used = 0.0
    step = 0
    step_left = PROFILE[0][0]
    state = 1
    sid = 1
    while len(frames) < count:
        secs, thr = PROFILE[step]
        running = step >= 1 and thr > 0 or (step >= 1 and step < len(PROFILE) - 1)
        target = (IDLE_RPM + (MAX_RPM - IDLE_RPM) * thr / 100) if running else 0
        rpm += (target - rpm) * min(1.0, dt * 10 * 0.8)
        egt += ((450 + 3 * thr if running else 20) - egt) * dt * 10 * 0.3
        flow = 0.1 + 0.9 * thr / 100 if running else 0.0
        fuel_used += flow * dt * 10 / 60
        state = 11 if running else (1 if step == 0 else 12)
        r = max(0, int(rpm + g(0, 30)))
        r = min(r, 655350)
        if sid == 1:
            f = enc(1, rpm=r // 10 * 10, engine_state=state, error_code=0,
                    egt_c=max(-50, min(1997, int(egt + g(0, 2)))), sw_state=2 if running else 1)
        elif sid == 2:
            f = enc(2, rpm=r // 10 * 10, radio_voltage_v=5.0 + round(g(0, 0.1) / 0.2) * 0.2,
                    power_voltage_v=24.0 - round(abs(g(0, 0.2)) / 0.2) * 0.2,
                    pump_voltage_v=round(flow * 8 / 0.2) * 0.2)
        elif sid == 3:
            f = enc(3, rpm=r // 10 * 10, throttle_pct=thr, pressure_pa=101324 + 2 * int(g(0, 2)))
        elif sid == 4:
            f = enc(4, rpm=r // 10 * 10, current_a=max(0.0, round(2 + flow * 15 + g(0, 0.2), 1)),
                    thrust_kg=round(max(0.0, (rpm / MAX_RPM) ** 2 * 14 + g(0, 0.05)), 1))
        elif sid == 5:
            f = enc(5, rpm=r // 10 * 10, ignition_pump_voltage_v=3.2, curve_inc=40, curve_dec=40)
        elif sid == 6:
            f = enc(6, rpm=r // 10 * 10, max_rpm=MAX_RPM // 1000 * 1000, max_pump_voltage_v=10.0,
                    protocol_version=5, status_rate_hz=50)
        elif sid == 7:
            f = enc(7, rpm=r // 10 * 10, fuel_flow_l_min=max(0.0, round(flow + g(0, 0.01), 2)),
                    fuel_used_l=round(fuel_used % 1600, 1))
        elif sid == 8:
            f = enc(8, rpm=r // 10 * 10, idle_rpm=IDLE_RPM // 1000 * 1000, esr=0, scl=1, startup_time_s=12.5)
        elif sid == 9:
            f = enc(9, rpm=r // 10 * 10, ecu_temp_c=int(35 + g(0, 0.5)), prop_rpm=0)
        else:
            f = enc(10, rpm=r // 10 * 10, fuel_pump_rpm=int(flow * 6000 + g(0, 5)) if running else 0)
        frames.append(f)
        sid = sid % 10 + 1
        if sid == 1:
            t += dt * 10
            step_left -= dt * 10
            if step_left <= 0:
                step = (step + 1) % len(PROFILE)
                step_left = PROFILE[step][0]
    return frames


def zk_distinct_frames(count, seed=1):
    """``count`` status frames of IDs 1..10 in turn with random payloads (a worst case for any
    per-frame cache: hardly a frame repeats). Status ID 6 keeps protocol version 5, as a real
    ECU does; its other bits are random."""
    rng = random.Random(seed)
    sf = zk.status_frame
    out = []
    for i in range(count):
        sid = i % 10 + 1
        p = rng.randbytes(5)
        if sid == 6:
            p = p[:4] + bytes(((5 << 2) | (p[4] & 3),))
        out.append(sf(sid, p))
    return out


def zk_capture(count=1_000_000, kind="engine", seed=1):
    """Path of a cached capture of ``count`` frames (generated on first use, in 1M-frame runs)."""
    path = os.path.join(DATA, f"zk-{kind}-{count}-{seed}.bin")
    if os.path.exists(path) and os.path.getsize(path) == 7 * count:
        return path
    gen = zk_engine_frames if kind == "engine" else zk_distinct_frames
    os.makedirs(DATA, exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        done = 0
        while done < count:
            n = min(1_000_000, count - done)
            f.write(b"".join(gen(n, seed=seed + done // 1_000_000)))
            done += n
    os.replace(tmp, path)
    return path


def _positions(count, seed):
    """(ID, position) of ``count`` present-position reads from IDs 1..4, each rod wandering."""
    rng = random.Random(seed)
    pos = [2048, 1000, 3000, 500]
    for i in range(count):
        ident = i % 4 + 1
        pos[ident - 1] = max(0, min(4095, pos[ident - 1] + rng.randint(-8, 8)))
        yield ident, pos[ident - 1]


def zap_feedback_packets(count, seed=1):
    """Feedback packets of present-position reads from IDs 1..4 (``FF FF FF ID 04 00 LL HH CHK``)."""
    return [zap.packet(ident, 0x00, p.to_bytes(2, "little")) for ident, p in _positions(count, seed)]


def dxl_feedback_packets(count, seed=1):
    """The equivalent Dynamixel Protocol 1.0 status packets (``FF FF ID 04 ERR LL HH CHK``)."""
    out = []
    for ident, p in _positions(count, seed):
        body = bytes((ident, 4, 0)) + p.to_bytes(2, "little")
        out.append(b"\xff\xff" + body + bytes((~sum(body) & 0xFF,)))
    return out


def mavlink_tlog(count, path=None, seed=1):
    """A .tlog (8-byte timestamp + MAVLink 2 message) of ``count`` telemetry messages: a cycle of
    HEARTBEAT, ATTITUDE, VFR_HUD, SYS_STATUS, GLOBAL_POSITION_INT, like a vehicle's stream."""
    from pymavlink.dialects.v20 import common as mavlink

    path = path or os.path.join(DATA, f"mav-{count}-{seed}.tlog")
    if os.path.exists(path):
        return path
    os.makedirs(os.path.dirname(path), exist_ok=True)

    class Sink:
        def write(self, b):
            pass

    mav = mavlink.MAVLink(Sink(), srcSystem=1, srcComponent=1)
    rng = random.Random(seed)
    t = 1_700_000_000.0
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        for i in range(count):
            k = i % 5
            if k == 0:
                m = mavlink.MAVLink_heartbeat_message(2, 3, 81, 4, 4, 3)
            elif k == 1:
                m = mavlink.MAVLink_attitude_message(i, rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-3, 3),
                                                     0.01, 0.02, 0.03)
            elif k == 2:
                m = mavlink.MAVLink_vfr_hud_message(20.0 + rng.random(), 21.0, 90, 50, 100.0 + rng.random(), 0.5)
            elif k == 3:
                m = mavlink.MAVLink_sys_status_message(0, 0, 0, 500, 24000, 1500, 80, 0, 0, 0, 0, 0, 0)
            else:
                m = mavlink.MAVLink_global_position_int_message(i, 473977000 + i, 85456000, 500000, 20000, 1, 2, 3,
                                                                9000)
            buf = m.pack(mav)
            f.write(struct.pack(">Q", int(t * 1e6)) + buf)
            t += 0.004
    os.replace(tmp, path)
    return path
