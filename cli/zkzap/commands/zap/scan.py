"""Bus-level mightyZAP commands: ``scan``, ``dump``, ``move``, ``set-id`` and ``set-baud``.

They share the link options of the instructions (:func:`.compose.link_options`); every
protocol detail comes from :mod:`zkzap.codec.zap` and every transaction from
:mod:`zkzap.link.zap_bus`.
"""

from __future__ import annotations

import sys
import time

import click

from ...codec import zap
from ...errors import CheckFailed, NoReply, UsageError
from .. import CONTEXT, Command
from ..options import SignedCommand, consent, note, resolve_format, warn, zap_yes_option as yes_option
from .compose import _link_args, link_options, open_link, register_records
from .params import INT, IdType

SCAN_COLUMNS = ["id", "baud", "model", "firmware", "return_mode", "status", "errors"]
SCAN_TABLE = [("id", "id"), ("baud", "baud"), ("_model", "model"), ("firmware", "firmware"),
              ("return_mode", "return mode"), ("status", "status"), ("_errors", "errors")]
#: The order ``--baud all`` tries: the factory default first, then the others fastest first.
ALL_BAUDS = (57600, 115200, 38400, 19200, 9600)
#: The block ``scan`` reads from each actuator found: model-number .. feedback-return-mode.
INFO_FIRST = zap.REGISTER_BY_NAME["model-number"]
INFO_LAST = zap.REGISTER_BY_NAME["feedback-return-mode"]


class IdList(click.ParamType):
    """IDs like ``0-253`` or ``1,2,5-8`` (no broadcast)."""

    name = "ids"

    def convert(self, value, param, ctx):
        if isinstance(value, list):
            return value
        out = []
        for part in str(value).replace(" ", ",").split(","):
            if not part:
                continue
            lo, dash, hi = part.partition("-")
            try:
                first = zap.check_id(lo, allow_broadcast=False)
                last = zap.check_id(hi, allow_broadcast=False) if dash else first
            except Exception as e:  # FieldValueError: name the option
                raise UsageError(f"--ids: {part!r}: {e}") from None
            if last < first:
                raise UsageError(f"--ids: {part!r} runs backwards; write {last}-{first}")
            out.extend(i for i in range(first, last + 1) if i not in out)
        if not out:
            raise UsageError("--ids: none given; expected a list like 0-253 or 1,2,5-8")
        return out


class BaudList(click.ParamType):
    """Baud rates from the actuator's table, or ``all``."""

    name = "bauds"

    def shell_complete(self, ctx, param, incomplete):
        from ..complete import bauds

        return bauds(ALL_BAUDS)(ctx, param, incomplete)

    def convert(self, value, param, ctx):
        if isinstance(value, list):
            return value
        if isinstance(value, int):
            return [value]
        text = str(value).strip().lower()
        if text == "all":
            return list(ALL_BAUDS)
        out = []
        for part in text.replace(" ", ",").split(","):
            if not part:
                continue
            try:
                b = int(part)
            except ValueError:
                b = None
            if b not in zap.BAUD_TO_CODE:
                raise UsageError(f"--baud: {part!r} is not an actuator baud rate; allowed "
                                 f"{', '.join(str(v) for v in ALL_BAUDS)} or all")
            if b not in out:
                out.append(b)
        if not out:
            raise UsageError("--baud: none given; allowed a list like 57600,115200 or all")
        return out


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


def _consent_real(port, sim, yes, action):
    from ...link.zap_bus import is_simulated

    if not (sim or is_simulated(port)):
        consent(f"{action} on {port}: a stored setting that survives power-off", yes)


# -- scan ----------------------------------------------------------------------------------------

@click.command(cls=Command, context_settings=CONTEXT)
@click.option("--ids", "ids", type=IdList(), default="0-253", show_default=True, metavar="RANGE",
              help="IDs to probe, like 0-253 or 1,2,5-8.")
@click.option("-f", "--format", "fmt", type=click.Choice(("table", "json", "jsonl", "csv")), default=None,
              help="Output format (default: table on a terminal, jsonl otherwise).")
