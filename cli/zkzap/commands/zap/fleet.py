"""Fleet commands: ``zap backup``, ``zap diff``, ``zap apply`` and ``zap setup``.

Thin: options -> :mod:`zkzap.api.fleet` -> writers. The link options are the instructions'
(:func:`.compose.link_options`).
"""

from __future__ import annotations

import sys

import click

from ...api import fleet
from ...codec import zap
from ...errors import CHECK_FAILED, CheckFailed, DEVICE_ERROR, MORE_TO_DO, NO_REPLY, NoReply, OK, USAGE, UsageError
from .. import CONTEXT, Command
from ..options import (Choice, InputPath, OutputPath, buses_option, consent, exits, fleet_option, note, plural,
                       protocol_options, resolve_format, warn, zap_map, zap_yes_option as yes_option)
from .compose import _link_args, link_options, open_link
from .scan import IdList, actuator_bauds

DOC_FORMATS = ("json", "toml", "yaml")
ROW_FORMATS = ("table", "json", "jsonl", "csv")


def _from_file(common, entries) -> None:
    """A fleet file's protocol and map are the bus's where --protocol (or its environment
    variable) does not say one: ``zap apply modbus-fleet.json`` talks Modbus RTU. Where it does
    and they differ, the apply or diff refuses (:func:`zkzap.api.fleet.same_map`)."""
    from click.core import ParameterSource

    from ...codec.regmap import default_map

    fm = fleet.map_of(entries)
    ctx = click.get_current_context()
    if ctx.get_parameter_source("protocol") in (None, ParameterSource.DEFAULT) and common.get("regmap") is None:
        common["protocol"] = fm.protocol
        if fm is not default_map(fm.protocol):
            common["regmap"] = fm


def _ir_return_mode(common, why) -> None:
    """--return-mode 0 refused on IR (Load Data is never answered there); Modbus has no return mode."""
    if common["return_mode"] == "0" and common.get("protocol", "ir") == "ir":
        raise UsageError(f"--return-mode 0: {why}")


def zap_map_of(common):
    """The register map of the bus ``common`` (the link options, as the command resolved them) talks to."""
    from ...codec.regmap import default_map

    return common.get("regmap") or default_map(common.get("protocol") or "ir")


def _real(common) -> bool:
    from ...link.zap_bus import is_simulated

    return not (common["sim"] or is_simulated(common["port"]))


def _write_rows(rows, columns, fmt, *, table_columns, title, stream=None):
    from ...io.writers import make_writer

    stream = stream if stream is not None else sys.stdout
    fmt = resolve_format(fmt, stream)
    writer = make_writer(fmt, stream, columns, table_columns=table_columns, title=title)
    try:
        for row in rows:
            if fmt == "table":
                row = {k: ("-" if v is None or v == [] else v) for k, v in row.items()}
            writer.write(row)
    finally:
        writer.close()


class MapType(click.ParamType):
    """``OLD:NEW,...`` pairs of actuator IDs."""

    name = "map"

    def convert(self, value, param, ctx):
        if isinstance(value, dict):
            return value
        out = {}
        for part in str(value).replace(" ", ",").split(","):
            if not part:
                continue
            old, sep, new = part.partition(":")
            try:
                if not sep:
                    raise ValueError
                a = zap.check_id(old, allow_broadcast=False)
                b = zap.check_id(new, allow_broadcast=False)
            except Exception:  # FieldValueError, ValueError
                raise UsageError(f"--id-map: {part!r} is not OLD:NEW with IDs 0..253 (like 1:5,2:6)") from None
            if a in out:
                raise UsageError(f"--id-map: ID {a} is mapped twice")
            out[a] = b
        if not out:
            raise UsageError("--id-map: none given; expected OLD:NEW pairs like 1:5,2:6")
        return out


#: What ``zap apply --map`` took before it named a register map file: ``OLD:NEW,...`` ID pairs.
OLD_ID_MAP = r"\s*\d+\s*:\s*\d+\s*(?:[, ]\s*\d+\s*:\s*\d+\s*)*"


def _apply_map_callback(ctx, param, value):
    """zap apply's --map: a register map file, as on every zap command; a value of the old form
    ``OLD:NEW,...`` (the ID mapping, now --id-map) that names no file is still taken as the ID
    mapping, with a note; one that also names a file is ambiguous: refused (exit 2)."""
    import os
    import re

    if value is not None and re.fullmatch(OLD_ID_MAP, value):
        if os.path.exists(value):
            raise UsageError(f"--map {value}: both a file and OLD:NEW ID pairs; give --map ./{value} for the "
                             f"register map file, or --id-map {value} for the IDs")
        warn(f"--map {value}: the ID mapping is --id-map now (--map names a register map file, as on every zap "
             f"command); taken as --id-map {value}")
        ctx.meta["zkzap.apply.id_map"] = MapType().convert(value, param, ctx)
        return None
    from ..options import _map_callback

    return _map_callback(ctx, param, value)


class RegisterList(click.ParamType):
    """Register names, comma separated."""

    name = "registers"

    def convert(self, value, param, ctx):
        if isinstance(value, list):
            return value
        return [p for p in str(value).replace(" ", ",").split(",") if p]

    def shell_complete(self, ctx, param, incomplete):
        from click.shell_completion import CompletionItem

        head, _, last = incomplete.rpartition(",")
        prefix = head + "," if head else ""
        return [CompletionItem(prefix + r.name, help=r.help) for r in zap.REGISTERS
                if r.writable and r.name.startswith(last)]


# -- backup --------------------------------------------------------------------------------------

