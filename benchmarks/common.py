"""What the benchmark scripts share.

``--quick`` (:func:`add_quick`): run at the smallest size, so that the test suite can run every
script and none stops working unnoticed. The figures of a quick run mean nothing (targets are
not checked); the scripts' own defaults are the sizes the published figures come from.

:func:`until_ready`: wait for a simulator that was just started to answer, before measuring.
"""

from __future__ import annotations

import argparse
import time


class _Quick(argparse.Action):
    def __init__(self, option_strings, dest, smallest=None, **kwargs):
        super().__init__(option_strings, dest, nargs=0, default=False, **kwargs)
        self.smallest = dict(smallest or {})

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, True)
        for key, value in self.smallest.items():
            setattr(namespace, key, value)


def add_quick(parser: argparse.ArgumentParser, **smallest) -> None:
    """Give ``parser`` a ``--quick`` option that sets ``smallest`` (its options' smallest useful
    values); options given after it on the command line still win."""
    parser.add_argument("--quick", action=_Quick, smallest=smallest,
                        help="run at the smallest size, as the test suite does (the figures mean nothing)")


def until_ready(call, within: float = 30.0):
    """``call()`` until it stops raising (a simulator process that has printed its pty may not be
    serving it yet, or a loaded machine may hold it up); its result. The last failure is raised
    after ``within`` seconds."""
    deadline = time.monotonic() + within
    while True:
        try:
            return call()
        except Exception:  # noqa: BLE001 - NoReply, BadReply: not ready yet
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)