@link_options(baud_type=BaudList(), baud_help="Baud rates to scan: one, a list like 57600,115200, or 'all' "
                                              "(57600, 115200, 38400, 19200, 9600) [env ZKZAP_ZAP_BAUD].")
def scan(ids, fmt, **common):
    """Find every actuator on the bus: Echo to each ID at each baud rate, then read the model,
    firmware and return mode of those that answer.

    The wait per ID is derived from the baud rate (about 7 ms at 57600 on a local port; see
    --timeout), so a full 0-253 scan takes about 2 s per baud rate. An ID that does not answer
    is not asked again; --retries applies to garbled replies. Results stream as found: a
    table on a terminal, JSON Lines otherwise (--format), with keys id, baud, model, firmware,
    return_mode, status (ok, error, garbled) and errors. Exit status 3 when nothing answers.

    \b
    Examples:
      zap scan -p /dev/ttyUSB0
      zap scan -b all --ids 0-20 -p /dev/ttyUSB0 -f json
      zap scan --sim --sim-ids 1,2,3
    """
    from ...errors import BadReply
    from ...io.writers import make_writer

    bauds = common["baud"]
    fmt = resolve_format(fmt)
    writer = make_writer(fmt, sys.stdout, SCAN_COLUMNS, table_columns=SCAN_TABLE, title="mightyZAP actuators")
    found = []
    t0 = time.monotonic()
    progress = None
    args = _link_args(common)
    args["return_mode"] = "1"
    args["baud"] = bauds[0]
    try:
        with open_link(ids=[0], **args) as bus:
            progress = _progress(len(ids) * len(bauds), "scanning")
            for baud in bauds:
                bus.set_baud(baud)
                for ident in ids:
                    if progress is not None:
                        progress.update(0, description=f"{baud} baud, ID {ident:3d} ({len(found)} found)")
                    rec = {"id": ident, "baud": baud, "model": None, "firmware": None, "return_mode": None,
                           "status": "ok", "errors": []}
                    try:
                        r = bus.ping(ident, retries=common["retries"])
                    except BadReply as e:
                        rec["status"] = "garbled"
                        rec["errors"] = [str(e)]
                        warn(f"ID {ident} at {rec['baud']} baud answers garbled: two actuators may share "
                             f"this ID (connect one at a time and give each its own with 'zap set-id')")
                        r = None
                        _emit(writer, rec, found, fmt)
                    if progress is not None:
                        progress.advance(0)
                    if r is None:
                        continue
                    rec["errors"] = r.errors
                    if r.error:
                        rec["status"] = "error"
                    _identify(bus, ident, rec)
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


def _identify(bus, ident, rec):
    """Model, firmware and return mode in one Load Data (answered in return modes 1 and 2)."""
    from ...errors import BadReply

    length = INFO_LAST.address + INFO_LAST.size - INFO_FIRST.address
    try:
        r = bus.transact(zap.load(ident, INFO_FIRST.address, length), reply=True, data_len=length,
                         optional=True, check=False)
    except BadReply as e:
        rec["status"] = "garbled"
        rec["errors"] = rec["errors"] + [str(e)]
        return
    if r is None:
        rec["return_mode"] = 0                     # answers Echo but not Load Data
        return
    values = {reg.name: raw for reg, raw in zap._register_values(INFO_FIRST.address, r.data)}
    rec["model"] = values.get("model-number")
    rec["firmware"] = values.get("firmware-version")
    rec["return_mode"] = values.get("feedback-return-mode")


def _emit(writer, rec, found, fmt):
    found.append(rec)
    if fmt == "table":
        rec = dict(rec, _model=f"0x{rec['model']:04X}" if rec["model"] is not None else "?",
                   _errors=", ".join(rec["errors"]) or "-")
    writer.write(rec)


def _ranges(ids):
    out = []
    start = prev = None
    for i in ids:
        if start is None:
            start = prev = i
        elif i == prev + 1:
            prev = i
        else:
            out.append(f"{start}-{prev}" if prev != start else str(start))
            start = prev = i
    out.append(f"{start}-{prev}" if prev != start else str(start))
    return ",".join(out)


# -- dump ----------------------------------------------------------------------------------------

