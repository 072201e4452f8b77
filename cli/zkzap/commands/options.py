"""Options and helpers shared by every command module (one definition each).

Nothing here imports rich or pyserial: both are loaded by the functions that need them.
"""

from __future__ import annotations

import math
import sys

import click

from ..codec.fields import beyond_float, quote_value
from ..errors import UsageError, clip
from ..io import FORMATS
from . import Command

#: Environment variables giving defaults, one pair per protocol group.
ENV = {
    "zk": {"port": "ZKZAP_ZK_PORT", "baud": "ZKZAP_ZK_BAUD", "stop_bits": "ZKZAP_ZK_STOPBITS"},
    "zap": {"port": "ZKZAP_ZAP_PORT", "baud": "ZKZAP_ZAP_BAUD", "stop_bits": "ZKZAP_ZAP_STOPBITS"},
}
#: What the stop-bit option says per group: the ZK document allows 1 or 2; the mightyZAP side is
#: 8N1, and the option is there for adapters that need it.
STOP_BITS_HELP = {
    "zk": "Stop bits of the ECU's UART (8 data bits, no parity): 1 or 2, as the ECU is configured",
    "zap": "Stop bits (the actuators use 8N1; for adapters that need 2)",
}
#: Default baud rates: the mightyZAP factory default is 57600 (code 32); the ZK document lists
#: 2400..115200 as configurable without a default, and 115200 is the common ECU setting.
DEFAULT_BAUD = {"zk": 115200, "zap": 57600}


class Lazy:
    """``Lazy(name)()`` is module ``name``, imported at the first call.

    For the library modules a command needs only when it talks to a device: a dry run never
    imports them, and a batch's lines, which run the command again and again in one process, do
    not pay an import statement on every line (a function-level import costs 10-16 us right after
    the process slept through a reply, several times a warm one)."""

    __slots__ = ("_name", "_module")

    def __init__(self, name: str):
        self._name = name
        self._module = None

    def __call__(self):
        module = self._module
        if module is None:
            import importlib

            module = self._module = importlib.import_module(self._name)
        return module


class SignedCommand(Command):
    """A command whose positional arguments may be negative numbers (``ignition-voltage -0.5``).

    click would read ``-0.5`` as an unknown option and never name the field: a token that looks
    like a negative number, is no option of this command and is not an option's value is moved
    behind ``--`` (keeping the arguments' order), so the field's own range check reports it.
    """

    negative_numbers = True


def _number(value, kind, allowed, param, ctx, fail):
    """``value`` as a finite ``kind`` (int or float), or ``fail`` with zkzap's wording: "'abc' is
    not a number; allowed 1..200" (never click's "is not a valid float range")."""
    if isinstance(value, bool):
        value = str(value)
    if isinstance(value, (int, float)) and not (kind is int and isinstance(value, float)):
        number = value
    else:
        text = str(value).strip()
        try:
            number = int(text, 0) if kind is int else float(text)
        except ValueError:
            what = "an integer" if kind is int else "a number"
            fail(f"{clip(repr(value))} is not {what}{allowed}", param, ctx)
    if isinstance(number, float) and not math.isfinite(number):     # an int of any size is finite
        if beyond_float(value, number):
            # a finite number beyond a float's range (1e400, 400 digits): too large, not infinite
            fail(f"{clip(repr(value))} is out of range{allowed or ' (a float reaches 1.8e308)'}", param, ctx)
        fail(f"{clip(repr(value))} is not a finite number{allowed}", param, ctx)
    return kind(number)


def range_text(lo, hi, lo_open=False, hi_open=False) -> str:
    """A range as messages and help say it: ``1..200``, ``1 or more``, ``more than 0``."""
    if lo is not None and hi is not None and not lo_open and not hi_open:
        return f"{lo:g}..{hi:g}"
    parts = []
    if lo is not None:
        parts.append(f"more than {lo:g}" if lo_open else f"{lo:g} or more")
    if hi is not None:
        parts.append(f"less than {hi:g}" if hi_open else f"at most {hi:g}")
    return " and ".join(parts) or "any number"


class _NumberRange:
    """zkzap's wording for click's numeric range types: "'x' is not a number; allowed 1..200",
    "500 is out of range; allowed 1..200"."""

    kind = float

    def __init__(self, min=None, max=None, min_open=False, max_open=False, clamp=False, *, unit=None,
                 hint=None):
        super().__init__(min, max, min_open, max_open, clamp)
        self.unit = unit
        self.hint = hint

    def allowed(self) -> str:
        text = range_text(self.min, self.max, self.min_open, self.max_open)
        return f"{text} {self.unit}" if self.unit else text

    def _describe_range(self) -> str:
        """The range as ``--help`` shows it after an option's text (``[1..200]``)."""
        return self.allowed()

    def convert(self, value, param, ctx):
        number = _number(value, self.kind, f"; allowed {self.allowed()}", param, ctx, self.fail)
        lo_bad = self.min is not None and (number <= self.min if self.min_open else number < self.min)
        hi_bad = self.max is not None and (number >= self.max if self.max_open else number > self.max)
        if lo_bad or hi_bad:
            extra = self.hint(number) if self.hint is not None else None
            shown = f"{number:g}" if isinstance(number, float) else quote_value(number)
            self.fail(f"{shown} is out of range; allowed {self.allowed()}" + (f" ({extra})" if extra else ""),
                      param, ctx)
        return number


class FiniteFloat(click.types.FloatParamType):
    """A float that must be a finite number: ``nan``, ``inf`` and ``-inf`` are refused (exit 2,
    naming the option), where click's FLOAT takes them and a timeout or duration never ends."""

    def convert(self, value, param, ctx):
        return _number(value, float, "", param, ctx, self.fail)


