"""``--quick`` for every benchmark script: run at its smallest size, so that the test suite can
run each one and none stops working unnoticed. The figures of a quick run mean nothing (targets
are not checked); the scripts' own defaults are the sizes the published figures come from."""

from __future__ import annotations

import argparse


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
