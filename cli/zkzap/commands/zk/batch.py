"""``zk batch [FILE|-]``: many ECU commands over one open port (see :mod:`..batch`)."""

from __future__ import annotations

import sys

import click

from .. import CONTEXT, Command
from ..batch import BATCH_EXITS
from ..options import InputPath, abort_option, consent, note, port_options, yes_option
from .telemetry import resolve_port


@BATCH_EXITS
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("file", required=False, default="-", metavar="[FILE|-]", type=InputPath("zk batch"))
@click.option("-k", "--keep-going", is_flag=True,
              help="Run past a failed command; the batch still exits with the first failure's status.")
@abort_option(default="standby",
              help="Sent when the batch stops early (a failure, Ctrl-C) after a line that controlled the "
                   "engine: that state with throttle 0; none sends nothing.")
@yes_option
@port_options("zk")
def batch(file, keep_going, abort, yes, port, baud, stop_bits, timeout, sim):
    """Run the zk commands of FILE (or stdin: '-', the default) over one open port.

    One command per line, as on the command line without 'zk' and the port options
    (send control --state run --throttle 30 --for 10; monitor --count 20); '#' comments and
    blank lines are skipped. Every line is checked whole before anything is sent — each command
    runs every check it makes at run time (values, limits, IDs, files, permissions) up to the
    point where it would open the port: a bad line is refused naming FILE:LINE (stdin:LINE),
    exit status 2, nothing sent. On a real port the engine-starting commands of the whole batch
    need one consent (--yes, or one prompt listing them).

    Each command gives one JSON Lines record on stdout: line, command, exit, result (what it
    printed) and error when it failed; the status records of a 'send --for' or 'monitor' line
    are its result. A line that prints more than 64 KiB has its record streamed as it prints
    (memory stays bounded however long it runs): its result is then the list of what it printed,
    a value per line (a line that is no JSON as its text), and exit follows result. The batch
    stops at the first failure unless --keep-going and exits with
    the first failure's status. Ctrl-C (or SIGTERM) stops the running line after its current
    transaction (a frame is never cut in half; a 'send --for', 'profile' or 'monitor' session
    stops between two records and sends its abort command as usual): its record says exit 130
    (143) with the records gathered so far, no further line starts, and the batch exits 130
    (143); a batch that stops early after controlling the engine also sends --abort.

    The lines share one alarm list: a trip latches an alarm, and a later start (with
    --keep-going) is refused, its line failing with the reason, until an 'ack' line acknowledges it
    ('ack', 'ack N ...', '--by NAME'; who and when are recorded) and the engine is at rest and
    cool. An 'alarms' line gives the list and whether a start is allowed.

    \b
    Examples:
      printf 'send keepalive\\nmonitor --count 5\\n' | zk batch --sim
      zk batch run.txt -p /dev/ttyUSB0 --yes
    """
    from ...api.session import abort_frames, describe_abort
    from ...link.shared import sharing
    from ...link.zk_port import ZkLink, is_simulator
    from ..batch import check_lines, consent_items, read_lines, read_source, run_lines
    from . import zk as group

    text, name = read_source(file)
    lines = read_lines(text, name)
    url = resolve_port(port, sim)
    defaults = {"port": url, "sim": False, "baud": baud, "yes": True}
    if timeout is not None:
        defaults["timeout"] = timeout
    check_lines(group, lines, "zk", defaults)
    if not lines:
        return
    if not is_simulator(url):
        items = consent_items(lines)
        if items:
            consent(f"this batch on {url} can start the engine or run ECU hardware: " + "; ".join(items), yes)
    link = ZkLink.open(url, baud, stop_bits=stop_bits)
    try:
        from ...api.stand import shared_stand

        # one alarm list for the batch: a line's trip latches, and with --keep-going a later line's
        # start is refused (exit 5) until an 'ack' line and the engine back at rest and cool
        with sharing("zk", link), shared_stand(notify=note):
            code = run_lines(group, "zk", lines, defaults, sys.stdout, keep_going=keep_going)
        if code and link.controlled and abort != "none":
            for f in abort_frames(abort):
                link.write(f)
            note(f"batch stopped early: sent {describe_abort(abort)}")
    finally:
        link.close()
    if code:
        raise click.exceptions.Exit(code)
