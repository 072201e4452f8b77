"""``zkzap zap`` / ``zap``: mightyZAP linear actuators (IR protocol)."""

from __future__ import annotations

import click

from ... import __version__
from .. import CONTEXT, EXIT_EPILOG, ZAP_COMMANDS, LazyGroup, debug_option


@click.group(cls=LazyGroup, lazy=ZAP_COMMANDS, context_settings=CONTEXT, epilog=EXIT_EPILOG)
@click.version_option(__version__, "-V", "--version", prog_name="zap", message="%(prog)s (zkzap) %(version)s")
@debug_option
def zap():
    """mightyZAP linear actuators, IR protocol: scan the bus, move, read and write registers,
    compose and decode packets.

    Packets are 'FF FF FF ID SIZE CMD params CHK'. REGISTER is a name from 'zap registers'
    (goal-position, present-voltage, ...) or an address (0x86, 134). IDs are 0..253; 254 or
    'broadcast' reaches every actuator and is never answered.
    """
