"""The library's import path: no click, rich, pyserial, typing or optional extra."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

CLI = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "cli")
NEVER = ("click", "rich", "serial", "typing", "zkzap.commands", "zkzap.io", "prompt_toolkit", "mkdocs", "griffe")


@pytest.mark.parametrize("statement", ["from zkzap import Bus", "from zkzap import Ecu",
                                       "from zkzap import Bus, Actuator, NoReply",
                                       "import zkzap.sim; zkzap.sim.start_zap"])
def test_library_import_path_is_light(statement):
    code = f"{statement}\nimport sys\nprint('\\n'.join(sorted(sys.modules)))"
    env = dict(os.environ, PYTHONPATH=CLI)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=30)
    assert out.returncode == 0, out.stderr
    mods = set(out.stdout.split())
    heavy = sorted(m for m in mods if any(m == n or m.startswith(n + ".") for n in NEVER))
    assert heavy == []
