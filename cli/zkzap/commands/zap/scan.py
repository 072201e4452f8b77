"""Bus-level mightyZAP commands: ``scan``, ``dump``, ``move``, ``set-id`` and ``set-baud``.

They share the link options of the instructions (:func:`.compose.link_options`); every
protocol detail comes from :mod:`zkzap.codec.zap` and every transaction from
:mod:`zkzap.link.zap_bus`.
"""

from __future__ import annotations

import sys
import time

import click

from ...api.zap import ALL_BAUDS, POSITION, SPEED, Bus, map_blocks  # noqa: F401 - re-exported
from ...codec import zap
from ...errors import CHECK_FAILED, DEVICE_ERROR, NO_REPLY, USAGE, NoReply, UsageError
from .. import CONTEXT, Command
from ..options import (BaudList, Choice, FiniteRange, SignedCommand, authorize, buses_option, exits, fleet_option,
                       format_option, id_option, note, protocol_options, resolve_format, unit_options, unit_scales, warn, zap_map,
                       zap_yes_option as yes_option)
from .compose import _link_args, link_options, open_link
from .params import INT, NUMBER, IdType

SCAN_COLUMNS = ["id", "baud", "model", "firmware", "return_mode", "status", "errors"]
SCAN_TABLE = [("id", "id"), ("baud", "baud"), ("_model", "model"), ("firmware", "firmware"),
              ("return_mode", "return mode"), ("status", "status"), ("_errors", "errors")]


class IdList(click.ParamType):
    """IDs like ``0-253`` or ``1,2,5-8`` (no broadcast)."""

    name = "ids"

    def convert(self, value, param, ctx):
        if isinstance(value, list):
            return value
        try:
            return zap.parse_id_list(value)
        except zap.FieldValueError as e:
            raise UsageError(str(e)) from None


def actuator_bauds():
    """The actuator baud rates ``zap scan -b`` takes, or ``all``."""
    return BaudList(ALL_BAUDS, label="--baud", what="an actuator baud rate", example="57600,115200")


def _progress(total, label):
    """A rich progress bar on stderr when stderr is a terminal, else None."""
    from ...io.term import is_tty

    if not is_tty(sys.stderr):
        return None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from ...io.term import console_for

    progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                        console=console_for(sys.stderr), transient=True)
    progress.start()
    progress.add_task(label, total=total)
    return progress


def stored_consent(common, yes, action, registers):
    """The STORED permission for a procedure that writes a stored setting (set-id, set-baud,
    setup), with consent on a real port (see :func:`zkzap.commands.options.authorize`)."""
    from ...codec.permissions import Permission
    from ...link.zap_bus import is_simulated

    return authorize({Permission.STORED: "a stored setting that survives power-off"}, what=action,
                     yes=yes, force=False, simulated=common["sim"] or is_simulated(common["port"]),
                     consent_text=f"{action} on {common['port']}: a stored setting that survives power-off",
                     brief=registers)


# -- scan ----------------------------------------------------------------------------------------