#: -b of the fleet commands that search the bus: one baud rate, a list, or all (as zap scan).
SEARCH_BAUDS = dict(baud_type=actuator_bauds(), baud_help="Baud rates to search: one, a list like 57600,115200, "
                                                         "or 'all' (as zap scan) [env ZKZAP_ZAP_BAUD].", several=True)


@exits({NO_REPLY: "a listed ID does not answer (nothing written)",
        DEVICE_ERROR: "an actuator reports error bits (the backup is written first)",
        CHECK_FAILED: "two actuators answer to one ID (nothing written)"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.option("--ids", "ids", type=IdList(), default=None, metavar="LIST",
              help="Actuators to back up, like 1,2,5-8 (each must answer); with --scan: the IDs to search.")
@click.option("--scan", "scan_", is_flag=True,
              help="Back up every actuator that answers (IDs 0-253, or --ids, at -b's baud rates), found as "
                   "'zap scan' finds them. The default without --ids.")
@click.option("-o", "--output", type=OutputPath("document", formats=DOC_FORMATS, default=None), default=None,
              help="Write the backup to FILE: .json, .toml or .yaml by its suffix (default: JSON on stdout).")
@click.option("-f", "--format", "fmt", type=Choice(DOC_FORMATS), default=None,
              help="Document format (default: from --output's suffix; JSON on stdout).")
@link_options(**SEARCH_BAUDS)
@protocol_options
@buses_option("Back up")
@fleet_option
def backup(ids, scan_, output, fmt, bus_names=None, fleet_file=None, **common):
    """Back up every readable register of every actuator: a fleet document.

    The document groups the actuators by ID, each with its model number, firmware version and
    the baud rate it answered at, the time, and the zkzap version; registers are in sections
    'stored' (NV: survives power-off), 'volatile' (V) and 'read-only' (for reference, never
    written back). Values are raw, in the units of 'zap registers'. The file is written
    atomically once every actuator has been read; exit status 3 when a listed ID does not
    answer (nothing written), 5 when one reports error bits (the backup is written first).
    Without --ids (or with --scan) the actuators are found as 'zap scan' finds them, at each
    baud rate of -b (a list, or all); a bus where two actuators answer to one ID is refused
    (exit 1, naming the ID), never backed up without one of them.

    \b
    Examples:
      zap backup -p /dev/ttyUSB0 -o fleet.json                 # every actuator found
      zap backup --ids 1-4 -p /dev/ttyUSB0 -o fleet.toml
      zap backup --ids 1 -p /dev/ttyUSB0 -f yaml > one.yaml
      zap backup -b all -p /dev/ttyUSB0 -o fleet.json          # every actuator at any baud rate
      zap backup --protocol modbus -p /dev/ttyUSB0 -o fleet.json   # 17Lf actuators (Modbus RTU)

    The document names its protocol and register map (protocol, map): a Modbus RTU fleet's file
    is read back as one, and never applied to an IR bus (nor the other way round).

    Several buses (-p again, or --buses NAMES of a --fleet file) are read at once, each on its
    own thread: the document names each bus (buses.NAME: port, baud, ids and its actuators; an
    ID is that bus's), and zap diff and zap apply take it bus by bus.
    """
    if output and output != "-":
        doc_fmt = fmt or fleet.format_of(output)
        from ...outfile import check_path

        check_path(output, "output")          # before the bus is read: the file is written at the end
    else:
        doc_fmt = fmt or "json"
    _ir_return_mode(common, "Load Data is never answered in feedback-return-mode 0")
    bauds = common["baud"]
    if fleet_file and bus_names is None:
        raise UsageError("--fleet: it names the buses of --buses; give --buses all (or NAMES) with it")
    from .motion import several_buses

    if several_buses(bus_names):
        return _backup_buses(ids, output, doc_fmt, bus_names, fleet_file, common)
    search = scan_ or ids is None or len(bauds) > 1
    targets = ids if ids is not None else fleet.all_ids(zap_map())
    sim_ids = ids if ids is not None else [0]
    args = dict(_link_args(common), baud=bauds[0])
    with open_link(ids=sim_ids, probe=None if search else sim_ids[0], **args) as bus:
        if search:
            found = fleet.survey(bus, targets, bauds, scan=True, retries=common["retries"])
            if not found:
                raise NoReply(f"no actuator answered (IDs {fleet._ranges(targets)} at "
                              f"{', '.join(map(str, bauds))} baud)")
            missing = [i for i in ids or () if i not in {r["id"] for r in found}] if not scan_ else []
            if missing:
                raise NoReply(f"no reply from ID{'s' if len(missing) > 1 else ''} {fleet._ranges(missing)} at "
                              f"{', '.join(map(str, bauds))} baud")
            if common["return_mode"] == "auto" and common.get("protocol", "ir") == "ir":
                bus.detect_return_mode(found[0]["id"])
        else:
            found = [{"id": i, "baud": bus.baud} for i in targets]
        targets = [r["id"] for r in found]
        shown = sys.stderr.isatty() or common["verbose"]

        def said(ident, entry):
            if shown:
                note(f"ID {ident}: model 0x{entry['model']:04X}, firmware {entry['firmware']}, "
                     f"{len(entry['stored'])} stored settings")

        doc = fleet.read_fleet(bus, found, on_actuator=said)
    doc["port"] = "sim" if common["sim"] else common["port"]
    if output and output != "-":
        from ...api.units import keep_motion, motion_entries

        kept = keep_motion(doc, motion_entries(output))     # strokes and calibrations are not on the bus
        fleet.dump_document(doc, output, doc_fmt)
        note(f"{len(targets)} actuator{'s' if len(targets) != 1 else ''} ({fleet._ranges(targets)}) "
             f"backed up to {output}" + (f"; the motion entries of {fleet._ranges(kept)} kept" if kept else ""))
    else:
        click.echo(fleet.dumps(doc, doc_fmt), nl=False)
    bad = [(i, e["errors"]) for i, e in doc["actuators"].items() if e.get("errors")]
    if bad:
        from ...errors import DeviceError

        raise DeviceError("; ".join(f"ID {i} reports {', '.join(errs)}" for i, errs in bad))


# -- diff ----------------------------------------------------------------------------------------

DIFF_TABLE = [("id", "id"), ("register", "register"), ("memory", "memory"), ("a", "A"), ("b", "B"),
              ("unit", "unit")]


@exits({OK: "equal", CHECK_FAILED: "they differ (like diff), or two actuators answer to one ID on the bus",
        USAGE: "a bad file or option"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("a", metavar="A", type=InputPath("fleet"))
@click.argument("b", metavar="B", type=InputPath("fleet"))
@click.option("--ids", "ids", type=IdList(), default=None, metavar="LIST",
              help="Compare only these actuators (default: every ID of either file; on the bus, every "
                   "actuator a scan finds at -b's baud rates).")
@click.option("--all", "everything", is_flag=True, help="List equal registers too (column equal).")
@click.option("--compare", type=Choice(tuple(fleet.COMPARE)), default="stored", show_default=True,
              help="stored: the settings that survive power-off; settings: stored and volatile; all: "
                   "read-only values too.")
@click.option("-f", "--format", "fmt", type=Choice(ROW_FORMATS), default=None,
              help="Output format (default: table on a terminal, jsonl otherwise).")
@link_options(**SEARCH_BAUDS)
@protocol_options
@buses_option("Compare")
def diff(a, b, ids, everything, compare, fmt, bus_names=None, **common):
    """Compare two fleets: A and B are backup files or 'bus' (the live bus on -p).

    One row per actuator and register that differs: id, register, address, memory, a, b,
    unit ('0.1 V' for raw values in tenths); an actuator on one side only is one row with
    register '(actuator)'. Exit status 0 when equal, 1 when they differ (like diff), 2 for a
    bad file. On the bus, --ids are asked for one by one; without it (or with several baud
    rates in -b, a list or all) the actuators are found as 'zap scan' finds them, and a bus
    where two actuators answer to one ID is refused (exit 1, naming it).

    \b
    Examples:
      zap diff fleet.json bus -p /dev/ttyUSB0
      zap diff monday.json friday.yaml --compare settings
      zap diff fleet.json bus -p /dev/ttyUSB0 -f csv > drift.csv
      zap diff machine.json bus --buses all                    # every bus the file names, at once

    A backup of several buses is compared bus by bus (rows start with bus): with the bus, on
    the buses it names (--buses all or NAMES; or -p once per bus, matched by name or port).
    """
    if a == "bus" and b == "bus":
        raise UsageError("diff: A and B are both the bus; compare a file with the bus")
    from .motion import several_buses

    if several_buses(bus_names) or _per_bus(a, common.get("regmap")) or _per_bus(b, common.get("regmap")):
        return _diff_buses(a, b, ids, everything, compare, fmt, bus_names, common)
    sides = {}
    for label, src in (("A", a), ("B", b)):
        if src != "bus":
            sides[label] = fleet.read_document(src, common.get("regmap"))
    if "bus" in (a, b):
        other = next(iter(sides.values()))
        _from_file(common, other)
        _ir_return_mode(common, "Load Data is never answered in feedback-return-mode 0")
        fleet.same_map(fleet.map_of(other), zap_map_of(common), a if a != "bus" else b, "the bus")
        bauds = common["baud"]
        args = dict(_link_args(common), baud=bauds[0])
        with open_link(ids=ids if ids is not None else sorted(other), **args) as bus:
            if common["return_mode"] == "auto" and common["protocol"] == "ir":
                bus.detect_return_mode((ids or sorted(other))[0])
            live = fleet.bus_entries(bus, ids, bauds, retries=common["retries"])
        sides["A" if a == "bus" else "B"] = live
    nowhere = [i for i in ids or () if i not in sides["A"] and i not in sides["B"]]
    if nowhere:
        raise UsageError(f"--ids: ID{'s' if len(nowhere) > 1 else ''} {fleet._ranges(nowhere)} "
                         f"{'are' if len(nowhere) > 1 else 'is'} in neither {a} nor {b}")
    rows = fleet.diff(sides["A"], sides["B"], compare=compare, ids=ids, everything=everything)
    title = f"A = {a}, B = {b}"
    table = DIFF_TABLE + ([("equal", "equal")] if everything else [])
    _write_rows(rows, fleet.DIFF_COLUMNS, fmt, table_columns=table, title=title)
    different = sum(1 for r in rows if not r["equal"])
    if different:
        note(f"{different} difference{'s' if different != 1 else ''} between {a} and {b} ({compare} registers)")
        raise click.exceptions.Exit(1)        # a result, like diff(1), not an error: exit 1 and a note
    if sys.stderr.isatty() or common["verbose"]:
        note(f"{a} and {b} are equal ({compare} registers)")


# -- apply ---------------------------------------------------------------------------------------

PLAN_TABLE = [("id", "id"), ("register", "register"), ("memory", "memory"), ("old", "bus"), ("new", "file"),
              ("unit", "unit"), ("status", "status"), ("read_back", "read back"), ("errors", "errors")]


@exits({OK: "every write reads back (or, with --plan, the plan was printed)",
        CHECK_FAILED: "a write reads back another value",
        USAGE: "a bad FILE or option (nothing written)", NO_REPLY: "an actuator does not answer",
        DEVICE_ERROR: "an actuator reports error bits"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("file", metavar="FILE", type=InputPath("fleet"))
@click.option("--ids", "ids", type=IdList(), default=None, metavar="LIST",
              help="Apply only these actuators of FILE (default: all of them).")
@click.option("--id-map", "mapping", type=MapType(), default=None, metavar="OLD:NEW,...",
              help="Apply FILE's actuator OLD to the bus's actuator NEW (--map OLD:NEW, its old spelling, is still "
                   "taken where it names no file).")
@click.option("--to", "to", type=IdList(), default=None, metavar="LIST",
              help="Clone the one selected actuator of FILE onto every bus ID listed, like 1-8.")
@click.option("--only", "only", type=RegisterList(), default=None, metavar="REG,...",
              help="Write only these registers (volatile ones too; id, baud-rate, protocol-type and "
                   "feedback-return-mode with --force).")
@click.option("--skip", "skip", type=RegisterList(), default=None, metavar="REG,...",
              help="Never write these registers.")
@click.option("--plan", "plan_only", is_flag=True, help="Print the writes it would make; write nothing.")
@click.option("--force", is_flag=True,
              help="Write id, baud-rate, protocol-type or feedback-return-mode named in --only; apply a file "
                   "from another model or firmware.")
@click.option("-f", "--format", "fmt", type=Choice(ROW_FORMATS), default=None,
              help="Output format of the plan and the result (default: table on a terminal, jsonl otherwise).")
@yes_option
@link_options(several=True)
@protocol_options(map_callback=_apply_map_callback)
@buses_option("Apply")
def apply(file, ids, mapping, to, only, skip, plan_only, force, fmt, yes, bus_names=None, **common):
    """Make the bus match FILE: write the stored settings that differ, read each back.

    Reads every target actuator, computes the writes (a write that would change nothing is
    skipped: stored writes wear the actuator's memory), shows the plan, asks for consent once on
    a real port (--yes), writes, reads each back, and prints one row per write: id, register,
    old (the bus's value), new (FILE's), status (verified, mismatch; planned with --plan),
    read_back. Volatile settings are written only when named in --only; id, baud-rate,
    protocol-type and feedback-return-mode only with --only and --force: the plan and the
    summary name every difference left out and why, so "0 writes" never hides one. A clone
    (--to, --id-map) never copies the file's id (it would give two actuators one ID); an id write
    is checked free first, as set-id does. A baud-rate write says when the rate takes effect. A
    file from another model or firmware is refused unless --force.

    An interrupted apply (Ctrl-C, a vanished port, a silent actuator) prints the writes that
    were made and says which; running the same command again makes the rest. Exit status 0
    when every write reads back, 1 when one reads back another value, 2 for a bad FILE or
    option (nothing written), 3 when an actuator does not answer, 5 for error bits.

    \b
    Examples:
      zap apply fleet.json -p /dev/ttyUSB0 --plan
      zap apply fleet.json -p /dev/ttyUSB0 --yes
      zap apply fleet.json --ids 1 --to 2-8 -p /dev/ttyUSB0 --yes     # clone ID 1 onto 2..8
      zap apply old.json --id-map 1:5,2:6 --skip current-limit -p /dev/ttyUSB0 --yes
      zap apply fleet.json --protocol modbus --map my-model.map -p /dev/ttyUSB0 --yes   # a map of your own
      zap apply fleet.json --only goal-speed,led -p /dev/ttyUSB0       # volatile settings
      zap apply machine.json --buses all --yes                         # every bus the file names

    A backup of several buses is applied bus by bus, each on its own thread (--buses all or
    NAMES: the file's ports; or -p once per bus, matched by name or port); rows start with bus.
    """
    from .motion import several_buses

    legacy = click.get_current_context().meta.get("zkzap.apply.id_map")
    if legacy is not None:
        if mapping is not None:
            raise UsageError("--map OLD:NEW and --id-map: give the ID mapping once, as --id-map")
        mapping = legacy
    if several_buses(bus_names) or _per_bus(file, common.get("regmap")):
        return _apply_buses(file, ids, mapping, to, only, skip, plan_only, force, fmt, yes, bus_names, common)
    entries = fleet.read_document(file, common.get("regmap"))
    file = "stdin" if file == "-" else file
    _from_file(common, entries)
    fleet.same_map(fleet.map_of(entries), zap_map_of(common), file, "the bus")
    pairs = fleet.assignments(entries, ids=ids, mapping=mapping, to=to)
    regmap = fleet.map_of(entries)
    only_regs = fleet.registers_option(only, "--only", regmap) if only is not None else None
    skip_regs = fleet.registers_option(skip, "--skip", regmap)
    if only_regs is not None:
        for reg in only_regs:
            if reg.name in fleet.PROTECTED and not force:
                raise UsageError(f"--only {reg.name}: this changes how the actuator is reached; add --force")
    fleet.check_only(only_regs, pairs)
    _ir_return_mode(common, "Load Data is never answered, so nothing can be compared or read back")
    targets = [t for _, t in pairs]
    from ...codec.permissions import FORCE, Permission
    from ...io.term import is_tty
    from ...link.zap_bus import device_error

    interactive = is_tty(sys.stdin) and is_tty(sys.stderr)
    if _real(common) and not plan_only and (yes or not interactive):
        # a script gets its answer before the port opens; a terminal sees the plan first (below)
        consent(f"apply {file} to {common['port']}: it writes stored settings that survive power-off", yes)
    allow = (FORCE if force else Permission.NONE) | (Permission.STORED if yes else Permission.NONE)

    with open_link(ids=targets, probe=targets[0], allow=allow, **_link_args(common)) as bus:
        writes, unchanged, current = fleet.plan_bus(bus, entries, pairs, name=file, only=only_regs, skip=skip_regs,
                                                    force=force, on_mismatch=warn)
        n_act = len({w.target for w in writes})
        stored = sum(1 for w in writes if w.register.stored)
        equal = plural(unchanged, "setting") + " already equal"
        if stored and stored == len(writes):
            kept = " (to a stored setting, which survives power-off)" if stored == 1 else \
                " (all to stored settings, which survive power-off)"
        else:
            kept = f" ({stored} of them to stored settings, which survive power-off)" if stored else ""
        to_write = f"{plural(len(writes), 'write')} on {plural(n_act, 'actuator')}{kept}"
        summary = f"{to_write}; {equal}" if writes else f"nothing to write; {equal}"
        left_out = fleet.left_out(entries, pairs, current, only=only_regs, skip=skip_regs)
        if left_out:
            summary += "; " + fleet.describe_left_out(left_out)
        if plan_only:
            _write_rows([w.record() for w in writes], fleet.PLAN_COLUMNS, fmt, table_columns=PLAN_TABLE,
                        title=f"plan: {file}")
            note(f"plan: {summary}; nothing written")
            return
        if not writes:
            note(f"nothing to write: every setting apply writes matches {file} ({unchanged} already equal)"
                 + (f"; {fleet.describe_left_out(left_out)}" if left_out else ""))
            return
        if _real(common) and not yes:
            if is_tty(sys.stderr):
                _write_rows([w.record() for w in writes], fleet.PLAN_COLUMNS, "table", table_columns=PLAN_TABLE,
                            title=f"plan: {file}", stream=sys.stderr)
            consent(f"apply {file} to {common['port']}: {summary}", yes)
            bus.allow |= Permission.STORED
        elif common["verbose"] or sys.stderr.isatty():
            note(f"applying {file}: {summary}")
        done: list = []
        try:
            fleet.execute(bus, writes, done)
        except BaseException as e:
            _report_interrupted(writes, done, fmt, file, e)
            raise
    _write_rows([w.record() for w in writes], fleet.PLAN_COLUMNS, fmt, table_columns=PLAN_TABLE,
                title=f"applied: {file}")
    for w in writes:
        if w.status == "unverifiable":
            warn(f"ID {w.target}: feedback-return-mode {w.new} written; in mode 0 it answers Echo only, so it "
                 "cannot be read back")
        elif w.note:
            note(w.note)
    bad = [w for w in writes if w.status not in ("verified", "unverifiable")]
    if bad:
        raise CheckFailed("; ".join(f"ID {w.target}: {w.register.name} reads back {w.read_back}, wrote {w.new}"
                                    for w in bad[:3]) + (f" (and {len(bad) - 3} more)" if len(bad) > 3 else ""))
    errs = [w for w in writes if w.errors]
    if errs:
        from ...link.zap_bus import Reply

        w = errs[0]
        err = sum(1 << b for b, n in zap.ERROR_BITS.items() if n in w.errors)
        raise device_error(Reply(w.target, err, b"", b""))
    note(f"{len(writes)} write{'s' if len(writes) != 1 else ''} made and verified ({unchanged} already equal"
         + (f"; {fleet.describe_left_out(left_out)}" if left_out else "") + ")")


def _report_interrupted(writes, done, fmt, file, exc):
    """After an interruption: the writes made go to stdout, a summary to stderr."""
    unsure = []
    for w in writes:
        if w.status == "sending":
            w.status = "unknown"          # interrupted while its packet went out
            unsure.append(w)
        elif w not in done:
            w.status = "not-sent"
    try:
        _write_rows([w.record() for w in done + unsure], fleet.PLAN_COLUMNS, fmt, table_columns=PLAN_TABLE,
                    title=f"interrupted: {file}")
    except Exception:  # noqa: BLE001 - a closed stdout must not hide the original failure
        pass
    what = "interrupted" if isinstance(exc, KeyboardInterrupt) else f"stopped ({exc})"
    read = ("verified", "mismatch", "unverifiable")
    made = ", ".join(f"ID {w.target} {w.register.name}" + ("" if w.status in read else " (not read back)")
                     for w in done) or "none"
    left = len(writes) - len(done) - len(unsure)
    maybe = "".join(f"; ID {w.target} {w.register.name} may or may not have been written" for w in unsure)
    click.echo(f"apply {what}: {len(done)} of {len(writes)} writes made: {made}{maybe}; {left} not made. "
               f"Run the same apply again to finish (writes already made are skipped).", err=True)


# -- setup ---------------------------------------------------------------------------------------

@exits({OK: "every ID is done",
        CHECK_FAILED: "IDs were skipped or one could not be set up (two answer, none found, a read-back differs)",
        MORE_TO_DO: "more to do: the run stopped as asked (--no-wait after its one ID, or q) with IDs pending; "
                    "running it again goes on"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.option("--ids", "ids", type=IdList(), required=True, metavar="LIST",
              help="The IDs to give, in order, one actuator each: like 1-8.")
@click.option("--config", "config", type=InputPath("fleet"), default=None,
              help="A backup file whose stored settings each actuator gets (id, baud-rate, protocol-type "
                   "and feedback-return-mode excepted).")
@click.option("--config-id", type=IdList(), default=None, metavar="ID",
              help="Which actuator of --config to copy (default: its only one).")
@click.option("--state", "state_path", type=OutputPath("state"), default="zap-setup.json", show_default=True,
              help="The state file: a second run resumes where the first stopped.")
@click.option("--skip", "skip", type=IdList(), default=None, metavar="LIST", help="IDs of --ids to leave out.")
@click.option("--redo", "redo", type=IdList(), default=None, metavar="LIST",
              help="Set these IDs up again although the state file has them done.")
@click.option("--find-ids", type=IdList(), default="0-253", show_default=True, metavar="RANGE",
              help="The IDs to search for each new actuator.")
@click.option("--find-baud", type=actuator_bauds(), default="all", show_default=True, metavar="BAUDS",
              help="The baud rates to search: a list or 'all' (57600 first).")
@click.option("--set-baud", "set_baud", type=Choice([str(b) for b in sorted(zap.BAUD_TO_CODE, reverse=True)]),
              default=None, metavar="RATE",
              help="Bring every actuator to this baud rate (found at any rate of --find-baud; checked free "
                   "and read back at the new rate, as set-baud does).")
@click.option("--no-wait", is_flag=True,
              help="Do not wait for Enter: set up the actuator connected now (the next pending ID) and stop; "
                   "exit status 8 when IDs remain pending.")
@yes_option
@link_options
@protocol_options
def setup(ids, config, config_id, state_path, skip, redo, find_ids, find_baud, set_baud, no_wait, yes, **common):
    """Guided ID setup: one actuator at a time, each gets the next ID of --ids.

    For each pending ID it asks you to connect the next actuator alone and press Enter (s and
    Enter skips the ID, q quits; the answers are read from stdin, so a script can pipe them).
    It finds the actuator at any ID of --find-ids and any baud rate of --find-baud, refuses
    when two actuators answer (or one that was set up already), gives it the ID, applies
    --config's stored settings, and verifies by reading back. The state file records each ID
    done, so a second run (after a crash, a Ctrl-C, or another day) resumes with the next one.
    The actuator keeps the baud rate it was found at. Exit status 0 when every ID is done; 8
    (more to do) when the run stopped as asked with IDs still pending (--no-wait after its one
    ID, or q), so a script can loop on it; 1 when IDs were skipped or one could not be set up
    (two answer, none found, a read-back differs); 2 for bad options. On a real port the ID
    changes need consent (--yes).

    \b
    Examples:
      zap setup --ids 1-8 -p /dev/ttyUSB0 --yes
      zap setup --ids 1-8 --config fleet.json --config-id 1 -p /dev/ttyUSB0 --yes
      zap setup --ids 1-8 --redo 3 -p /dev/ttyUSB0 --yes      # set up ID 3 again
      zap setup --ids 1-8 --set-baud 115200 -p /dev/ttyUSB0 --yes  # every actuator at 115200 baud

    --set-baud RATE brings every actuator to one baud rate: its rate is changed first (the ID it
    was found at checked free at RATE, the actuator restarted on IR and read back at RATE), then
    its ID is given at RATE (checked free there), then --config's settings.
    """
    entry = None
    if config:
        entries = fleet.read_document(config, common.get("regmap"))
        _from_file(common, entries)
        fleet.same_map(fleet.map_of(entries), zap_map_of(common), config, "the bus")
        if config_id is not None:
            if len(config_id) != 1 or config_id[0] not in entries:
                raise UsageError(f"--config-id: give one ID of {config} ({', '.join(map(str, sorted(entries)))})")
            entry = entries[config_id[0]]
        elif len(entries) != 1:
            raise UsageError(f"--config: {config} has {len(entries)} actuators; choose one with --config-id")
        else:
            entry = next(iter(entries.values()))
    elif config_id is not None:
        raise UsageError("--config-id needs --config")
    for opt, lst in (("--skip", skip), ("--redo", redo)):
        for i in lst or ():
            if i not in ids:
                raise UsageError(f"{opt}: ID {i} is not in --ids")
    _ir_return_mode(common, "Load Data is never answered, so nothing can be verified")
    from ...outfile import check_state

    check_state(state_path)                   # read now and saved after each ID: a file it can rewrite
    state = fleet.SetupState.load(state_path, ids)
    state.ids = ids
    for i in redo or ():
        state.redo(i, save=False)
    for i in skip or ():
        state.mark_skipped(i, save=False)
    if not state.pending():
        if redo or skip:
            state.save()
        _setup_summary(state)
        _setup_end(state, state_path, stopped=False)
        return
    from .scan import stored_consent

    rate = None if set_baud is None else int(set_baud)
    allow = stored_consent(common, yes, "setup gives actuators new IDs" + (f", the baud rate {rate}" if rate else "")
                           + (f" and {config}'s stored settings" if config else ""),
                           "id" + (", baud-rate" if rate else "") + (f" and {config}'s stored settings" if config else ""))
    if redo or skip:
        state.save()
    args = _link_args(common)
    args["baud"] = find_baud[0]
    regmap = zap_map_of(common)
    search = [i for i in find_ids if i in set(fleet.all_ids(regmap))]   # (no broadcast ID 0 on Modbus RTU)
    factory = regmap.by_name["id"].default or 0                         # the ID a new actuator comes with
    stopped = refused = False
    with open_link(ids=[0], allow=allow, **args) as bus:
        while state.pending():
            target = state.pending()[0]
            if not no_wait:
                answer = _ask(f"connect the actuator for ID {target} alone, then press Enter "
                              f"(s: skip ID {target}, q: quit) ")
                if answer is None or answer == "q":
                    note(f"stopped before ID {target}; run the same command again to resume ({state_path})")
                    stopped = True
                    break
                if answer == "s":
                    state.mark_skipped(target)
                    note(f"ID {target} skipped")
                    continue
            done_ids = set(state.done)
            try:
                found = fleet.find_alone(bus, search, find_baud, prefer=[factory, target])
                if found[0] in done_ids and found[0] != target:
                    raise fleet.TwoAnswer(f"the actuator found answers as ID {found[0]} at {found[1]} baud, "
                                          f"which this setup gave already; connect the next one "
                                          f"(or --redo {found[0]})")
                record = fleet.setup_one(bus, target, found=found, config=entry, baud=rate)
                if record.get("warning"):
                    warn(f"ID {target}: {record['warning']}")
            except (fleet.TwoAnswer, fleet.NotFound, NoReply, CheckFailed) as e:
                if no_wait:
                    raise
                warn(f"ID {target}: {e}")
                refused = True
                continue
            state.mark_done(target, record)
            note(f"ID {target} done: found at ID {found[0]}, {found[1]} baud"
                 + (f"; now at {rate} baud" if rate and rate != found[1] else "")
                 + (f"; {record.get('config', 0)} settings from {config}" if entry is not None else "")
                 + " (verified)")
            if no_wait:
                stopped = True
                break
    _setup_summary(state)
    _setup_end(state, state_path, stopped=stopped and not refused)


def _setup_end(state, state_path, *, stopped):
    """The end of a setup, and its exit status: 0 when every ID is done; 8 (more to do) when
    the run stopped as asked (--no-wait after its one ID, q) with IDs pending; 1 when IDs were
    skipped or could not be set up."""
    from ...errors import MoreToDo

    ids = state.ids
    pending = state.pending()
    skipped = [i for i in ids if i in state.skipped and i not in state.done]
    if not pending and not skipped:
        note(f"every ID of {fleet._ranges(ids)} is done ({state_path}); --redo ID sets one up again")
        return
    if pending and stopped and not skipped:
        raise MoreToDo(f"more to do: ID{'s' if len(pending) != 1 else ''} {fleet._ranges(pending)} not set up yet; "
                       f"run the same command again ({state_path})", pending=pending)
    parts = []
    if pending:
        parts.append(f"ID{'s' if len(pending) != 1 else ''} {fleet._ranges(pending)} not set up")
    if skipped:
        parts.append(f"ID{'s' if len(skipped) != 1 else ''} {fleet._ranges(skipped)} skipped "
                     f"(--redo {fleet._ranges(skipped)} sets {'them' if len(skipped) != 1 else 'it'} up)")
    raise CheckFailed(f"setup not complete: {'; '.join(parts)} ({state_path})", pending=pending, skipped=skipped)


def _ask(prompt):
    """A line from stdin after a prompt on stderr: '' for Enter, 's', 'q'; None at end of input."""
    click.echo(prompt, err=True, nl=False)
    try:
        line = sys.stdin.readline()
    except (OSError, ValueError):
        return None
    if not line:
        click.echo("", err=True)
        return None
    return line.strip().lower()[:1]


def _setup_summary(state):
    done = sorted(i for i in state.done if i in state.ids)
    parts = [f"{len(done)} of {len(state.ids)} done" + (f" ({fleet._ranges(done)})" if done else "")]
    skipped = [i for i in state.skipped if i in state.ids]
    if skipped:
        parts.append(f"skipped {fleet._ranges(skipped)}")
    note("setup: " + "; ".join(parts))


# -- several buses -------------------------------------------------------------------------------

def _per_bus(path, regmap=None) -> bool:
    """Whether a fleet file (not 'bus', not stdin) keeps its actuators per bus (a backup of several buses);
    ``regmap``: a --map FILE (the file's model may be one zkzap does not ship)."""
    if path in ("bus", "-"):
        return False
    return bool(fleet.read_bus_document(path, regmap)[0])


def _bus_specs(bus_names, fleet_file, common, ids=()):
    from .motion import bus_specs

    _ir_return_mode(common, "Load Data is never answered in feedback-return-mode 0")
    if bus_names is None and ports_given_() is None:
        raise UsageError("this file keeps its actuators per bus: give --buses all (or NAMES), or -p once per bus")
    return bus_specs(bus_names, fleet_file, common, "counts", ids)


def ports_given_():
    from ..options import ports_given

    return ports_given()


def _backup_buses(ids, output, doc_fmt, bus_names, fleet_file, common):
    """zap backup of several buses: one thread a bus, one document naming each."""
    from .motion import open_spec

    specs = _bus_specs(bus_names, fleet_file, common, ids or ())
    shown = sys.stderr.isatty() or common["verbose"]

    def said(bus, ident, entry):
        if shown:
            note(f"bus {bus} ID {ident}: model 0x{entry['model']:04X}, firmware {entry['firmware']}, "
                 f"{len(entry['stored'])} stored settings")

    bauds = list(common["baud"]) if ports_given_() is not None else None
    doc = fleet.backup_buses(specs, bauds=bauds, retries=common["retries"], open_bus=open_spec(common),
                             on_actuator=said)
    n = sum(len(b["actuators"]) for b in doc["buses"].values())
    if output and output != "-":
        fleet.dump_document(doc, output, doc_fmt)
        note(f"{plural(n, 'actuator')} on {len(specs)} buses backed up to {output}")
    else:
        click.echo(fleet.dumps(doc, doc_fmt), nl=False)
    bad = [(bus, i, e["errors"]) for bus, b in doc["buses"].items() for i, e in b["actuators"].items()
           if e.get("errors")]
    if bad:
        from ...errors import DeviceError

        raise DeviceError("; ".join(f"bus {bus} ID {i} reports {', '.join(errs)}" for bus, i, errs in bad))


def _diff_buses(a, b, ids, everything, compare, fmt, bus_names, common):
    """zap diff of backups of several buses, or of one with its live buses (one thread a bus)."""
    from .motion import open_spec

    if ids is not None:
        raise UsageError("--ids: with several buses every actuator of each bus is compared")
    sides, ports = {}, {}
    for label, src in (("A", a), ("B", b)):
        if src != "bus":
            per_bus, ports[label], _ = fleet.read_bus_document(src, common.get("regmap"))
            if not per_bus:
                raise UsageError(f"{src}: not a backup of several buses (no buses.NAME.actuators)")
            sides[label] = per_bus
    if "bus" in (a, b):
        label = "A" if a != "bus" else "B"
        _from_file(common, next(iter(sides[label].values())))    # its protocol, where --protocol says none
        specs = _bus_specs(bus_names, a if a != "bus" else b, common)
        wanted = fleet.match_buses(sides[label], ports[label], specs, a if a != "bus" else b)
        live = fleet.live_buses(specs, retries=common["retries"], open_bus=open_spec(common),
                                bauds=list(common["baud"]) if ports_given_() is not None else None)
        sides[label] = wanted
        sides["B" if label == "A" else "A"] = live
    rows = fleet.diff_buses(sides["A"], sides["B"], compare=compare, everything=everything)
    table = [("bus", "bus")] + DIFF_TABLE + ([("equal", "equal")] if everything else [])
    _write_rows(rows, ["bus"] + fleet.DIFF_COLUMNS, fmt, table_columns=table, title=f"A = {a}, B = {b}")
    different = sum(1 for r in rows if not r["equal"])
    if different:
        note(f"{different} difference{'s' if different != 1 else ''} between {a} and {b} ({compare} registers, "
             f"{len(set(sides['A']) | set(sides['B']))} buses)")
        raise click.exceptions.Exit(1)
    if sys.stderr.isatty() or common["verbose"]:
        note(f"{a} and {b} are equal ({compare} registers)")


def _apply_buses(file, ids, mapping, to, only, skip, plan_only, force, fmt, yes, bus_names, common):
    """zap apply of a backup of several buses: each bus planned and written on its own thread."""
    from ...codec.permissions import FORCE, Permission
    from .motion import open_spec

    if ids is not None or mapping or to is not None:
        raise UsageError("--ids, --id-map, --to: with several buses each bus's actuators are applied as the file has "
                         "them")
    if file == "-":
        raise UsageError("several buses: give the backup as a file, not stdin")
    per_bus, ports, _ = fleet.read_bus_document(file, common.get("regmap"))
    if not per_bus:
        raise UsageError(f"{file}: not a backup of several buses (no buses.NAME.actuators)")
    _from_file(common, next(iter(per_bus.values())))      # its protocol, where --protocol says none
    regmap = fleet.map_of(next(iter(per_bus.values())))
    only_regs = fleet.registers_option(only, "--only", regmap) if only is not None else None
    skip_regs = fleet.registers_option(skip, "--skip", regmap)
    for reg in only_regs or ():
        if reg.name in fleet.PROTECTED and not force:
            raise UsageError(f"--only {reg.name}: this changes how the actuator is reached; add --force")
    specs = _bus_specs(bus_names, file, common)
    wanted = fleet.match_buses(per_bus, ports, specs, file)
    real = any(not _simulated(s.port) for s in specs)
    if real and not plan_only:
        consent(f"apply {file} to {len(specs)} buses: it writes stored settings that survive power-off", yes)
    allow = (FORCE if force else Permission.NONE) | (Permission.STORED if (yes or not real) else Permission.NONE)
    records, summaries, made = [], {}, {}
    from ...io.writers import make_writer

    out_fmt = resolve_format(fmt, sys.stdout)
    writer = make_writer(out_fmt, sys.stdout, ["bus"] + fleet.PLAN_COLUMNS, table_columns=[("bus", "bus")] + PLAN_TABLE,
                         title=f"{'plan' if plan_only else 'applied'}: {file}")
    try:
        for kind, bus, item in fleet.apply_buses(specs, wanted, name=file, only=only_regs, skip=skip_regs, force=force,
                                                  plan_only=plan_only, allow=allow, open_bus=open_spec(common),
                                                  on_mismatch=warn):
            if kind == "write":
                row = dict({"bus": bus}, **item.record())
                if out_fmt == "table":
                    row = {k: ("-" if v is None or v == [] else v) for k, v in row.items()}
                writer.write(row)
                records.append((bus, item))
            elif kind == "summary":
                summaries[bus] = item
            else:
                made[bus] = item
    except BaseException as e:
        writer.close()
        text = "; ".join(f"bus {b}: {len(d)} of {len(w)} writes made" for b, (d, w) in made.items())
        click.echo(f"apply stopped ({e}): {text or 'no write made'}. Run the same apply again to finish "
                   "(writes already made are skipped).", err=True)
        raise
    writer.close()
    for bus, (unchanged, left, n) in summaries.items():
        text = (f"bus {bus}: {plural(n, 'write')}{'' if plan_only or not n else ' made and verified'}; "
                f"{plural(unchanged, 'setting')} already equal")
        if left:
            text += "; " + fleet.describe_left_out(left)
        note(("plan: " if plan_only else "") + text + ("; nothing written" if plan_only else ""))
    for bus, w in records:
        if w.note:
            note(f"bus {bus}: {w.note}")
    bad = [(bus, w) for bus, w in records if not plan_only and w.status not in ("verified", "unverifiable")]
    if bad:
        raise CheckFailed("; ".join(f"bus {bus} ID {w.target}: {w.register.name} reads back {w.read_back}, wrote "
                                    f"{w.new}" for bus, w in bad[:3]))


def _simulated(port) -> bool:
    from ...link.zap_bus import is_simulated

    return is_simulated(port)
