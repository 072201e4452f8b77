"""Whether this process is one of the zkzap programs: asked by ``zkzap/__init__`` before
anything else loads, so it imports nothing beyond ``sys`` and ``os`` (a library user pays for
no signal handling it does not get)."""

from __future__ import annotations

import os
import sys


def is_program() -> bool:
    """Whether this process is one of the zkzap programs (not a library user or a test run)."""
    argv = getattr(sys, "orig_argv", None) or []
    if "-m" in argv[:-1] and argv[argv.index("-m") + 1] in ("zkzap", "zkzap.__main__"):
        return True                  # python -m zkzap, while the package itself is imported
    main = sys.modules.get("__main__")
    spec = getattr(main, "__spec__", None)
    if spec is not None and spec.name in ("zkzap", "zkzap.__main__"):
        return True
    path = getattr(main, "__file__", None) or ""
    return os.path.basename(path) in ("zk", "zap", "zkzap") and spec is None
