"""``zap batch [FILE|-]``: many actuator commands over one open port (see :mod:`..batch`)."""

from __future__ import annotations

import sys

import click

from ...codec import zap
from .. import CONTEXT, Command
from ..batch import ZAP_BATCH_EXITS
from ..options import InputPath, consent, zap_yes_option as yes_option
from ..options import protocol_options
from .compose import line_defaults, link_options, open_link, shared_bus_args


@ZAP_BATCH_EXITS
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("file", required=False, default="-", metavar="[FILE|-]", type=InputPath("zap batch"))
@click.option("-k", "--keep-going", is_flag=True,
              help="Run past a failed command; the batch still exits with the first failure's status.")
@yes_option
@link_options
@protocol_options
def batch(file, keep_going, yes, **common):
    """Run the zap commands of FILE (or stdin: '-', the default) over one open port.

    One command per line, as on the command line without 'zap' and the port options
    (load present-position --id 1; store goal-speed 600 --id 2); '#' comments and blank lines
    are skipped. Every line is checked whole before anything is sent — each command runs every
    check it makes at run time (values, registers, conditions, files, permissions) up to the
    point where it would open the port: a bad line is refused naming FILE:LINE (stdin:LINE),
    exit status 2, nothing sent. On a real port the stored writes of the whole batch need one
    consent (--yes, or one prompt listing them); --force goes on the line that needs it.

    Each command gives one JSON Lines record on stdout: line, command, exit (the status the
    command would have exited with), result (what it printed: a value, a record or a list of
    records, else its text) and error (the message) when it failed. The batch stops at the
    first failure unless --keep-going, and exits with the first failure's status. The link
    options (-b, --timeout, --return-mode, --retries) are every line's defaults.

    Ctrl-C (or SIGTERM) stops the running line after its current transaction (one request and
    its reply or timeout; never half a packet): the line ends as the command does on Ctrl-C
    (a scan keeps what it found, 'move --wait' stops the rod where it is), its record says exit
    130 (143) with what it printed, no further line starts, and the batch exits 130 (143). A
    second Ctrl-C interrupts at once.

    \b
    Examples:
      printf 'load present-position --id 1\\nmove 2000 --id 1 --wait\\n' | zap batch --sim --sim-ids 1
      zap batch setup.txt -p /dev/ttyUSB0 --yes
      zap batch moves.txt -p /dev/ttyUSB0 --keep-going | jq -c 'select(.exit != 0)'
      printf 'store goal-speed 500 --id 1\nload goal-speed --id 1\n' | zap batch --protocol modbus --sim

    With --protocol modbus every line speaks Modbus RTU (the batch's --protocol and --map are
    every line's; a line giving another protocol, or a command that speaks the IR protocol only,
    is refused before anything is sent).
    """
    from .. import zap as _  # noqa: F401 - the group, for the lines
    from ...link.shared import sharing
    from ...link.zap_bus import is_simulated
    from ..batch import check_lines, consent_items, line_ids, read_lines, read_source, run_lines
    from . import zap as group

    text, name = read_source(file)
    lines = read_lines(text, name)
    defaults = line_defaults(common)
    defaults["yes"] = True
    check_lines(group, lines, "zap", defaults)
    for line in lines:                     # every line speaks the batch's protocol, or is refused now
        spoken = line.params.get("protocol", "ir")
        if spoken != defaults["protocol"]:
            from ...errors import UsageError

            raise UsageError(f"{line.where}: {' '.join(line.path)}: speaks {spoken}; this batch's port speaks "
                             f"{defaults['protocol']} (--protocol is the batch's)")
    if not lines:
        return
    if not (common["sim"] or is_simulated(common["port"])):
        items = consent_items(lines)
        if items:
            consent(f"this batch writes stored settings on {common['port']}; they survive power-off: "
                    + "; ".join(items), yes)
    ids = {i for line in lines for i in line_ids(line) if i != zap.BROADCAST}
    with open_link(**shared_bus_args(common, sorted(ids) or [0])) as bus, sharing("zap", bus):
        code = run_lines(group, "zap", lines, defaults, sys.stdout, keep_going=keep_going,
                         keep_baud_after=("set-baud",))
    if code:
        raise click.exceptions.Exit(code)
