"""``zkzap zk`` / ``zk``: the ZK turbine ECU protocol."""

from __future__ import annotations

import click

from .. import CONTEXT, EXIT_EPILOG, ZK_COMMANDS, LazyGroup, debug_option, version_option


@click.group(cls=LazyGroup, lazy=ZK_COMMANDS, context_settings=CONTEXT, epilog=EXIT_EPILOG)
@version_option("zk")
@debug_option
def zk():
    """ZK turbine ECU protocol V1.2: send control commands, monitor and log status, run throttle
    profiles, decode captures.

    Control frames (host -> ECU) are 4 bytes 'FF b1 b2 CRC'; status frames (ECU -> host) are 7
    bytes 'F0|ID b1..b5 CRC'; CRC-8/MAXIM-DOW.
    """