class Integer(click.types.IntParamType):
    """An integer (decimal or ``0x..``) in zkzap's words, for values whose range the codec
    checks itself."""

    def convert(self, value, param, ctx):
        return _number(value, int, "", param, ctx, self.fail)


class FiniteRange(_NumberRange, click.FloatRange):
    """``click.FloatRange`` for finite numbers only (its own comparisons let ``nan`` through,
    and ``inf`` wherever there is no upper bound), in zkzap's words. Every float option of
    zkzap is one of these or a :class:`FiniteFloat`.

    With ``unit`` the range is named in that unit (help and messages), and ``hint`` (a function
    of an out-of-range value, returning text or None) may add what the number probably meant
    (``800`` for a density in kg/L: kg/m³)."""

    name = "number"
    kind = float


class IntRange(_NumberRange, click.IntRange):
    """``click.IntRange`` in zkzap's words (decimal or ``0x..``). Every integer option of zkzap
    is one of these."""

    name = "integer"
    kind = int


class Choice(click.Choice):
    """``click.Choice`` that names the closest choices of a misspelt value ("'rn' is not
    allowed; allowed pwm, stop, standby, run; did you mean run?"). Every choice option of zkzap
    is one of these."""

    def convert(self, value, param, ctx):
        try:
            return super().convert(value, param, ctx)
        except click.BadParameter:
            from ..errors import did_you_mean

            choices = [str(c) for c in self.choices]
            self.fail(f"{value!r} is not allowed; allowed {', '.join(choices)}{did_you_mean(value, choices)}",
                      param, ctx)


FINITE = FiniteFloat()
INTEGER = Integer()


# --- exit statuses ---------------------------------------------------------------------------------

def exits(meanings=None, tail=""):
    """Declare a command's own exit statuses: ``{code: what it means for this command}`` over
    the defaults :func:`exit_statuses` derives from its parameters (a meaning of None drops a
    default); ``tail`` follows the list in ``--help``. Decorates a click command (put it above
    ``@click.command``) or applies to one: ``exits({...})(command)``."""
    def apply(cmd):
        if not isinstance(cmd, click.Command):
            raise TypeError("exits(): put it above @click.command (it decorates a command)")
        cmd.exit_meanings = dict(meanings or {})
        cmd.exit_tail = tail
        return cmd

    return apply


def exit_statuses(cmd) -> list:
    """``[(code, meaning), ...]`` of a leaf command, in the order of the exit-code table (143
    after 130): what every command can exit with (0, 2, 7, 130, 143), what a command that opens
    a port can (3 and 4; 5 and 6 on a mightyZAP bus, whose replies carry error bits and
    checksums), what ``--verify`` adds (1 and 3: the read-back), ``--limit`` (5), and what the
    command declares with :func:`exits`."""
    from ..errors import (BAD_REPLY, CHECK_FAILED, DEVICE_ERROR, EXIT_CODES, INTERRUPTED, NO_REPLY, OK, OUTPUT_ERROR,
                          PORT_ERROR, TERMINATED, USAGE)

    meanings = {OK: "success", USAGE: "bad usage or input (nothing was sent)",
                OUTPUT_ERROR: "the output could not be written (disk full) or stalled", INTERRUPTED: "Ctrl-C",
                TERMINATED: "SIGTERM (128+N: another signal N, 129 SIGHUP)"}
    port = next((p for p in cmd.params if p.name == "port" and isinstance(p, click.Option)), None)
    if port is not None:
        envvar = port.envvar if isinstance(port.envvar, str) else " ".join(port.envvar or ())
        meanings[PORT_ERROR] = "the port cannot be opened, or failed or vanished"
        if ENV["zap"]["port"] in envvar:
            meanings[NO_REPLY] = "no reply within the timeout, after the retries"
            meanings[DEVICE_ERROR] = "a reply carried error bits"
            meanings[BAD_REPLY] = "a corrupted or unexpected reply, after the retries"
        else:
            meanings[NO_REPLY] = "no status frame within --timeout"
    if any(p.name == "verify" for p in cmd.params):          # writes read back (store, sync-move)
        meanings[CHECK_FAILED] = "with --verify, a value reads back different"
        meanings[NO_REPLY] = "no reply; with --verify, nothing answers the read-back (the write is unconfirmed)"
    meanings.update(getattr(cmd, "exit_meanings", {}))
    if any(p.name == "limit" for p in cmd.params) and "limit" not in (meanings.get(DEVICE_ERROR) or ""):
        meanings[DEVICE_ERROR] = ", or ".join(m for m in (meanings.get(DEVICE_ERROR), "a --limit was violated") if m)
    order = [c for c, _ in EXIT_CODES]
    order.insert(order.index(INTERRUPTED) + 1, TERMINATED)
    return [(code, meanings[code]) for code in order if meanings.get(code) is not None]


def exit_help(cmd) -> str:
    """The ``Exit status: ...`` paragraph of a command's ``--help``."""
    from ..errors import exit_status_help

    return exit_status_help(dict(exit_statuses(cmd)), tail=getattr(cmd, "exit_tail", ""))


#: Where messages go while a live view holds the terminal (its ``note``): above the view.
_NOTE_SINKS = []


def note(message: str) -> None:
    """A message for the person (stderr), never mixed with data; above a live view while one is
    shown (:func:`notes_above`)."""
    if _NOTE_SINKS:
        _NOTE_SINKS[-1](f"note: {message}")
        return
    click.echo(f"note: {message}", err=True)