DUMP_COLUMNS = ["id", "register", "address", "value", "physical", "unit", "meaning", "access", "memory"]
DUMP_TABLE = [("_address", "addr"), ("register", "register"), ("value", "value"), ("_physical", "physical"),
              ("meaning", "meaning"), ("access", "access"), ("memory", "memory")]


def map_blocks(gap=8):
    """Contiguous runs of the register map, as (address, length): few, efficient Load Data reads
    (gaps of at most ``gap`` unmapped bytes are read through)."""
    blocks = []
    for reg in sorted(zap.REGISTERS, key=lambda r: r.address):
        end = reg.address + reg.size
        if blocks and reg.address - (blocks[-1][0] + blocks[-1][1]) <= gap:
            blocks[-1][1] = end - blocks[-1][0]
        else:
            blocks.append([reg.address, reg.size])
    return [tuple(b) for b in blocks]


@click.command(cls=Command, context_settings=CONTEXT)
@click.option("-i", "--id", "ident", type=IdType(allow_broadcast=False), default=0, show_default=True,
              help="Actuator ID 0..253.")
@click.option("-f", "--format", "fmt", type=click.Choice(("table", "json", "jsonl", "csv")), default=None,
              help="Output format (default: table on a terminal, jsonl otherwise).")
@link_options
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

    if common["return_mode"] == "0":
        raise UsageError("--return-mode 0: Load Data is never answered in feedback-return-mode 0")
    records = []
    worst = None
    with open_link(ids=[ident], probe=ident, **_link_args(common)) as bus:
        if bus.return_mode == 0:
            raise UsageError(f"ID {ident} is in feedback-return-mode 0: it answers Echo only, never Load Data")
        for address, length in map_blocks():
            reply, values = bus.read_registers(ident, address, length, check=False)
            if reply.error and worst is None:
                worst = reply
            mapped = [(reg, raw) for reg, raw in values if zap.REGISTER_BY_ADDRESS.get(reg.address) is reg]
            records += register_records(ident, mapped, reply.errors)
    fmt = resolve_format(fmt)
    writer = make_writer(fmt, sys.stdout, DUMP_COLUMNS, table_columns=DUMP_TABLE,
                         title=f"mightyZAP ID {ident}")
    for rec in records:
        reg = zap.REGISTER_BY_ADDRESS[rec["address"]]
        rec.pop("errors", None)
        rec["access"] = reg.access
        rec["memory"] = reg.memory
        if fmt == "table":
            unit = rec.get("unit", "")
            shown = rec.get("physical", rec["value"]) if unit else ""
            rec = dict(rec, _address=f"0x{rec['address']:02X}", _physical=f"{shown} {unit}" if unit else "")
        writer.write(rec)
    writer.close()
    if worst is not None:
        raise device_error(worst)


# -- move ----------------------------------------------------------------------------------------

POSITION = zap.REGISTER_BY_NAME["goal-position"]
SPEED = zap.REGISTER_BY_NAME["goal-speed"]
#: present-position .. moving, read in one Load Data while waiting.
WATCH_FIRST = zap.REGISTER_BY_NAME["present-position"]
WATCH_LAST = zap.REGISTER_BY_NAME["moving"]


@click.command(cls=SignedCommand, context_settings=CONTEXT)
@click.argument("position", type=INT, metavar="POSITION")
@click.option("-i", "--id", "ident", type=IdType(), default=0, show_default=True,
              help="Actuator ID 0..253 (254 or 'broadcast': all, then --wait is not possible).")
@click.option("-s", "--speed", type=INT, default=None,
              help=f"Goal speed {SPEED.lo}..{SPEED.hi}, written first (default: leave as it is).")
@click.option("-w", "--wait", is_flag=True,
              help="Wait until the actuator stops at the goal; print its final position.")
@click.option("--wait-timeout", type=click.FloatRange(0.01, 86400), default=10.0, show_default=True,
              metavar="SECONDS", help="With --wait: give up after this long (exit status 3).")
@click.option("--poll", type=click.FloatRange(0.0, 10), default=0.01, show_default=True, metavar="SECONDS",
              help="With --wait: pause between position reads.")
@click.option("--no-stop", is_flag=True,
              help="With --wait: on Ctrl-C or SIGTERM leave the rod moving to its goal (default: stop it "
                   "where it is).")
