"""Find a ZK ECU's line settings by listening: baud rate, stop bits, protocol version, status rate
(:func:`detect`); and which protocol and baud rate a mightyZAP bus speaks (:func:`detect_bus`,
at the end).

The ZK document lets the ECU's UART run at 2400 .. 115200 baud, 8 data bits, no parity, 1 or 2
stop bits, and an ECU streams status frames on its own. :func:`detect` listens at each setting
in turn (it never transmits unless ``probe`` asks it to send keep-alives) until CRC-valid status
frames arrive, then listens on for a status ID 6 frame to report the protocol version and the
status rate.

Policy, per baud rate (the document's list, commonest first):

1. listen with 1 stop bit, which reads a 1- and a 2-stop-bit sender alike; give up on the
   setting as soon as enough bytes came without a valid frame (garbage: the wrong baud rate),
   or when its listening window passes;
2. once frames decode, listen again with 2 stop bits: a sender using 1 stop bit misframes there
   (back-to-back bytes hit the second stop bit), so frames that still decode mean the ECU uses
   2. (A lenient receiver that checks only the first stop bit reads both: then 2 is reported,
   which is also safe to send with.)

A setting counts as found with :data:`FRAMES_NEEDED` valid frames; the time budget bounds the
whole search and is reported with the result.
"""

from __future__ import annotations

import time

from ..codec import zk
from ..codec.framing import ZkFramer
from ..errors import NoReply

#: The baud rates the ZK document lists, in the order they are tried (commonest first).
BAUDS = (115200, 57600, 38400, 19200, 9600, 4800, 2400)
#: Valid status frames that make a setting found.
FRAMES_NEEDED = 3
#: Bytes without one valid frame after which a setting is given up (three frames' worth).
GIVE_UP_BYTES = 3 * zk.STATUS_LEN + 7
#: Default listening window per setting (seconds): three frames at the lowest status rate (20 Hz)
#: plus their time on the wire at 2400 baud, plus margin.
WINDOW_S = 0.35
#: Default budget for the whole search (seconds).
BUDGET_S = 12.0
#: After a setting is found: how long to wait for a status ID 6 (more than a cycle at 20 Hz).
VERSION_WAIT_S = 0.8


class Attempt:
    """What one line setting gave: ``frames`` valid, ``bad`` CRC failures, ``bytes`` received."""

    __slots__ = ("baud", "stop_bits", "frames", "bad", "bytes", "seconds", "verdict")

    def __init__(self, baud, stop_bits):
        self.baud, self.stop_bits = baud, stop_bits
        self.frames = self.bad = self.bytes = 0
        self.seconds = 0.0
        self.verdict = "silent"

    def as_dict(self) -> dict:
        return {"baud": self.baud, "stop_bits": self.stop_bits, "frames": self.frames,
                "crc_errors": self.bad, "bytes": self.bytes, "seconds": round(self.seconds, 3),
                "verdict": self.verdict}


class Detection:
    """The result: the settings found (``baud`` None when nothing answered), what the ECU
    reported, and every attempt made."""

    def __init__(self, port, budget):
        self.port = port
        self.budget = budget
        self.baud = None
        self.stop_bits = None
        self.protocol_version = None
        self.status_rate_hz = None
        self.frames_per_s = None
        self.attempts = []
        self.elapsed = 0.0
        self.out_of_budget = False

    @property
    def found(self) -> bool:
        return self.baud is not None

    def as_dict(self) -> dict:
        return {"port": self.port, "found": self.found, "baud": self.baud, "stop_bits": self.stop_bits,
                "protocol_version": self.protocol_version, "status_rate_hz": self.status_rate_hz,
                "frames_per_s": self.frames_per_s, "elapsed_s": round(self.elapsed, 3),
                "budget_s": self.budget, "tried": [a.as_dict() for a in self.attempts]}

    def describe_tried(self) -> str:
        return ", ".join(f"{a.baud}/{a.stop_bits} {a.verdict}" for a in self.attempts) or "nothing"


def _configure(ser, baud, stop_bits):
    ser.baudrate = baud
    ser.stopbits = stop_bits
    try:
        ser.reset_input_buffer()
    except Exception:  # noqa: BLE001 - a URL handler without it; stale bytes only cost a frame
        pass


def listen(ser, baud, stop_bits, window, *, probe=False, until=None, deadline=None) -> Attempt:
    """Listen at one setting for up to ``window`` seconds (and not past ``deadline``)."""
    _configure(ser, baud, stop_bits)
    att = Attempt(baud, stop_bits)
    framer = ZkFramer("status")
    keepalive = zk.encode_control("keepalive")[0] if probe else None
    t0 = time.monotonic()
    end = t0 + window if deadline is None else min(t0 + window, deadline)
    next_probe = t0
    while True:
        now = time.monotonic()
        if now >= end:
            break
        if keepalive is not None and now >= next_probe:
            ser.write(keepalive)
            next_probe = now + 0.05
        ser.timeout = max(0.001, min(0.02, end - now))
        data = ser.read(256)
        if not data:
            continue
        att.bytes += len(data)
        frames = framer.feed(data)
        att.frames += len(frames)
        if until is not None and any([until(f) for f in frames]):
            break
        if att.frames >= FRAMES_NEEDED and until is None:
            break
        if att.frames == 0 and att.bytes >= GIVE_UP_BYTES:
            break
    att.bad = framer.bad
    att.seconds = time.monotonic() - t0
    if att.frames >= FRAMES_NEEDED:
        att.verdict = "status frames"
    elif att.bytes:
        att.verdict = "garbage" if att.frames == 0 else "too few frames"
    return att


