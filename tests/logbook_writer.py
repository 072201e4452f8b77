"""A process that writes runs into a logbook, for the tests of concurrent writers (a spawned
process imports its target by module name: a test module, imported by pytest's importlib
mode, is no importable module)."""

from zkzap.api import logbook as lb


def write_runs(path, n, tag):
    """``n`` runs of one start, 30 s running and 0.25 L each, on a real port (a run on sim:// counts
    toward no engine's totals), their command ``tag``."""
    for _ in range(n):
        lb.record(path, {"started": "2026-01-01T00:00:00Z", "ended": "2026-01-01T00:01:00Z", "duration_s": 60.0,
                         "running_s": 30.0, "starts": 1, "max_rpm": 100000, "max_egt_c": 700, "fuel_used_l": 0.25,
                         "errors": [], "limits_violated": [], "command": tag, "port": "/dev/ttyUSB0", "schedule": None,
                         "files": [], "outcome": "duration", "exit_status": 0})