@exits({NO_REPLY: "nothing answers"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.option("--ids", "ids", type=IdList(), default="0-253", show_default=True, metavar="RANGE",
              help="IDs to probe, like 0-253 or 1,2,5-8.")
@format_option()
@link_options(baud_type=actuator_bauds(), baud_help="Baud rates to scan: one, a list like 57600,115200, or 'all' "
                                              "(57600, 115200, 38400, 19200, 9600) [env ZKZAP_ZAP_BAUD].",
              several=True)
@protocol_options(protocols=("ir", "modbus", "auto"))
@buses_option("Scan (each at its baud rate)")
@fleet_option
def scan(ids, fmt, bus_names=None, fleet_file=None, **common):
    """Find every actuator on the bus: Echo to each ID at each baud rate, then read the model,
    firmware and return mode of those that answer.

    The first pass waits per ID only for the bus's typical turnaround (about 5 ms at 57600
    with 2 ms actuators: a full 0-253 scan takes about 1.3 s per baud rate). A reply that
    comes later is recognised by its ID, and that ID and those probed meanwhile are probed
    again with the full allowance (20 ms), as are the IDs near bytes that make no packet;
    --retries applies to garbled replies. Results stream as found: a table on a terminal,
    JSON Lines otherwise (--format), with keys id, baud, model, firmware, return_mode,
    status (ok, error, garbled, duplicate, unidentified) and errors. A failed identify read
    leaves model, firmware and return_mode null (status unidentified). Two actuators with
    one ID (replies that collide) are reported on stderr. Exit status 3 when nothing answers.

    \b
    Examples:
      zap scan -p /dev/ttyUSB0
      zap scan -b all --ids 0-20 -p /dev/ttyUSB0 -f json
      zap scan --sim --sim-ids 1,2,3
      zap scan --protocol modbus -b all -p /dev/ttyUSB0     # 17Lf actuators, IDs 1-247
      zap scan --protocol auto -p /dev/ttyUSB0              # both protocols: records say which

    With --protocol modbus the probe is a read of the model number (IDs 1-247 by default; an
    exception reply counts as an answer, its name in errors) and return_mode is null; with
    --protocol auto the IR protocol is scanned, then Modbus RTU, and every record carries
    'protocol'.
    """
    from ...codec import modbus
    from ...io.writers import make_writer

    from .motion import several_buses

    unit_scales("counts", fleet_file, [])         # a --fleet given is read all the same: a bad one refused
    bauds = common["baud"]
    fmt = resolve_format(fmt)
    protocols = ["ir", "modbus"] if common["protocol"] == "auto" else [common["protocol"]]
    if "modbus" in protocols:
        ctx = click.get_current_context()
        if ctx.get_parameter_source("ids") == click.core.ParameterSource.DEFAULT:
            ids_for = {"ir": ids, "modbus": list(range(1, modbus.MAX_ID + 1))}
        else:
            bad = [i for i in ids if not 1 <= i <= modbus.MAX_ID]
            if bad and protocols == ["modbus"]:
                raise UsageError(f"--ids: {bad[0]} is not a Modbus unit ID; allowed 1..247")
            ids_for = {"ir": ids, "modbus": [i for i in ids if 1 <= i <= modbus.MAX_ID]}
    else:
        ids_for = {"ir": ids}
    if several_buses(bus_names):
        from .motion import scan_buses

        if len(protocols) > 1:
            raise UsageError("--protocol auto: one bus at a time (several buses speak the protocol --protocol names)")
        return scan_buses(ids_for[protocols[0]], fmt, bus_names, fleet_file, common)
    columns = SCAN_COLUMNS + (["protocol"] if len(protocols) > 1 else [])
    table = SCAN_TABLE + ([("protocol", "protocol")] if len(protocols) > 1 else [])
    writer = make_writer(fmt, sys.stdout, columns, table_columns=table, title="mightyZAP actuators")
    found = []
    t0 = time.monotonic()
    progress = None
    try:
        progress = _progress(sum(len(ids_for[p]) for p in protocols) * len(bauds), "scanning")

        def probed(baud, ident, n):
            if progress is not None:
                progress.update(0, description=f"{baud} baud, ID {ident:3d} ({n} found)")
                progress.advance(0)

        for protocol in protocols:
            args = _link_args(common)
            args["return_mode"] = "1"
            args["baud"] = bauds[0]
            args["protocol"] = protocol
            with open_link(ids=[0 if protocol == "ir" else 1], **args) as link:
                for rec in Bus.over(link).scan(ids_for[protocol], bauds, retries=common["retries"],
                                               on_probe=probed if progress is not None else None, on_warning=warn,
                                               on_note=note):
                    if len(protocols) > 1:
                        rec["protocol"] = protocol
                    _emit(writer, rec, found, fmt)
    except KeyboardInterrupt:             # Ctrl-C or SIGTERM: what was found so far, then 130/143
        if progress is not None:
            progress.stop()
            progress = None
        note(f"interrupted after {time.monotonic() - t0:.2f} s: "
             f"{len(found)} actuator{'s' if len(found) != 1 else ''} found so far")
        raise
    finally:
        if progress is not None:
            progress.stop()
        writer.close()
    took = time.monotonic() - t0
    where = f"IDs {_ranges(ids)} at {', '.join(str(b) for b in bauds)} baud"
    if not found:
        raise NoReply(f"no actuator answered ({where}, {took:.2f} s)")
    if common["verbose"] or sys.stderr.isatty():
        note(f"{len(found)} actuator{'s' if len(found) != 1 else ''} found ({where}, {took:.2f} s)")


def _emit(writer, rec, found, fmt):
    found.append(rec)
    if fmt == "table":
        rec = dict(rec, _model=f"0x{rec['model']:04X}" if rec["model"] is not None else "?",
                   _errors=", ".join(rec["errors"]) or "-")
    writer.write(rec)


_ranges = zap.id_ranges


# -- dump ----------------------------------------------------------------------------------------

DUMP_COLUMNS = ["id", "register", "address", "value", "physical", "unit", "meaning", "access", "memory"]
DUMP_TABLE = [("_address", "addr"), ("register", "register"), ("value", "value"), ("_physical", "physical"),
              ("meaning", "meaning"), ("access", "access"), ("memory", "memory")]


@click.command(cls=Command, context_settings=CONTEXT)
@id_option(allow_broadcast=False)
@format_option()
@link_options
@protocol_options
def dump(ident, fmt, **common):
    """Read back the whole register map of one actuator (12Lf), with names, units and values.

    The map is read in as few Load Data reads as it has contiguous blocks (two). Records carry
    id, register, address, value, physical and unit (scaled registers), meaning (coded
    registers), access (R/RW) and memory (NV stored, V volatile).

    \b
    Examples:
      zap dump --id 1 -p /dev/ttyUSB0
      zap dump --id 1 -p /dev/ttyUSB0 -f csv > actuator1.csv
    """
    from ...io.writers import make_writer
    from ...link.zap_bus import device_error

    if common["return_mode"] == "0" and common["protocol"] == "ir":
        raise UsageError("--return-mode 0: Load Data is never answered in feedback-return-mode 0")
    with open_link(ids=[ident], probe=ident, **_link_args(common)) as link:
        records, worst = Bus.over(link).dump_records(ident)
    fmt = resolve_format(fmt)
    writer = make_writer(fmt, sys.stdout, DUMP_COLUMNS, table_columns=DUMP_TABLE,
                         title=f"mightyZAP ID {ident}")
    for rec in records:
        if fmt == "table":
            unit = rec.get("unit", "")
            shown = rec.get("physical", rec["value"]) if unit else ""
            rec = dict(rec, _address=f"0x{rec['address']:02X}", _physical=f"{shown} {unit}" if unit else "")
        writer.write(rec)
    writer.close()
    if worst is not None:
        raise device_error(worst)


# -- move ----------------------------------------------------------------------------------------

@exits({CHECK_FAILED: "with --wait, the rod stopped away from the goal (beyond end-compliance-margin)",
        NO_REPLY: "no reply; with --wait, still moving at --wait-timeout",
        DEVICE_ERROR: "a reply carried error bits (overload: the force is cut)"})
@click.command(cls=SignedCommand, context_settings=CONTEXT)
@click.argument("position", type=NUMBER, metavar="POSITION")
@id_option(help="Actuator ID 0..253 (254 or 'broadcast': all, then --wait is not possible).", writes=True)
@click.option("-s", "--speed", type=NUMBER, default=None,
              help=f"Goal speed {SPEED.lo}..{SPEED.hi} (mm/s with --unit mm), written first (default: leave as it is).")
@click.option("-w", "--wait", is_flag=True,
              help="Wait until the actuator stops at the goal; print its final position.")
@click.option("--wait-timeout", type=FiniteRange(0.01, 86400), default=10.0, show_default=True,
              metavar="SECONDS", help="With --wait: give up after this long (exit status 3).")
@click.option("--poll", type=FiniteRange(0.0, 10), default=0.01, show_default=True, metavar="SECONDS",
              help="With --wait: pause between position reads.")
@click.option("--no-stop", is_flag=True,
              help="With --wait: on Ctrl-C or SIGTERM leave the rod moving to its goal (default: stop it "
                   "where it is).")
@unit_options
@link_options
@protocol_options
def move(position, ident, speed, wait, wait_timeout, poll, no_stop, unit, fleet_file, **common):
    """Move to POSITION (0..4095, 0..10000 on the 17Lf; millimetres with --unit mm), optionally
    waiting until the actuator stops there.

    With --unit mm, POSITION and --speed (mm/s) are converted by the actuator's stroke in the
    --fleet file (and the final position printed in mm). Writes goal-speed (with --speed) and goal-position; a goal position turns the force back
    on. The actuator clamps the goal to its stroke limits: --wait reads the goal back and says
    so. With --wait the final position goes to stdout; exit status 3 when it is still moving
    at --wait-timeout, 1 when it stopped away from the goal (beyond end-compliance-margin),
    5 when it reports an error (overload: force cut). Progress is shown on a terminal. Ctrl-C
    or SIGTERM while waiting stops the rod where it is (goal = present position; --no-stop
    leaves it moving), prints the position it stopped at and exits 130/143.

    \b
    Examples:
      zap move 2047 --id 1 -p /dev/ttyUSB0
      zap move 0 --id 1 --speed 300 --wait -p /dev/ttyUSB0
      pos=$(zap move 3000 --id 2 --wait --sim)
      zap move 12.5 --unit mm --fleet fleet.json --id 1 --wait -p /dev/ttyUSB0
      zap move --protocol modbus 12.5 --unit mm --fleet fleet.json --id 1 --wait --sim
    """
    regmap = zap_map()
    scale = None
    if unit == "mm":
        if ident == (zap.BROADCAST if common["protocol"] == "ir" else 0):
            raise UsageError("--unit mm: give one actuator's ID (each has its own stroke)")
        scale = unit_scales(unit, fleet_file, [ident])[ident]
        mm = position
        position = scale.counts(position, what="position")
        if speed is not None:
            speed = scale.speed_raw(speed)
        if common["verbose"]:
            note(f"ID {ident}: {mm:g} mm is position {position}")
    else:
        unit_scales(unit, fleet_file, [])
        for name, v in (("position", position), ("speed", speed)):
            if isinstance(v, float):
                raise UsageError(f"{name}: {v:g} is not a whole number of counts; millimetres need --unit mm")
    regmap.register(POSITION).check(position)       # the goal range of the protocol's map
    if speed is not None:
        regmap.register(SPEED).check(speed)
    if no_stop and not wait:
        raise UsageError("no-stop: applies only with --wait")
    if wait and ident == (zap.BROADCAST if common["protocol"] == "ir" else 0):
        raise UsageError("--wait: a broadcast is never answered; give one actuator's ID to wait for it")
    with open_link(ids=[ident], probe=ident if wait else None, **_link_args(common)) as link:
        bus = Bus.over(link)
        if not wait:
            bus.move(ident, position, speed=speed, wait=False)
            if common["verbose"]:
                note(f"ID {ident}: goal-position {position}" + (f" at speed {speed}" if speed is not None else ""))
            return
        if speed is not None:
            bus.store(ident, SPEED, speed)
        bus.store(ident, POSITION, position)
        if bus.return_mode_of(ident) == 0:
            raise UsageError(f"--wait: ID {ident} is in feedback-return-mode 0 and never answers Load Data")
        progress = _progress(None, f"ID {ident} -> {position}")

        def show(pos, goal, first):
            total = max(1, abs(goal - first))
            progress.update(0, total=total, completed=total - min(total, abs(goal - pos)),
                            description=f"ID {ident}: {pos} -> {goal}")

        told = []

        def on_progress(pos, goal, first):
            if common["verbose"] and not told:
                told.append(True)
                note(f"ID {ident}: moving from {first} to {goal}")
            if progress is not None:
                show(pos, goal, first)

        from ...link.zap_safety import interrupted_move

        import warnings

        from ...errors import GoalClamped

        start = time.monotonic()
        guard = interrupted_move(link, ident, stop=not no_stop, notify=note, why_not=" (--no-stop)")
        try:
            with guard, warnings.catch_warnings():
                warnings.simplefilter("ignore", GoalClamped)      # said below, from the result
                final = bus.wait_stopped(ident, position, timeout=wait_timeout, poll=poll,
                                         on_progress=on_progress, notify=note)
        except KeyboardInterrupt:
            if progress is not None:
                progress.stop()
                progress = None
            if guard.stopped_at is not None:         # where it stopped: the position, as ever
                click.echo(str(guard.stopped_at) if scale is None else f"{scale.mm(guard.stopped_at):g}")
            raise
        finally:
            if progress is not None:
                progress.stop()
        if final.clamped:
            note(f"ID {ident}: goal {final.requested} clamped to {final.goal} by the stroke limits")
        if common["verbose"]:
            note(f"ID {ident} stopped at {final} (goal {final.goal}) after {time.monotonic() - start:.2f} s")
    click.echo(str(final) if scale is None else f"{scale.mm(final):g}")


# -- set-id / set-baud ---------------------------------------------------------------------------

@exits({USAGE: "bad usage or input, or NEW is taken (refused: nothing is written)",
        CHECK_FAILED: "the read-back differs, NEW does not answer or --id still answers"})
@click.command("set-id", cls=Command, context_settings=CONTEXT)
@click.argument("new", type=IdType(allow_broadcast=False), metavar="NEW")
@id_option(allow_broadcast=False, help="The actuator's present ID 0..253 (factory default 0).", writes=True)
@click.option("--force", is_flag=True, help="Go ahead even if another actuator already answers to NEW.")
@click.option("--ready-timeout", type=FiniteRange(0.01, 60), default=2.0, show_default=True, metavar="SECONDS",
              help="How long to wait for the actuator to answer after the change.")
@yes_option
@link_options
@protocol_options
def set_id(new, ident, force, ready_timeout, yes, **common):
    """Give the actuator at --id the ID NEW, verified by reading it back from NEW.

    Checks first that --id answers and that NEW is free: NEW is probed up to three times with
    the full reply allowance, and any reply (error bits, garbled or late) means taken (two
    actuators with one ID garble every reply; --force skips that check). Afterwards NEW must
    read back its ID and --id must be silent. Exit status 2 when NEW is taken (nothing is
    written), 1 when the read-back differs, NEW does not answer or --id still answers. On a real port it asks for consent
    (--yes).

    \b
    Examples:
      zap set-id 1 -p /dev/ttyUSB0 --yes          # a new actuator (ID 0) becomes ID 1
      zap set-id 7 --id 3 -p /dev/ttyUSB0 --yes
    """
    if new == ident:
        note(f"ID {ident} already; nothing to do")
        return
    allow = stored_consent(common, yes, f"change ID {ident} to {new}", "id")
    with open_link(ids=[ident], probe=ident, allow=allow, **_link_args(common)) as link:
        Bus.over(link).set_id(ident, new, force=force, ready_timeout=ready_timeout)
    note(f"ID {ident} is now ID {new} (verified)")


@exits({CHECK_FAILED: "it does not answer at BAUD or reads back another rate"})
@click.command("set-baud", cls=Command, context_settings=CONTEXT)
@click.argument("new_baud", type=Choice([str(b) for b in ALL_BAUDS]), metavar="BAUD")
@id_option(allow_broadcast=False, writes=True)
@click.option("--no-restart", is_flag=True,
              help="Only store the new rate (it takes effect at the next restart or power-up).")
@click.option("--ready-timeout", type=FiniteRange(0.01, 60), default=2.0, show_default=True, metavar="SECONDS",
              help="How long to wait for the actuator to answer after the change.")
@yes_option
@link_options
@protocol_options
def set_baud(new_baud, ident, no_restart, ready_timeout, yes, **common):
    """Change the actuator's baud rate to BAUD (9600, 19200, 38400, 57600, 115200), verified.

    Stores baud-rate, restarts the actuator (the rate takes effect at restart), switches this
    port to BAUD, waits for the actuator to answer there and reads baud-rate back. Exit status
    1 when it does not answer at BAUD or reads back another rate. Later commands need
    -b BAUD (or ZKZAP_ZAP_BAUD). On a real port it asks for consent (--yes).

    \b
    Examples:
      zap set-baud 115200 --id 1 -p /dev/ttyUSB0 --yes
      zap set-baud 57600 --id 1 -b 115200 -p /dev/ttyUSB0 --yes
      zap set-baud --protocol modbus 115200 --id 1 -p /dev/ttyUSB0 --yes

    With --protocol modbus the map's code for BAUD is written (the 17Lf's codes differ from the
    12Lf's) and the actuator answers at BAUD after its reply: there is no restart.
    """
    baud = int(new_baud)
    if common["protocol"] == "modbus" and no_restart:
        raise UsageError("--no-restart: a Modbus actuator takes its new baud rate after the reply (no restart)")
    allow = stored_consent(common, yes, f"change ID {ident}'s baud rate to {baud}", "baud-rate")
    with open_link(ids=[ident], probe=ident, allow=allow, **_link_args(common)) as link:
        Bus.over(link).set_baud(ident, baud, restart=not no_restart, ready_timeout=ready_timeout)
    if no_restart:
        note(f"ID {ident}: baud rate {baud} stored (verified); it takes effect at the next restart")
        return
    note(f"ID {ident} now talks at {baud} baud (verified); use -b {baud} from now on")


# -- detect --------------------------------------------------------------------------------------

DETECT_COLUMNS = ["protocol", "baud", "ids", "found"]


@exits({NO_REPLY: "nothing answers on either protocol at any baud rate tried"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.option("--all", "every", is_flag=True,
              help="Go on after the first protocol and baud rate that answer: every combination is tried.")
@format_option()
@link_options(baud_type=actuator_bauds(), baud_help="Baud rates to try: one, a list like 57600,115200, or 'all' "
                                              "(the default: 57600, 115200, 38400, 19200, 9600).")
def detect(every, fmt, **common):
    """Say which protocol (IR or Modbus RTU) and baud rate the actuators on a bus speak.

    At each baud rate in turn (the factory default first), the IR protocol is scanned (IDs
    0-253) and then Modbus RTU (IDs 1-247), as 'zap scan' does; the first combination where
    an actuator answers is the answer (--all: every combination). Records: protocol, baud,
    ids (the IDs that answered) and found (how many). Exit status 3 when nothing answers.

    \b
    Examples:
      zap detect -p /dev/ttyUSB0
      zap detect -p /dev/ttyUSB0 --all -f json
    """
    from ...api.detect import detect_bus
    from ...io.writers import make_writer

    ctx = click.get_current_context()
    bauds = list(ALL_BAUDS) if ctx.get_parameter_source("baud") == click.core.ParameterSource.DEFAULT \
        else common["baud"]
    fmt = resolve_format(fmt)

    def opener(baud, protocol):          # as every command opens its port (batches, --sim)
        args = _link_args(common)
        args.update(return_mode="1", baud=baud, protocol=protocol, regmap=None)
        return open_link(ids=[0 if protocol == "ir" else 1], **args)

    writer = make_writer(fmt, sys.stdout, DETECT_COLUMNS, title="mightyZAP bus")
    try:
        for rec in detect_bus(bauds=bauds, every=every, retries=common["retries"], on_warning=warn, opener=opener):
            writer.write(dict(rec, ids=_ranges(rec["ids"])) if fmt == "table" else rec)
    finally:
        writer.close()