def detect(ser, *, bauds=BAUDS, stop_bits=(1, 2), window=WINDOW_S, budget=BUDGET_S, probe=False,
           port_name=None) -> Detection:
    """Search the line settings of the ECU on the open pyserial port ``ser``; returns a
    :class:`Detection` (``found`` False when nothing answered within the budget). The port is
    left at the settings found."""
    result = Detection(port_name or getattr(ser, "port", None), budget)
    t0 = time.monotonic()
    deadline = t0 + budget
    first = 1 if 1 in stop_bits else 2
    for baud in bauds:
        if time.monotonic() >= deadline:
            result.out_of_budget = True
            break
        att = listen(ser, baud, first, window, probe=probe, deadline=deadline)
        result.attempts.append(att)
        if att.frames < FRAMES_NEEDED:
            continue
        chosen = first
        if first == 1 and 2 in stop_bits:
            strict = listen(ser, baud, 2, window, probe=probe, deadline=deadline)
            result.attempts.append(strict)
            if strict.frames >= FRAMES_NEEDED:
                chosen = 2
        result.baud, result.stop_bits = baud, chosen
        _identify(ser, result, probe, deadline)
        break
    result.elapsed = time.monotonic() - t0
    if not result.found and time.monotonic() >= deadline:
        result.out_of_budget = True
    return result


def _identify(ser, result, probe, deadline):
    """At the settings found: wait for status ID 6 (version, rate) and measure frames/s."""
    seen = {"six": None, "n": 0}

    def until(frame):
        seen["n"] += 1
        if frame[0] == 0xF6 and seen["six"] is None:
            seen["six"] = frame
        return seen["six"] is not None and seen["n"] >= 2 * FRAMES_NEEDED

    t0 = time.monotonic()
    listen(ser, result.baud, result.stop_bits, VERSION_WAIT_S, probe=probe, until=until,
           deadline=max(deadline, t0 + VERSION_WAIT_S))
    took = time.monotonic() - t0
    if seen["six"] is not None:
        rec = zk.decode_status(seen["six"])
        result.protocol_version = rec["protocol_version"]
        result.status_rate_hz = rec["status_rate_hz"]
    if took > 0 and seen["n"]:
        result.frames_per_s = round(seen["n"] / took, 1)


def no_answer(result: Detection) -> NoReply:
    """The error for a search that found nothing (facts only: what was tried, how long)."""
    why = "out of time budget; " if result.out_of_budget else ""
    return NoReply(f"no ZK status frames on {result.port} at any setting tried ({why}"
                   f"{result.elapsed:.1f} s of {result.budget:g} s): {result.describe_tried()}")


# -- the actuator bus ----------------------------------------------------------------------------

#: The protocols a mightyZAP bus may speak, in the order :func:`detect_bus` tries them at a rate.
BUS_PROTOCOLS = ("ir", "modbus")


def detect_bus(port=None, bauds=None, *, protocols=BUS_PROTOCOLS, every=False, retries=2, on_warning=None,
               opener=None, **options):
    """Say which protocol (IR or Modbus RTU) and baud rate the actuators on a bus speak: yields
    one record per combination where an actuator answers — ``protocol``, ``baud``, ``ids`` (the
    IDs that answered, in order: a late reply found after an earlier ID's does not reorder them) and ``found`` (how many) — and stops after the first unless ``every``.

    At each baud rate of ``bauds`` in turn (default :data:`zkzap.api.zap.ALL_BAUDS`, the
    factory default first), each protocol of ``protocols`` is scanned over all its IDs (IR
    0-253, Modbus RTU 1-247) as :meth:`zkzap.api.zap.Bus.scan` scans (its timing policy: a
    silent ID costs its probe's time on the wire and the first-byte wait, and late replies are
    still recognised by their ID). ``opener(baud, protocol)``: how the port is opened for one
    combination (a context manager giving a bus link; the command line's, which knows
    batches and ``--sim``); by default :func:`zkzap.link.zap_bus.open_bus` on ``port`` with
    ``options`` (timeout, stop_bits, latency, ...). ``on_warning(text)``: what the scans say.
    Raises :class:`~zkzap.errors.NoReply` when nothing answers (the rates tried, the time
    taken)."""
    from ..codec import modbus, zap
    from .zap import ALL_BAUDS, Bus

    bauds = list(ALL_BAUDS if bauds is None else bauds)
    ids_for = {"ir": list(range(zap.MAX_ID + 1)), "modbus": list(range(1, modbus.MAX_ID + 1))}
    if opener is None:
        from ..link.zap_bus import open_bus

        def opener(baud, protocol):
            return open_bus(port, baud, protocol=protocol, return_mode=1, retries=retries, **options)

    t0 = time.monotonic()
    found = 0
    for baud in bauds:
        for protocol in protocols:
            with opener(baud, protocol) as link:
                recs = list(Bus.over(link).scan(ids_for[protocol], [baud], retries=retries, on_warning=on_warning))
            if recs:
                found += 1
                yield {"protocol": protocol, "baud": baud, "ids": sorted(r["id"] for r in recs), "found": len(recs)}
                if not every:
                    return
    if not found:
        names = {"ir": "the IR protocol", "modbus": "Modbus RTU"}
        raise NoReply(f"nothing answered on {' or '.join(names[p] for p in protocols)} at "
                      f"{', '.join(map(str, bauds))} baud ({time.monotonic() - t0:.2f} s)")
