"""Fuzz what zkzap reads: the streaming framers, and every kind of input file or stream.

    python benchmarks/fuzz.py                       # both: the framers, then the inputs
    python benchmarks/fuzz.py framers --seed 7 --count 200000 --proto zap --jobs 2
    python benchmarks/fuzz.py inputs --cases 500 --kind capture-zk   # see benchmarks/fuzz_inputs.py

``inputs`` mutates valid files of every kind (fleet files, schedules, limits, batches,
captures, raw logs, hex dumps, report inputs, replay files, logbooks, state files) and runs
each case in a worker process under a deadline and an address-space limit, reporting
tracebacks, hangs, exit statuses and peak memory (:mod:`fuzz_inputs`). The rest of this
description is the framers' part.

The framer fuzzer, by default 10^6 streams per decoder with seed 1:

Each stream is built from pieces: valid frames (status and control for ZK, commands and
feedback for mightyZAP), random garbage, garbage rich in head bytes, false heads (a head byte
or ``FF FF FF`` followed by random bytes), truncated frames, frames with a bit flipped; then
random bit flips across the whole stream. It is fed to the framer whole, one byte at a time,
or cut at random offsets, and every frame the framer returns goes through the record decoder
(``ZkDecoder``/``ZapDecoder``) and the JSON Lines and CSV text encoders.

Properties checked on every stream:

1. nothing raises;
2. every frame returned is a whole frame with a valid CRC/checksum (and, for ZK, of an
   accepted kind and a defined control ID);
3. every byte is accounted for: ``skipped`` + the bytes of the returned frames == stream length;
4. every valid frame embedded in the stream is returned, unless its own bytes were damaged.
   A loss is *explained* when a false frame (one that passed the 8-bit check but was not
   embedded at that place) overlaps it: an 8-bit CRC accepts 1 in 256 random candidates, so
   no framer can tell such a pair apart every time. The script counts explained losses (the
   residual rate) apart from unexplained ones (bugs: always 0).

The figures (streams, bytes, frames, losses, false frames, rates) are printed at the end; the
exit status is 1 when any stream broke property 1, 2, 3 or had an unexplained loss.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import time
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))
sys.path.insert(0, HERE)

from zkzap.codec import zap, zk  # noqa: E402
from zkzap.codec.framing import ZapFramer, ZkFramer  # noqa: E402
from zkzap.io.zk_lines import ZkLines  # noqa: E402
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # common.py, beside this script
from common import add_quick  # noqa: E402

ZK_HEADS = bytes(range(0xF1, 0x100))


# --- pools of valid frames (built once: the CRC of each is computed by the codec) ------------

def zk_pool(rng, n=4096):
    frames = []
    for _ in range(n):
        if rng.random() < 0.7:
            frames.append(zk.status_frame(rng.randint(1, 14), rng.randbytes(5)))
        else:
            frames.append(zk.control_frame(rng.randint(0, 8), rng.randrange(16), rng.randrange(256)))
    return frames


def zap_pool(rng, n=4096):
    codes = [i.code for i in zap.INSTRUCTIONS]
    packets = []
    for _ in range(n):
        ident = rng.randint(0, 254)
        code = rng.choice(codes) if rng.random() < 0.5 else rng.choice((0, 0, 0x01, 0x20, 0x21, rng.randrange(256)))
        k = rng.random()
        size = rng.randint(0, 4) if k < 0.8 else rng.randint(5, 40) if k < 0.98 else rng.randint(41, 253)
        params = bytes(rng.choice((0xFF, rng.randrange(256))) for _ in range(size)) if rng.random() < 0.1 \
            else rng.randbytes(size)
        packets.append(zap.packet(ident, code, params))
    return packets


# --- stream generation --------------------------------------------------------------------------

class Case:
    """One fuzz stream: its bytes, the intact frames embedded ((position, bytes), in order),
    the framer options and how to cut it into chunks."""

    __slots__ = ("proto", "data", "expected", "accept", "cuts")

    def __init__(self, proto, data, expected, accept=None, cuts=None):
        self.proto, self.data, self.expected, self.accept, self.cuts = proto, data, expected, accept, cuts


def _flip(rng, data, expected, damaged):
    p = rng.randrange(len(data))
    data[p] ^= 1 << rng.randrange(8)
    for k, (pos, f) in enumerate(expected):
        if pos <= p < pos + len(f):
            damaged.add(k)


def _truncated(rng, pool):
    """A valid frame cut short."""
    f = rng.choice(pool)
    return f[:rng.randint(1, len(f) - 1)]


def _bit_flipped(rng, pool):
    """A valid frame with one bit flipped."""
    f = bytearray(rng.choice(pool))
    f[rng.randrange(len(f))] ^= 1 << rng.randrange(8)
    return bytes(f)


def _damaged(rng, parts, expected):
    """The stream of ``parts`` with 0..2 random bit flips, and the embedded frames they left
    intact."""
    data = bytearray(b"".join(parts))
    damaged = set()
    for _ in range(rng.choice((0, 0, 0, 1, 2)) if data else 0):
        _flip(rng, data, expected, damaged)
    return bytes(data), [e for k, e in enumerate(expected) if k not in damaged]


def _cuts(rng, n):
    r = rng.random()
    if r < 0.4 or n == 0:
        return []                                   # whole
    if r < 0.5 and n <= 200:
        return list(range(1, n))                    # one byte at a time
    return sorted(rng.sample(range(1, n + 1), min(n, rng.randint(1, 8))))


def make_zk(rng, pool, max_pieces=12):
    parts = []
    expected = []
    pos = 0
    r = rng.random()
    accept = "both" if r < 0.8 else "status" if r < 0.9 else "control"
    for _ in range(rng.randint(0, max_pieces)):
        r = rng.random()
        if r < 0.55:
            piece = rng.choice(pool)
            if accept == "both" or (len(piece) == 7) == (accept == "status"):
                expected.append((pos, piece))
        elif r < 0.68:
            piece = rng.randbytes(rng.randint(1, 12))
        elif r < 0.78:
            piece = bytes((rng.choice(ZK_HEADS),)) + rng.randbytes(rng.randint(0, 6))
        elif r < 0.86:
            piece = _truncated(rng, pool)
        elif r < 0.94:
            piece = _bit_flipped(rng, pool)
        else:
            piece = bytes(rng.choice(ZK_HEADS) for _ in range(rng.randint(1, 8)))
        parts.append(piece)
        pos += len(piece)
    data, expected = _damaged(rng, parts, expected)
    return Case("zk", data, expected, accept, _cuts(rng, len(data)))


def make_zap(rng, pool, max_pieces=10):
    parts = []
    expected = []
    pos = 0
    for _ in range(rng.randint(0, max_pieces)):
        r = rng.random()
        if r < 0.55:
            piece = rng.choice(pool)
            # a run of FF before a header belongs to the header run: the packet is still whole
            expected.append((pos, piece))
        elif r < 0.67:
            piece = rng.randbytes(rng.randint(1, 12))
        elif r < 0.77:
            piece = b"\xff" * rng.randint(1, 4) + rng.randbytes(rng.randint(0, 8))
        elif r < 0.85:
            piece = _truncated(rng, pool)
        elif r < 0.93:
            piece = _bit_flipped(rng, pool)
        else:
            piece = bytes(rng.choice((0xFF, 0xFF, rng.randrange(256))) for _ in range(rng.randint(1, 8)))
        parts.append(piece)
        pos += len(piece)
    # A packet's ID must not be FF; a packet whose header run is extended by a preceding FF
    # is still the same packet, but one preceded by FF FF? (? != FF) is too.
    data, expected = _damaged(rng, parts, expected)
    return Case("zap", data, expected, None, _cuts(rng, len(data)))


# --- checking -------------------------------------------------------------------------------

class Tally:
    FIELDS = ("streams", "bytes", "embedded", "recovered", "lost_explained", "lost_unexplained",
              "false_frames", "emitted", "violations", "errors")

    def __init__(self):
        for f in self.FIELDS:
            setattr(self, f, 0)
        self.examples = []

    def add(self, other):
        for f in self.FIELDS:
            setattr(self, f, getattr(self, f) + getattr(other, f))
        self.examples += other.examples[:5 - len(self.examples)]


class Encoders:
    """The record decoders and the text encoders every emitted frame goes through."""

    def __init__(self, proto, accept):
        from zkzap.io.writers import csv_dialect, json_dialect

        self.proto = proto
        if proto == "zk":
            from zkzap.commands.zk.decode import columns

            self.records = zk.ZkDecoder()
            cols = columns(accept or "both")
            self.json = ZkLines(zk.ZkDecoder(), json_dialect())
            self.csv = ZkLines(zk.ZkDecoder(), csv_dialect(cols))
        else:
            self.records = zap.ZapDecoder()
            self.json = self.csv = None

    def run(self, frames, case=None):
        recs = [self.records.decode(f) for f in frames]
        if self.json is not None:
            lines = self.json.encode_all(frames)
            self.csv.encode_all(frames)
            if case is not None:
                # the fused path (framing and rendering in one pass) gives the same lines
                fused = ZkLines(zk.ZkDecoder(), self.json.dialect, cache=16)
                framer = ZkFramer(case.accept)
                got = []
                prev = 0
                for cut in case.cuts + [len(case.data)]:
                    got += framer.feed_lines(case.data[prev:cut], fused)
                    prev = cut
                got += framer.flush_lines(fused)
                if got != lines:
                    raise AssertionError(f"fused lines differ: {got} != {lines}")
        return recs


def check_case(case, encoders=True):
    """Run one case; returns a Tally of one stream (with an example when it failed)."""
    t = Tally()
    t.streams = 1
    t.bytes = len(case.data)
    t.embedded = len(case.expected)
    data = case.data
    try:
        framer = ZkFramer(case.accept) if case.proto == "zk" else ZapFramer()
        out = []
        prev = 0
        for cut in case.cuts + [len(data)]:
            out += framer.feed(data[prev:cut])
            prev = cut
        out += framer.flush()
        if encoders:
            Encoders(case.proto, case.accept).run(out, case)
    except Exception:  # property 1
        t.errors = 1
        t.examples.append(("exception", case, traceback.format_exc()))
        return t
    t.emitted = len(out)
    problems = []
    for f in out:
        try:
            if case.proto == "zk":
                kind = zk.check_frame(f)
                if case.accept != "both" and kind != case.accept:
                    problems.append(f"{kind} frame with accept={case.accept}")
                if kind == "control" and f[1] >> 4 > 8:
                    problems.append(f"control ID {f[1] >> 4}")
            else:
                zap.check_packet(f)
        except ValueError as e:  # property 2
            problems.append(f"invalid frame {f.hex(' ')}: {e}")
    if framer.frames != len(out) or framer.skipped + sum(len(f) for f in out) != len(data) or framer.pending:
        problems.append(f"counters: frames {framer.frames}/{len(out)}, skipped {framer.skipped}, "
                        f"pending {framer.pending}, length {len(data)}")
    # positions of the emitted frames (in order, non-overlapping)
    placed = []
    pos = 0
    for f in out:
        p = data.find(f, pos)
        if p < 0:
            problems.append(f"frame {f.hex(' ')} is not in the stream")
            break
        placed.append((p, f))
        pos = p + len(f)
    at = set(placed)
    expected_at = set(case.expected)
    false = [(p, f) for p, f in placed if (p, f) not in expected_at]
    t.false_frames = len(false)
    for p, f in case.expected:
        if (p, f) in at:
            t.recovered += 1
            continue
        if any(q < p + len(f) and p < q + len(g) for q, g in false):
            t.lost_explained += 1
        else:
            t.lost_unexplained += 1
            problems.append(f"lost the frame {f.hex(' ')} at {p} with no false frame over it")
    if problems:
        t.violations = 1
        t.examples.append(("violation", case, "; ".join(problems)))
    return t


def run_batch(proto, seed, count, encoders=True):
    rng = random.Random(seed)
    pool = zk_pool(rng) if proto == "zk" else zap_pool(rng)
    make = make_zk if proto == "zk" else make_zap
    tally = Tally()
    for _ in range(count):
        tally.add(check_case(make(rng, pool), encoders))
    return tally


def _job(args):
    return run_batch(*args)


def describe(case):
    return (f"proto={case.proto} accept={case.accept} cuts={case.cuts}\n  data={case.data.hex(' ')}\n"
            f"  expected={[(p, f.hex(' ')) for p, f in case.expected]}")


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    import fuzz_inputs

    if argv[:1] == ["inputs"]:
        return fuzz_inputs.main(argv[1:])
    if argv[:1] == ["framers"]:
        return framers(argv[1:])
    status = framers(argv)
    args = argparse.ArgumentParser(add_help=False)
    args.add_argument("--seed", default="1")
    args.add_argument("--jobs", default=str(os.cpu_count() or 1))
    args.add_argument("--quick", action="store_true")
    known, _ = args.parse_known_args(argv)
    sized = ["--quick"] if known.quick else ["--jobs", known.jobs]
    return fuzz_inputs.main([*sized, "--seed", known.seed]) or status


def framers(argv=None):
    ap = argparse.ArgumentParser(prog="fuzz.py framers", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--count", type=int, default=1_000_000, help="streams per decoder (default 10^6)")
    ap.add_argument("--proto", choices=["zk", "zap", "both"], default="both")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--no-encoders", action="store_true", help="framers only (faster)")
    add_quick(ap, count=200, jobs=1)
    args = ap.parse_args(argv)
    protos = ["zk", "zap"] if args.proto == "both" else [args.proto]
    failed = False
    for proto in protos:
        t0 = time.perf_counter()
        batches = max(args.jobs * 8, 1)
        per = [args.count // batches + (1 if k < args.count % batches else 0) for k in range(batches)]
        jobs = [(proto, args.seed * 1_000_003 + k, n, not args.no_encoders) for k, n in enumerate(per) if n]
        tally = Tally()
        if args.jobs > 1:
            import multiprocessing

            with multiprocessing.Pool(args.jobs) as pool:
                for part in pool.imap_unordered(_job, jobs):
                    tally.add(part)
        else:
            for job in jobs:
                tally.add(_job(job))
        dt = time.perf_counter() - t0
        print(f"{proto}: {tally.streams} streams, {tally.bytes} bytes, {tally.embedded} valid frames embedded "
              f"({dt:.1f} s, {tally.bytes / dt / 1e6:.2f} MB/s)")
        print(f"  recovered {tally.recovered}; lost to a false frame (explained) {tally.lost_explained}; "
              f"lost, unexplained {tally.lost_unexplained}")
        print(f"  frames returned {tally.emitted}, of which false (valid check, not embedded there) "
              f"{tally.false_frames}")
        if tally.embedded:
            print(f"  residual loss rate {tally.lost_explained / tally.embedded:.2e} per embedded frame; "
                  f"false frames {tally.false_frames / max(tally.bytes, 1) * 1e6:.1f} per MB")
        print(f"  exceptions {tally.errors}; property violations {tally.violations}")
        for kind, case, detail in tally.examples:
            print(f"  {kind}: {detail}\n  {describe(case)}")
        failed |= bool(tally.errors or tally.violations)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
