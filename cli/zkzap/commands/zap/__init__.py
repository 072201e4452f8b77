"""``zkzap zap`` / ``zap``: mightyZAP linear actuators (IR protocol)."""

from __future__ import annotations

import click

from .. import CONTEXT, EXIT_EPILOG, ZAP_COMMANDS, LazyGroup, debug_option, version_option


@click.group(cls=LazyGroup, lazy=ZAP_COMMANDS, context_settings=CONTEXT, epilog=EXIT_EPILOG)
@version_option("zap")
@debug_option
def zap():
    """mightyZAP linear actuators, IR protocol: scan the bus, move, read and write registers,
    compose and decode packets.

    Packets are 'FF FF FF ID SIZE CMD params CHK'. REGISTER is a name from 'zap registers'
    (goal-position, present-voltage, ...) or an address (0x86, 134). IDs are 0..253; 254 or
    'broadcast' reaches every actuator and is never answered.
    """
