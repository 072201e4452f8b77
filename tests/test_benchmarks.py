"""Every benchmark script runs, at its smallest size (``--quick``): none may stop working
unnoticed. The figures of these runs mean nothing (the machine is shared with the other tests);
the published ones come from the scripts' default sizes (docs/benchmarks.md)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

BENCH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks")


def scripts():
    """The benchmark scripts: every program in benchmarks/ but the floors, which the decode
    benchmarks run themselves."""
    out = []
    for name in sorted(os.listdir(BENCH)):
        if name.endswith(".py") and not name.startswith("floor_"):
            with open(os.path.join(BENCH, name), encoding="utf-8") as f:
                if 'if __name__ == "__main__":' in f.read():
                    out.append(name)
    return out


def test_every_benchmark_has_a_quick_size():
    assert len(scripts()) >= 13
    for name in scripts():
        with open(os.path.join(BENCH, name), encoding="utf-8") as f:
            assert "add_quick(" in f.read(), f"{name}: no --quick (benchmarks/common.py)"


@pytest.mark.parametrize("name", scripts())
def test_benchmark_runs_at_its_smallest_size(name, tmp_path):
    if name == "bridges.py" and shutil.which("mosquitto") is None and not os.path.exists("/usr/sbin/mosquitto"):
        pytest.skip("mosquitto is not installed (apt-get install mosquitto)")
    env = dict(os.environ, ZKZAP_BENCH_DATA=str(tmp_path / "data"), NO_COLOR="1")
    env["PATH"] = os.path.dirname(sys.executable) + os.pathsep + env.get("PATH", "")
    p = subprocess.run([sys.executable, os.path.join(BENCH, name), "--quick"], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    assert p.stdout.strip(), p.stderr[-2000:]