class notes_above:
    """``with notes_above(view.note):`` every :func:`note` and :func:`warn` goes to ``sink`` (a live
    view's place above itself) until the block ends."""

    def __init__(self, sink):
        self.sink = sink

    def __enter__(self):
        _NOTE_SINKS.append(self.sink)
        return self

    def __exit__(self, *exc):
        _NOTE_SINKS.remove(self.sink)
        return False


def warn(message: str) -> None:
    if _NOTE_SINKS:
        _NOTE_SINKS[-1](f"warning: {message}")
        return
    from ..io.term import color_enabled, style

    click.echo(f"{style('warning:', sys.stderr, fg='yellow', bold=True)} {message}", err=True,
               color=color_enabled(sys.stderr))


def format_option(*, choices=FORMATS, help_extra="", default=None, help=None):
    """``-f/--format``, the one definition: by default a table on a terminal, JSON Lines
    otherwise; a command with its own ``default`` (``value``, ``text``) or ``help`` says so."""
    return click.option(
        "-f", "--format", "fmt", type=Choice(choices), default=default, show_default=default is not None,
        help=(help if help is not None else "Output format (default: table on a terminal, jsonl otherwise).")
        + help_extra)


def rate_option(help="Control frames per second (default 20)."):
    """``--rate HZ``: how often a ZK session sends its control frame (1..200 Hz)."""
    return click.option("--rate", type=FiniteRange(1, 200), default=None, metavar="HZ", help=help)


def abort_option(help, default=None):
    """``--abort standby|stop|none``: what a ZK session sends when it ends abnormally (the
    choices are :data:`zkzap.codec.zk.ABORTS`)."""
    from ..codec.zk import ABORTS

    return click.option("--abort", type=Choice(list(ABORTS)), default=default,
                        show_default=default is not None, help=help)


def id_option(default=0, allow_broadcast=True, help=None, *, writes=False):
    """``-i/--id``: a mightyZAP actuator ID 0..253, and 254/'broadcast' where allowed.

    ``writes``: the command writes to (or acts on) the actuator it names: the option has no
    default, so a forgotten ``--id`` is bad usage (exit 2, nothing sent) instead of a write to
    whatever answers at ID 0 (on Modbus, 0 is the broadcast). Broadcast stays possible, given
    explicitly (``--id broadcast``), under its own permission rules."""
    from .zap.params import IdType

    if help is None:
        help = "Actuator ID 0..253" + (" (254 or 'broadcast': all, never answered)." if allow_broadcast else ".")
    if writes:
        help = help.rstrip(".") + "; required: a write has no default ID."
        return click.option("-i", "--id", "ident", type=IdType(allow_broadcast), required=True, help=help)
    return click.option("-i", "--id", "ident", type=IdType(allow_broadcast), default=default, show_default=True,
                        help=help)


#: The mightyZAP protocol families (``--protocol``): the IR protocol of the 12Lf and Modbus RTU
#: of the 17Lf (and of a 12Lf switched to it).
ZAP_PROTOCOLS = ("ir", "modbus")
PROTOCOL_ENV = "ZKZAP_ZAP_PROTOCOL"


def _map_callback(ctx, param, value):
    if value is None:
        return None
    from ..codec.regmap import load_map

    return load_map(value)                 # MapError: exit 2, FILE:LINE


def protocol_options(f=None, *, protocols=ZAP_PROTOCOLS, ir_only=None, map_callback=None):
    """``--protocol ir|modbus`` and ``--map FILE``, the one definition for every zap command.
    Both are eager: a REGISTER argument is read against the map they choose
    (:func:`zap_map`). ``ir_only``: why the command has no Modbus RTU form (``--protocol
    modbus``, or the environment saying it, is then refused with that reason, exit 2).
    ``map_callback``: reads --map's value where a command reads more than a map file (zap
    apply: an old ID mapping); it returns the map, or None."""
    if f is None:
        return lambda g: protocol_options(g, protocols=protocols, ir_only=ir_only, map_callback=map_callback)
    f = click.option("--map", "regmap", metavar="FILE", default=None, is_eager=True,
                     callback=map_callback or _map_callback,
                     help="A register map file for a model zkzap does not ship (format: the manual's "
                          "Modbus page); its 'protocol:' line must agree with --protocol.")(f)
    return protocol_option(f, protocols=protocols, ir_only=ir_only)


def _protocol_callback(ir_only):
    def callback(ctx, param, value):
        if ir_only and value != "ir":
            source = ctx.get_parameter_source(param.name)
            given = f"{PROTOCOL_ENV}={value}" if source == click.core.ParameterSource.ENVIRONMENT \
                else f"--protocol {value}"
            raise UsageError(f"{given}: zap {ctx.info_name} speaks the IR protocol only: {ir_only}")
        return value

    return callback


def protocol_option(f=None, *, protocols=ZAP_PROTOCOLS, ir_only=None):
    """``--protocol ir|modbus`` alone (the simulator, which has no map to choose); see
    :func:`protocol_options` for ``ir_only``."""
    if f is None:
        return lambda g: protocol_option(g, protocols=protocols, ir_only=ir_only)
    f = click.option("--protocol", type=Choice(list(protocols)), default="ir", show_default=True,
                     is_eager=True, envvar=PROTOCOL_ENV, callback=_protocol_callback(ir_only),
                     help="The actuators' protocol family: ir (the 12Lf's IR protocol) or modbus (Modbus RTU: "
                          f"the 17Lf, or a 12Lf with protocol-type 0) [env {PROTOCOL_ENV}]."
                          + (f" IR only: {ir_only}." if ir_only else ""))(f)
    for param in getattr(f, "__click_params__", ()):
        if param.name == "protocol":
            param.ir_only = ir_only        # why the command has no Modbus form (None: it has one)
    return f


