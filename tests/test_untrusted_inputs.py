"""Untrusted input never crashes and never balloons: a short seeded run of the input fuzzer
(``benchmarks/fuzz.py inputs``) over every kind of input zkzap reads finds nothing, and the
fuzzer itself catches what it is there to catch (a traceback, a hang, a memory hog)."""

from __future__ import annotations

import importlib.util
import io
import os
import sys

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="the fuzzer forks its workers")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_spec = importlib.util.spec_from_file_location("zkzap_fuzz_inputs", os.path.join(ROOT, "benchmarks", "fuzz_inputs.py"))
fuzz = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fuzz)

#: Cases per kind: enough for each kind's refusals and whole decodes, short enough for the suite.
CASES = 10


def test_a_short_seeded_run_over_every_input_kind_finds_nothing():
    out = io.StringIO()
    # report-svg draws with matplotlib (seconds a case); its readers are report-run's
    tallies = fuzz.run(seed=20261201, count=CASES, jobs=1, skip={"report-svg"}, out=out)
    report = out.getvalue()
    assert not any(t.findings for t in tallies.values()), report
    names = set(tallies)
    for kind in ("fleet-json", "fleet-toml", "fleet-yaml", "schedule", "limits", "zap-batch", "zk-batch",
                 "capture-zk", "capture-zap", "replay-capture", "sim-replay-zk", "sim-replay-zap", "raw-log-replay",
                 "raw-zk-decode", "hex-zk", "hex-file-zk", "hex-file-zap", "hex-crc", "report-run", "report-runs",
                 "report-steps", "report-summary", "logbook", "aux-lines",
                 "setup-state", "sim-state"):
        assert kind in names, kind
    assert all(t.cases == CASES for t in tallies.values()), report
    # mutation reaches both sides: inputs that are refused and inputs that decode
    codes = {}
    for t in tallies.values():
        for code, n in t.codes.items():
            codes[code] = codes.get(code, 0) + n
    assert codes.get(0) and codes.get(2), report


def test_the_fuzzer_reports_tracebacks_hangs_and_memory():
    def raises(path, data):
        return {}["missing"]

    def hangs(path, data):
        import time

        time.sleep(30)

    def hogs(path, data):
        block = bytearray(200 << 20)
        block[::4096] = b"x" * len(block[::4096])          # touched: resident, not just reserved
        return 0, b"", ""

    def lies(path, data):                                   # a refusal of two lines, with stdout
        return 2, b"partial", "zkzap: error: x\nmore\n"

    def spins(path, data):                                  # quadratic in some input
        import time

        t0 = time.process_time()
        while time.process_time() - t0 < 0.3:
            pass
        return 0, b"", ""

    extra = [fuzz.Kind(name, ["profile.csv"], "stand.csv", run, warm=False, cpu=0.2 if run is spins else 10)
             for name, run in (("t-raises", raises), ("t-hangs", hangs), ("t-hogs", hogs), ("t-lies", lies),
                               ("t-spins", spins))]
    out = io.StringIO()
    tallies = fuzz.run(seed=1, count=1, jobs=2, only={k.name for k in extra}, extra=extra, timeout=3,
                       memory_mib=64, out=out)
    found = {name: {f.what for f in t.findings} for name, t in tallies.items()}
    assert found == {"t-raises": {"traceback"}, "t-hangs": {"hang"}, "t-hogs": {"memory"},
                     "t-lies": {"lines", "stdout"}, "t-spins": {"cpu"}}, out.getvalue()
    assert "KeyError: 'missing'" in out.getvalue()


def test_mutations_are_seeded_and_lie_where_it_hurts():
    import random

    seed = bytes(range(64)) * 4
    a = [fuzz.mutate(random.Random(5), seed, True) for _ in range(3)]
    b = [fuzz.mutate(random.Random(5), seed, True) for _ in range(3)]
    assert a == b and any(x != seed for x in a)
    many = [fuzz.mutate(random.Random(i), seed, True) for i in range(400)]
    assert any(b"\xff\xff\xff\xff" in x for x in many)                   # lying 4-byte fields
    text = [fuzz.mutate(random.Random(i), b"a = 1\nb = 2\n", False) for i in range(400)]
    assert any(b"9" * 5000 in x for x in text) and any(b"\xef\xbb\xbf" in x for x in text)