@link_options
def move(position, ident, speed, wait, wait_timeout, poll, no_stop, **common):
    """Move to POSITION (0..4095), optionally waiting until the actuator stops there.

    Writes goal-speed (with --speed) and goal-position; a goal position turns the force back
    on. The actuator clamps the goal to its stroke limits: --wait reads the goal back and says
    so. With --wait the final position goes to stdout; exit status 3 when it is still moving
    at --wait-timeout, 1 when it stopped away from the goal (beyond end-compliance-margin),
    5 when it reports an error (overload: force cut). Progress is shown on a terminal. Ctrl-C
    or SIGTERM while waiting stops the rod where it is (goal = present position; --no-stop
    leaves it moving) and exits 130/143.

    \b
    Examples:
      zap move 2047 --id 1 -p /dev/ttyUSB0
      zap move 0 --id 1 --speed 300 --wait -p /dev/ttyUSB0
      pos=$(zap move 3000 --id 2 --wait --sim)
    """
    POSITION.check(position)
    if speed is not None:
        SPEED.check(speed)
    if no_stop and not wait:
        raise UsageError("no-stop: applies only with --wait")
    if wait and ident == zap.BROADCAST:
        raise UsageError("--wait: a broadcast is never answered; give one actuator's ID to wait for it")
    with open_link(ids=[ident], probe=ident if wait else None, **_link_args(common)) as bus:
        if speed is not None:
            bus.store(ident, SPEED, speed)
        bus.store(ident, POSITION, position)
        if not wait:
            if common["verbose"]:
                note(f"ID {ident}: goal-position {position}" + (f" at speed {speed}" if speed is not None else ""))
            return
        if bus.return_mode == 0:
            raise UsageError(f"--wait: ID {ident} is in feedback-return-mode 0 and never answers Load Data")
        from ...link.zap_safety import interrupted_move

        with interrupted_move(bus, ident, stop=not no_stop, notify=note):
            final = _wait(bus, ident, position, wait_timeout, poll, common["verbose"])
    click.echo(str(final))


def _wait(bus, ident, position, limit, poll, verbose):
    goal = bus.read(ident, POSITION)
    margin = bus.read(ident, zap.REGISTER_BY_NAME["end-compliance-margin"])
    if goal != position:
        note(f"ID {ident}: goal {position} clamped to {goal} by the stroke limits")
    length = WATCH_LAST.address + WATCH_LAST.size - WATCH_FIRST.address
    start = time.monotonic()
    progress = _progress(None, f"ID {ident} -> {goal}")
    first = None
    try:
        while True:
            _, values = bus.read_registers(ident, WATCH_FIRST.address, length)
            v = {reg.name: raw for reg, raw in values}
            pos, moving = v["present-position"], v["moving"]
            if first is None:
                first = pos
                if verbose:
                    note(f"ID {ident}: moving from {pos} to {goal}")
            if progress is not None:
                total = max(1, abs(goal - first))
                progress.update(0, total=total, completed=total - min(total, abs(goal - pos)),
                                description=f"ID {ident}: {pos} -> {goal}")
            if not moving:
                if abs(pos - goal) <= max(margin, 1):
                    if verbose:
                        note(f"ID {ident} stopped at {pos} (goal {goal}) after {time.monotonic() - start:.2f} s")
                    return pos
                force = bus.read(ident, zap.REGISTER_BY_NAME["force-on-off"])
                why = "; the force is off" if not force else ""
                raise CheckFailed(f"ID {ident} stopped at {pos}, {abs(pos - goal)} away from the goal {goal}{why}")
            if time.monotonic() - start >= limit:
                raise NoReply(f"ID {ident} still moving after {limit:g} s (position {pos}, goal {goal})")
            if poll:
                time.sleep(poll)
    finally:
        if progress is not None:
            progress.stop()


# -- set-id / set-baud ---------------------------------------------------------------------------

ID_REG = zap.REGISTER_BY_NAME["id"]
BAUD_REG = zap.REGISTER_BY_NAME["baud-rate"]