def zap_map(ctx=None):
    """The register map a zap command works with: ``--map FILE``, else the shipped map of
    ``--protocol`` (the 12Lf's on ir, the 17Lf's on modbus). A map whose protocol is not
    ``--protocol`` is refused (exit 2)."""
    from ..codec.regmap import default_map

    ctx = ctx or click.get_current_context(silent=True)
    params = ctx.params if ctx is not None else {}
    protocol = params.get("protocol") or "ir"
    regmap = params.get("regmap")
    if regmap is None:
        return default_map(protocol)
    if regmap.protocol != protocol:
        from ..errors import UsageError

        raise UsageError(f"map: {regmap.path} describes the {regmap.protocol} protocol; give --protocol "
                         f"{regmap.protocol}")
    return regmap


def fleet_option(f, help="The fleet file giving each actuator's stroke (motion.part, motion.stroke_mm or a zap "
                          "calibrate calibration), for --unit mm [env ZKZAP_ZAP_FLEET]."):
    """``--fleet FILE``: the fleet file of the actuators' strokes and the machine's buses."""
    return click.option("--fleet", "fleet_file", type=InputPath("fleet"), default=None, envvar="ZKZAP_ZAP_FLEET",
                        metavar="FILE", help=help)(f)


def buses_option(what):
    """``--buses NAMES``: work on the buses the --fleet file names, each on its own thread
    (:mod:`zkzap.api.buses`); ``what`` says what is done on each."""
    return click.option("--buses", "bus_names", default=None, metavar="NAMES",
                        help=f"{what} on the buses the --fleet file names (all, or NAMES like left,right), each on "
                             "its own thread, instead of -p; every record names its bus.")


def unit_options(f):
    """``--unit counts|mm`` and ``--fleet FILE`` (the fleet file that gives each actuator's
    stroke, see :mod:`zkzap.api.units`): positions in counts (the default) or millimetres, and
    speeds in mm/s; tables show counts beside millimetres."""
    f = fleet_option(f)
    f = click.option("--unit", type=Choice(["counts", "mm"]), default="counts", show_default=True,
                     help="Positions in counts (0..4095; 0..10000 on the 17Lf) or millimetres (and speeds in "
                          "mm/s), by the strokes of --fleet.")(f)
    return f


def unit_scales(unit, fleet_file, ids):
    """``{ID: Scale}`` for ``--unit mm`` (None for counts); exit 2 without --fleet."""
    if unit != "mm":
        if fleet_file:                    # read all the same: a bad file is refused, not ignored
            from ..api.fleet import read_document

            read_document(fleet_file)
        return None
    if not fleet_file:
        raise UsageError("--unit mm: needs --fleet FILE (the fleet file giving each actuator's stroke)")
    from ..api.units import scales

    ctx = click.get_current_context(silent=True)
    modbus = ctx is not None and (ctx.params.get("protocol") == "modbus" or ctx.params.get("regmap") is not None)
    return scales(fleet_file, ids, zap_map(ctx) if modbus else None)


def resolve_format(fmt, stream=None, *, tty_default="table", pipe_default="jsonl"):
    from ..io.term import is_tty

    if fmt:
        return fmt
    return tty_default if is_tty(stream if stream is not None else sys.stdout) else pipe_default


def write_rows(rows, columns, fmt=None, *, title=None, table_columns=None, stream=None):
    """Write dict ``rows`` in ``fmt`` (default: a table on a terminal, JSON Lines otherwise)."""
    from ..io.writers import make_writer

    stream = stream if stream is not None else sys.stdout
    writer = make_writer(resolve_format(fmt, stream), stream, columns, title=title, table_columns=table_columns)
    try:
        for row in rows:
            writer.write(row)
    finally:
        writer.close()


class FilePath(click.ParamType):
    """A file path, completed as a file by the shell. The command opens it and reports a failure
    naming the option (click.Path's checks would run its message catalogue look-ups at start-up,
    on every command that merely has such an option)."""

    name = "file"

    def convert(self, value, param, ctx):
        return value if isinstance(value, str) else str(value)

    def shell_complete(self, ctx, param, incomplete):
        from click.shell_completion import CompletionItem

        return [CompletionItem(incomplete, type="file")]


class InputPath(FilePath):
    """A file a command reads (``-``: stdin). Declared as such so that the one same-file check
    (:func:`check_files`, run before every command) knows what no output may be; ``holds``
    says what it holds (``schedule``, ``fleet``, ``zk capture``, ``zap capture``, ``limits``,
    ``run``, ``steps``, ``summary``, ``logbook``, ``zk batch``, ``zap batch``, ``frames``: hex,
    raw bytes or a capture; ``sensors``: a sensors file, or a sensor's source); ``label`` names it in messages (default: the option, or the
    argument's name in capitals)."""

    def __init__(self, holds, label=None):
        self.holds = holds
        self.label = label


class OutputPath(FilePath):
    """A file a command writes, through :mod:`zkzap.outfile` (``-``: stdout where the command
    allows it). ``kind`` says how: ``records`` (streamed, opened by the first record),
    ``bytes`` (a raw log, opened by the first byte), ``capture`` (pcapng), ``document``
    (written whole, atomically), ``database`` (the SQLite logbook), ``state`` (read and
    rewritten whole: it is its own input), ``link`` (a symlink).

    ``formats``: the formats the file's suffix may name when ``-f`` is not given (None: the
    command fixes the format); ``default``: the format of a name without a suffix (None to
    refuse one); ``suffixes``: the file-name endings it takes (by default those of
    ``formats``, the default format's first). Before the command runs, :func:`check_files`
    refuses an unknown suffix (naming the known ones) and an output that is one of the
    command's inputs or another output (exit 2, nothing opened, no existing file touched)."""

    def __init__(self, kind="records", *, formats=None, default="jsonl", suffixes=None):
        self.kind = kind
        self.formats = tuple(formats) if formats else None
        self.default = default
        if suffixes is None and self.formats:
            suffixes = sorted(_suffixes(self.formats), key=lambda s: _suffix_format(s) != default)
        self.suffixes = tuple(suffixes) if suffixes else None     # the names it takes, when it decides the format

    def format_of(self, path, fmt=None):
        """The format for ``path``: ``fmt`` when given, else what its suffix names (a UsageError
        for a suffix that names none of ``formats``)."""
        from ..io import format_for_path

        if fmt or not self.formats:
            return fmt
        return format_for_path(path, self.formats, self.default, what="output")


def check_output_suffixes(cmd, params) -> None:
    """Refuse (UsageError) an :class:`OutputPath` value whose suffix names no format of ``cmd``
    while no ``-f`` was given; ``params`` are the parsed values (``ctx.params``)."""
    if params.get("fmt"):
        return
    for p in cmd.params:
        value = params.get(p.name)
        if isinstance(p.type, OutputPath) and value and value != "-":
            p.type.format_of(value)


def check_files(ctx) -> None:
    """Refuse (exit 2) a command whose ``-o`` suffix names no format it writes
    (:func:`check_output_suffixes`), whose output is one of its inputs, or two outputs that
    are one file: files are compared, not names (:func:`zkzap.outfile.refuse_same_files`).
    Runs for every command before its callback, from the types its options declare."""
    outputs, inputs = {}, {}
    for p in ctx.command.params:
        value = ctx.params.get(p.name) if p.expose_value else ctx.meta.get(f"zkzap.{p.name}")
        if not value or not isinstance(p.type, FilePath):
            continue
        label = getattr(p.type, "label", None) or (p.opts[-1] if isinstance(p, click.Option) else p.name.upper())
        if isinstance(p.type, OutputPath):
            outputs[label] = value
        elif isinstance(p.type, InputPath):
            inputs[label] = value
    if outputs and (inputs or len(outputs) > 1):
        from ..outfile import refuse_same_files

        refuse_same_files(outputs, inputs)     # first: "is also the input" says more than its suffix
    _refuse_port_outputs(ctx, outputs)
    check_output_suffixes(ctx.command, ctx.params)


#: The parameters that name a command's port(s).
_PORT_PARAMS = ("port", "ports")


def _refuse_port_outputs(ctx, outputs) -> None:
    """An output (``-o``, ``--raw-log``, ``--capture``, a MAVLink serial device, stdout) that
    is the command's own port is refused before anything opens (exit 2)."""
    ports = []
    for p in ctx.command.params:
        if p.name in _PORT_PARAMS:
            value = ctx.params.get(p.name)
            ports += [value] if isinstance(value, str) else list(value or ())
    if not any(isinstance(u, str) and "://" not in u or str(u).lower().startswith("spy://") for u in ports):
        return                                 # sim://, socket://: no device of this machine to write to
    outputs = dict(outputs)
    mavlink = (ctx.meta.get("zkzap.bridges") or {}).get("mavlink")
    if isinstance(mavlink, str) and mavlink.startswith(("/", "COM", "com")):
        outputs["--mavlink"] = mavlink.split(",", 1)[0]
    outputs.setdefault("stdout", "-")
    from ..outfile import refuse_port_outputs

    refuse_port_outputs(outputs, ports)


def output_options(f=None, *, formats=FORMATS):
    """``-o/--output`` (an :class:`OutputPath` of records in ``formats``) and ``--append``; as a
    decorator with or without ``formats``."""
    if f is None:
        return lambda g: output_options(g, formats=formats)
    f = click.option("--append", is_flag=True, help="Append to --output instead of replacing it.")(f)
    f = click.option("-o", "--output", type=OutputPath("records", formats=formats),
                     help="Write records to FILE instead of stdout, created by the first record (the "
                          "format by its suffix: " + ", ".join(_suffixes(formats)) + "; JSON Lines without one).")(f)
    return f


def _suffixes(formats):
    from ..io import SUFFIXES

    return [s for s, f in SUFFIXES.items() if f in formats]


def _suffix_format(suffix):
    from ..io import SUFFIXES

    return SUFFIXES.get(suffix)


def output_file(path, append=False, *, fmt=None, columns=None, inputs=None):
    """The checked :class:`~zkzap.outfile.OutFile` for ``-o PATH`` (None for stdout): refused
    (exit 2) when it is one of ``inputs`` (option -> paths), cannot be written, or cannot be
    appended to in ``fmt`` with ``columns``. Nothing is truncated until it is opened."""
    from ..outfile import OutFile, refuse_same_files

    if not path or path == "-":
        return None
    refuse_same_files({"--output": path}, inputs)
    return OutFile(path, append=append, fmt=fmt, columns=columns).check()


def decode_inputs(inputs, binary, explicit):
    """The files a decoder reads, for ``inputs=`` of :func:`output_file` (hex arguments: none)."""
    if explicit:
        return None
    if binary:
        return {"--binary": list(inputs) or ["-"]}
    return {"FILE" if inputs and list(inputs) != ["-"] else "stdin": list(inputs) or ["-"]}


def output_format(fmt, path, formats=FORMATS):
    """The format for ``-o PATH`` or stdout: given, else a table on a terminal, JSON Lines
    otherwise; a file's suffix names its format (:func:`zkzap.io.format_for_path`; a file is
    never a terminal)."""
    if fmt:
        return fmt
    if not path or path == "-":
        return resolve_format(None)
    from ..io import format_for_path

    return format_for_path(path, formats)