def _read_back(bus, ident, reg, within, silent):
    """After a change: wait until ``ident`` answers again, then read ``reg``. ``silent`` is the
    failure (exit 1) when it does not answer within ``within`` seconds."""
    try:
        bus.wait_ready(ident, within=within)
        return bus.read(ident, reg)
    except NoReply:
        raise CheckFailed(silent) from None


@click.command("set-id", cls=Command, context_settings=CONTEXT)
@click.argument("new", type=IdType(allow_broadcast=False), metavar="NEW")
@click.option("-i", "--id", "ident", type=IdType(allow_broadcast=False), default=0, show_default=True,
              help="The actuator's present ID 0..253 (factory default 0).")
@click.option("--force", is_flag=True, help="Go ahead even if another actuator already answers to NEW.")
@click.option("--ready-timeout", type=click.FloatRange(0.01, 60), default=2.0, show_default=True, metavar="SECONDS",
              help="How long to wait for the actuator to answer after the change.")
@yes_option
@link_options
def set_id(new, ident, force, ready_timeout, yes, **common):
    """Give the actuator at --id the ID NEW, verified by reading it back from NEW.

    Checks first that --id answers and that NEW is free (two actuators with one ID garble
    every reply; --force skips that check). Exit status 1 when the read-back differs or NEW
    does not answer afterwards. On a real port it asks for consent (--yes).

    \b
    Examples:
      zap set-id 1 -p /dev/ttyUSB0 --yes          # a new actuator (ID 0) becomes ID 1
      zap set-id 7 --id 3 -p /dev/ttyUSB0 --yes
    """
    if new == ident:
        note(f"ID {ident} already; nothing to do")
        return
    _consent_real(common["port"], common["sim"], yes, f"change ID {ident} to {new}")
    with open_link(ids=[ident], probe=ident, **_link_args(common)) as bus:
        bus.echo(ident)
        if not force and bus.ping(new) is not None:
            raise CheckFailed(f"ID {new} is already taken by another actuator; choose a free ID "
                              "('zap scan') or pass --force")
        bus.store(ident, ID_REG, new)
        value = _read_back(bus, new, ID_REG, ready_timeout,
                           f"set-id: ID {new} does not answer after the change; check with 'zap scan'")
    if value != new:
        raise CheckFailed(f"set-id: ID {new} reads back its ID as {value}")
    note(f"ID {ident} is now ID {new} (verified)")


@click.command("set-baud", cls=Command, context_settings=CONTEXT)
@click.argument("new_baud", type=click.Choice([str(b) for b in ALL_BAUDS]), metavar="BAUD")
@click.option("-i", "--id", "ident", type=IdType(allow_broadcast=False), default=0, show_default=True,
              help="Actuator ID 0..253.")
@click.option("--no-restart", is_flag=True,
              help="Only store the new rate (it takes effect at the next restart or power-up).")
@click.option("--ready-timeout", type=click.FloatRange(0.01, 60), default=2.0, show_default=True, metavar="SECONDS",
              help="How long to wait for the actuator to answer after the change.")
@yes_option
@link_options
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
    """
    baud = int(new_baud)
    code = zap.BAUD_TO_CODE[baud]
    _consent_real(common["port"], common["sim"], yes, f"change ID {ident}'s baud rate to {baud}")
    with open_link(ids=[ident], probe=ident, **_link_args(common)) as bus:
        bus.echo(ident)
        bus.store(ident, BAUD_REG, code)
        if no_restart:
            value = bus.read(ident, BAUD_REG)
            if value != code:
                raise CheckFailed(f"set-baud: ID {ident} reads back baud-rate {value}, expected {code}")
            note(f"ID {ident}: baud rate {baud} stored (verified); it takes effect at the next restart")
            return
        bus.restart(ident)
        bus.set_baud(baud)
        value = _read_back(bus, ident, BAUD_REG, ready_timeout,
                           f"set-baud: ID {ident} does not answer at {baud} baud after the restart; "
                           f"try 'zap scan --baud all'")
    if value != code:
        raise CheckFailed(f"set-baud: ID {ident} reads back baud-rate code {value}, expected {code} ({baud})")
    note(f"ID {ident} now talks at {baud} baud (verified); use -b {baud} from now on")