def open_output(path, append=False, *, fmt=None, columns=None, inputs=None):
    """(stream, had_content) for ``path`` ('-' or None: stdout), checked as :func:`output_file`
    checks it; ``had_content``: appending to existing records (no second header; a JSON array
    continued). A file is opened by the first record written to the stream
    (:class:`zkzap.outfile.LazyOutput`): a run that writes none leaves it as it was."""
    out = output_file(path, append, fmt=fmt, columns=columns, inputs=inputs)
    if out is None:
        return sys.stdout, False
    from ..outfile import LazyOutput

    return LazyOutput(out), out.had


def checked(check, frame, hint=""):
    """Run a codec check on one explicit frame: a CRC/checksum mismatch is a failed check
    (exit 1), a malformed frame is bad input (exit 2, ``hint`` appended). Returns what
    ``check`` returns."""
    from ..codec import zap, zk
    from ..errors import CheckFailed

    try:
        return check(frame)
    except (zk.CrcError, zap.ChecksumError) as e:
        raise CheckFailed(str(e)) from None
    except (zk.FrameError, zap.PacketError) as e:
        raise UsageError(f"{e}{hint}") from None


def close_output(writer, stream) -> None:
    """Close ``writer`` and, unless it is stdout, the stream ``open_output`` gave."""
    try:
        writer.close()
    finally:
        if stream is not sys.stdout:
            stream.close()


def plural(n: int, word: str, words=None) -> str:
    """``1 frame``, ``2 frames``, ``0 bytes``."""
    return f"{n} {word if n == 1 else (words or word + 's')}"


def note_skipped(framer, what: str, check: str) -> None:
    """Say on stderr what a decoding stream skipped, when it skipped anything (``what``: the
    singular noun, ``frame`` or ``packet``): frames of the kind --accept leaves out and a frame
    cut short by the end are counted apart from the frames that failed their check."""
    if not (framer.bad or framer.skipped):
        return
    parts = []
    filtered = getattr(framer, "filtered", 0)
    if filtered:
        kind = "control" if framer.accept == "status" else "status"
        parts.append(f"{plural(filtered, kind + ' frame')} left out (--accept {framer.accept})")
    parts.append(f"{framer.bad} bad ({check})")
    truncated = getattr(framer, "truncated", 0)
    if truncated:
        parts.append(f"{truncated} cut short by the end of the input")
    note(f"{plural(framer.frames, what)} decoded; {', '.join(parts)}; {plural(framer.skipped, 'byte')} skipped")


def end_decode(framer, chunks, what: str, check: str) -> None:
    """The notes a decoding stream ends with: what it skipped (:func:`note_skipped`) and what
    the hex input held besides frames."""
    from ..io.sources import hex_note

    note_skipped(framer, what, check)
    text = hex_note(chunks)
    if text:
        note(text)


dry_run_option = click.option(
    "-n", "--dry-run", is_flag=True,
    help="Compose and print the frame as hex; open no port, send nothing.")

yes_option = click.option(
    "-y", "--yes", is_flag=True,
    help="Consent to a command that can start the engine, pump fuel or fire the igniter; without "
         "it a terminal prompts and a script is refused (sim:// and --sim never ask).")

zap_yes_option = click.option(
    "-y", "--yes", is_flag=True,
    help="Consent to writing stored settings (they survive power-off and wear the actuator's "
         "memory), an ID or baud change, or a factory reset on a real port; without it a terminal "
         "prompts and a script is refused (sim://, loop:// and --sim never ask).")

#: ``--force`` on the mightyZAP commands that compose packets: the FORCE permissions of
#: :mod:`zkzap.codec.permissions` (``--yes`` is the consent on a real port; this is needed on
#: the simulator too).
FORCE_HELP = ("Allow deliberate writes that --yes does not cover, simulator included: the id, baud-rate "
              "or protocol-type register (set-id and set-baud check and verify instead), a write after "
              "which the actuator stops answering (feedback-return-mode 0), a factory reset of the ID or "
              "baud rate, addresses and values the 12Lf map does not document, a write to part of a "
              "multi-byte register, and such writes to every actuator (broadcast).")

force_option = click.option("--force", is_flag=True, help=FORCE_HELP)

zap_move_yes_option = click.option(
    "-y", "--yes", is_flag=True,
    help="Consent to moving the rods (a full stroke each, then back to where they were) on a real "
         "port; without it a terminal prompts and a script is refused (--no-move checks without "
         "moving; sim://, loop:// and --sim never ask).")

protocol_version_option = click.option(
    "--protocol-version", type=IntRange(1, 63), default=None, metavar="N",
    help="ECU protocol version assumed until a status ID 6 frame reveals it "
         "(sets the voltage unit: 0.1 V up to 3, 0.2 V from 4; default 4).")


def apply_options(f, options):
    """Apply option decorators listed in help order to a function or to a click Command (a
    Command lists its options in the order they are added; a function's decorators apply in
    reverse)."""
    for opt in (options if isinstance(f, click.Command) else reversed(options)):
        f = opt(f)
    return f


class BaudType(click.ParamType):
    """A baud rate 300..4000000; with ``auto`` allowed, also the word ``auto`` (detect it)."""

    name = "integer"

    def __init__(self, auto=False):
        self.auto = auto

    def convert(self, value, param, ctx):
        if isinstance(value, int) and not isinstance(value, bool):
            number = value
        else:
            text = str(value).strip().lower()
            if text == "auto" and self.auto:
                return "auto"
            try:
                number = int(text)
            except ValueError:
                number = None
        if number is None or not 300 <= number <= 4_000_000:
            allowed = "300..4000000" + (" or auto" if self.auto else "")
            self.fail(f"{value!r} is not allowed; allowed {allowed}"
                      + ("" if self.auto or str(value).strip().lower() != "auto"
                         else " (auto: only 'zk monitor', 'zk check' and 'zk detect' find the baud rate)"), param, ctx)
        return number

    def shell_complete(self, ctx, param, incomplete):
        from click.shell_completion import CompletionItem

        bauds = ["2400", "4800", "9600", "19200", "38400", "57600", "115200"] + (["auto"] if self.auto else [])
        return [CompletionItem(b) for b in bauds if b.startswith(incomplete)]


class BaudList(click.ParamType):
    """A list of baud rates from ``allowed`` (``57600,115200``), or ``all`` (``allowed`` in its
    order). ``label`` names the option in messages, ``what`` says what a rate must be,
    ``listed`` is the order the allowed rates are named in, ``example`` a valid list."""

    name = "bauds"

    def __init__(self, allowed, *, label, what, example, listed=None):
        self.allowed = tuple(allowed)
        self.label, self.what, self.example = label, what, example
        self.listed = tuple(listed) if listed is not None else self.allowed

    def shell_complete(self, ctx, param, incomplete):
        from .complete import bauds

        return bauds(self.allowed)(ctx, param, incomplete)

    def convert(self, value, param, ctx):
        if isinstance(value, (list, tuple)):
            return list(value)
        if isinstance(value, int):
            return [value]
        text = str(value).strip().lower()
        if text == "all":
            return list(self.allowed)
        out = []
        for part in text.replace(" ", ",").split(","):
            if not part:
                continue
            try:
                b = int(part)
            except ValueError:
                b = None
            if b not in self.allowed:
                raise UsageError(f"{self.label}: {part!r} is not {self.what}; allowed "
                                 f"{', '.join(str(v) for v in self.listed)} or all")
            if b not in out:
                out.append(b)
        if not out:
            raise UsageError(f"{self.label}: none given; allowed a list like {self.example} or all")
        return out


PORTS_META = "zkzap.ports"


def _several_ports(ctx, param, value):
    """``-p`` given more than once: every port kept for :func:`ports_given`; the command's
    ``port`` is the first (one bus), or None."""
    ports = [v for v in (value or ()) if v]
    ctx.meta.pop(PORTS_META, None)
    if len(ports) > 1:
        twice = sorted({p for p in ports if ports.count(p) > 1})
        if twice:
            raise UsageError(f"-p/--port: {twice[0]} is given twice")
        ctx.meta[PORTS_META] = ports
    return ports[0] if ports else None


class _PortsOption(click.Option):
    """A ``-p`` that may be given again: one port from a default (a batch's or shell's port,
    which every line shares whether its command takes one bus or several) is that one port."""

    def value_from_envvar(self, ctx):
        # the environment names one port, spaces and all (click would split it at whitespace)
        return self.resolve_envvar_value(ctx)

    def type_cast_value(self, ctx, value):
        if isinstance(value, str):
            value = (value,)
        return super().type_cast_value(ctx, value)


def ports_given():
    """The ports of a ``-p`` given more than once (several buses), or None (one port or none)."""
    ctx = click.get_current_context(silent=True)
    return ctx.meta.get(PORTS_META) if ctx is not None else None


def port_options(group: str, *, baud_auto: bool = False, several: bool = False):
    """``-p/--port``, ``-b/--baud``, ``--stop-bits``, ``--timeout`` and ``--sim`` for a protocol
    group; ``baud_auto``: ``-b auto`` detects the line settings first; ``several``: ``-p`` may
    be given again for several buses at once (:func:`ports_given`)."""
    env = ENV[group]
    options = [
        click.option("-p", "--port", envvar=env["port"], metavar="PORT", default=None, multiple=several,
                     cls=_PortsOption if several else click.Option, callback=_several_ports if several else None,
                     shell_complete=lambda ctx, param, incomplete: _complete_ports(ctx, param, incomplete, group),
                     help=f"Serial device or pyserial URL (socket://host:port, rfc2217://, "
                          f"loop://, spy://, hwgrep://) [env {env['port']}]."
                          + (" Again for several buses at once, each on its own thread (records name their "
                             "bus by its port)." if several else "")),
        click.option("-b", "--baud", type=BaudType(baud_auto), envvar=env["baud"],
                     default=DEFAULT_BAUD[group], show_default=True,
                     help=(f"Baud rate, or auto to detect it (and the stop bits) first [env {env['baud']}]."
                           if baud_auto else f"Baud rate [env {env['baud']}].")),
        click.option("--stop-bits", "stop_bits", type=Choice(["1", "2"]), envvar=env["stop_bits"],
                     default="1", show_default=True, callback=lambda ctx, param, v: int(v),
                     help=f"{STOP_BITS_HELP[group]} [env {env['stop_bits']}]."),
        click.option("--timeout", type=FiniteRange(0.001, 3600), default=None, metavar="SECONDS",
                     help="Reply timeout (default: derived from the baud rate)."),
        click.option("--sim", is_flag=True, help="Talk to the built-in simulator instead of a port."),
        capture_option(group),
    ]
    return lambda f: apply_options(f, options)


#: The port hints said in this run (:func:`warn_port`); :func:`zkzap.commands.run` empties it.
_SAID_PORTS: set = set()


def warn_port(url) -> None:
    """Say on stderr when a port name is wrong for an outgoing connection (macOS /dev/tty.*):
    once per run, however often the command (a batch's every line, a shell's every command)
    checks the port."""
    from .. import checking
    from ..link.adapters import outgoing_port_hint

    if checking.active() is not None:
        return                             # a batch's check of its lines: what it says is not shown
    hint = outgoing_port_hint(url)
    if hint and hint not in _SAID_PORTS:
        _SAID_PORTS.add(hint)
        warn(hint)


def capture_option(protocol: str):
    """``--capture FILE``: record every chunk read from and written to the port, timestamped, in
    pcapng (the port's link type: 147 for ZK, 148 for mightyZAP). Not a parameter of the command:
    :func:`zkzap.link.port.open_port` taps whatever port the command opens."""

    def callback(ctx, param, value):
        if ctx.resilient_parsing:
            return
        ctx.meta["zkzap.capture"] = value             # for check_files: an output like the others
        if not value and "zkzap.link.capture" not in sys.modules:
            return                        # nothing asked, nothing to reset: import nothing
        from ..link import capture

        if not value and capture.kept():
            return                        # a batch's line: the batch's capture goes on
        capture.request(value, protocol)
        if value:
            ctx.call_on_close(lambda: capture.request(None, protocol))   # close it, ask for no more

    return click.option("--capture", type=OutputPath("capture"), default=None, metavar="FILE", expose_value=False,
                        callback=callback,
                        help="Record every byte read and written, timestamped with its direction, in "
                             "FILE (pcapng; Wireshark opens it with zkzap's dissector).")


def _complete_ports(ctx, param, incomplete, group=None):
    """The serial ports present, the URL schemes, and the group's built-in simulator."""
    from click.shell_completion import CompletionItem

    try:
        from serial.tools import list_ports
    except ImportError:  # pragma: no cover
        return []
    items = [CompletionItem(p.device, help=p.description) for p in list_ports.comports()]
    items += [CompletionItem(u) for u in ("socket://", "rfc2217://", "loop://", "spy://", "hwgrep://")]
    if group is not None:
        items.append(CompletionItem(f"sim://{group}", help="the built-in simulator"))
    return [i for i in items if i.value.startswith(incomplete)]


#: The most bytes a command that takes hex whole (zkzap crc) reads from stdin.
MAX_HEX_INPUT = 16 << 20


def read_hex_input(args, *, what="hex input") -> bytes:
    """Hex bytes from the arguments (joined), or from stdin when there are none or one is ``-``."""
    from ..codec.hexfmt import parse_hex

    if not args or list(args) == ["-"]:
        if sys.stdin is None or (sys.stdin.isatty() and not args):
            raise UsageError(f"{what}: none given; pass hex bytes as arguments or on stdin")
        from ..io.sources import HexText

        parts, size = [], 0
        for block in HexText(strict=True):
            parts.append(block)
            size += len(block)
            if size > MAX_HEX_INPUT:
                raise UsageError(f"stdin: more than {MAX_HEX_INPUT >> 20} MiB of bytes; give a frame or a "
                                 "capture's bytes (zk decode, zap decode) instead")
        return b"".join(parts)
    return parse_hex(" ".join(a for a in args), what=what)


def consent(action: str, yes: bool, brief=None) -> None:
    """Ask before something hazardous. ``--yes`` consents; a terminal prompts; anything else
    (a script, CI, no stdin) is refused with exit status 2 and nothing is sent. While a batch
    checks its lines (:mod:`zkzap.checking`) the consent is recorded (``brief``, else
    ``action``) for the batch's one prompt."""
    from .. import checking

    if checking.consent(brief or action) or yes:
        return
    from ..io.term import is_tty

    if is_tty(sys.stdin) and is_tty(sys.stderr):
        if _ask(f"{action}. Continue? [y/N]: "):
            return
        raise UsageError("not sent: consent refused")
    raise UsageError(f"not sent: {action}; pass --yes to confirm")


def _ask(question: str) -> bool:
    """A yes/no question on the terminal; the end of input (Ctrl-D) is a refusal (exit 2), Ctrl-C
    an interruption (130), as everywhere."""
    while True:
        click.echo(question, nl=False, err=True)
        line = sys.stdin.readline()
        if not line:
            click.echo("", err=True)
            raise UsageError("not sent: no answer (end of input)")
        answer = line.strip().lower()
        if answer in ("y", "yes"):
            return True
        if answer in ("", "n", "no"):
            return False
        click.echo("Answer y or n.", err=True)


def authorize(needs, *, what: str, yes: bool, force: bool, simulated: bool, consent_text=None, brief=None):
    """The command line's side of the permission policy (:mod:`zkzap.codec.permissions`): the
    permissions to give a command whose frames need ``needs`` — typed frames
    (:class:`zkzap.codec.zap.Command`, :class:`zkzap.codec.zk.ControlFrame`), or a
    ``{Permission: reason}`` of a procedure.

    The FORCE permissions need ``--force`` (without it: PermissionNeeded naming the frame, exit
    2, nothing sent); the CONSENT ones, on a real port, ``--yes`` or a yes at a prompt
    (:func:`consent`, with ``consent_text`` or ``what`` and the reasons). Everything is decided
    here, before the port opens; the bus or link then enforces the same rules on every frame."""
    from ..codec.permissions import CONSENT, FORCE, Permission, require

    granted = FORCE if force else Permission.NONE
    if isinstance(needs, dict):
        require({p: why for p, why in needs.items() if p & FORCE}, granted, what=what)
    else:
        frames, needs = list(needs), {}
        for f in frames:
            own = f.needs()
            require({p: why for p, why in own.items() if p & FORCE}, granted,
                    what=f.describe() if hasattr(f, "describe") else what, frame=getattr(f, "packet", None) or f.frame)
            for p, why in own.items():
                needs.setdefault(p, why)
    wanted = {p: why for p, why in needs.items() if p & CONSENT}
    if wanted and not simulated:
        reasons = "; ".join(dict.fromkeys(wanted.values()))
        consent(consent_text or f"{what}: {reasons}", yes, brief=brief or reasons)
    for p in wanted:
        granted |= p
    return granted
