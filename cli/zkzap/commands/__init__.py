"""The command-line application: a root group whose sub-commands are imported only when used.

``zkzap`` is the root (``zkzap zk ...``, ``zkzap zap ...``, ``zkzap crc ...``, ``zkzap sim ...``);
``zk`` and ``zap`` are direct entry points to those two groups. Every command module is thin:
it parses options (``options.py``) and calls the codec, link, simulator and io layers.
"""

from __future__ import annotations

import os
import sys

import click

from .. import __version__
from .. import signals as _signals
from ..errors import EXIT_CODES, INTERRUPTED, ZkzapError, exit_status_help

EXIT_EPILOG = exit_status_help()


HELP_TEXT = "Show this message and exit."


def _show_help(ctx, param, value):
    if value and not ctx.resilient_parsing:
        click.echo(ctx.get_help(), color=ctx.color)
        ctx.exit()


class QuickHelp:
    """A ``-h/--help`` option built without a message-catalogue look-up.

    click builds each command's help option with ``gettext``, whose first call imports
    :mod:`locale` and compiles its regular expressions: about 1 ms on every run of a command
    that shell scripts call in loops and that every TAB runs. The option is the same otherwise.
    """

    def get_help_option(self, ctx):
        names = self.get_help_option_names(ctx)
        if not names or not self.add_help_option:
            return None
        option = self.__dict__.get("_quick_help")
        if option is None:
            # created once: click orders eager callbacks by object identity
            option = self._quick_help = click.Option(
                [*names, "_zkzap_help"], is_flag=True, expose_value=False, is_eager=True,
                help=HELP_TEXT, callback=_show_help)
        return option


class Command(QuickHelp, click.Command):
    """Every zkzap command: click's, with the quick help option, and a lone short option
    (``-n``) handed to click in its long spelling (``--dry-run``): click tries every single-dash
    token as a long option first, and the failed try (an exception and a message-catalogue
    look-up) costs the start-up of a command that shell scripts call in loops.

    With ``negative_numbers`` set, a token that looks like a negative number, is no option of
    the command and is not an option's value goes behind ``--`` (keeping the arguments' order).
    """

    negative_numbers = False

    def parse_args(self, ctx, args):
        if "--" not in args:
            opts = {o: p for p in self.get_params(ctx) if isinstance(p, click.Option)
                    for o in p.opts + p.secondary_opts}
            head, tail, prev = [], [], None
            for a in args:
                takes_value = prev in opts and not opts[prev].is_flag and not opts[prev].count
                if self.negative_numbers and _is_negative_number(a) and a not in opts and not takes_value:
                    tail.append(a)
                elif not takes_value and len(a) == 2 and a in opts and _long(opts[a]):
                    head.append(_long(opts[a]))
                else:
                    head.append(a)
                prev = a
            args = head + ["--"] + tail if tail else head
        return super().parse_args(ctx, args)

    def invoke(self, ctx):
        if not ctx.resilient_parsing and _has_files(self):
            from .options import check_files

            check_files(ctx)      # -o run.xlsx where .xlsx means nothing, an output that is an input: exit 2
            from ..io.term import input_progress

            with input_progress():    # a bar on a terminal's stderr while a large input file is read
                return super().invoke(ctx)
        return super().invoke(ctx)

    def format_epilog(self, ctx, formatter):
        """The epilog, then the command's exit statuses (:func:`zkzap.commands.options.exit_help`)."""
        import inspect

        from .options import exit_help

        text = " ".join(p for p in (inspect.cleandoc(self.epilog or ""), exit_help(self)) if p)
        formatter.write_paragraph()
        with formatter.indentation():
            formatter.write_text(text)


def _has_files(cmd) -> bool:
    """Whether ``cmd`` declares file options (cached on the command: a dry run pays one look-up)."""
    has = cmd.__dict__.get("_zkzap_files")
    if has is None:
        has = cmd._zkzap_files = any(getattr(p.type, "name", None) == "file" for p in cmd.params)
    return has


def _long(option):
    return next((o for o in option.opts if o.startswith("--")), None)


def _is_negative_number(token: str) -> bool:
    if token[1:].lower() in ("inf", "infinity", "nan"):
        return True                 # refused by the value's own (finite) type, naming it
    if len(token) < 2 or token[0] != "-" or not (token[1].isdigit() or token[1] == "."):
        return False
    try:
        float(token) if not token[1:].lower().startswith("0x") else int(token, 16)
    except ValueError:
        return False
    return True


class Group(QuickHelp, click.Group):
    """Every zkzap group: click's, with the quick help option for itself and its commands, and
    the closest command names when one is misspelt ("No such command 'sned'; did you mean
    send?")."""

    command_class = Command

    def resolve_command(self, ctx, args):
        try:
            return super().resolve_command(ctx, args)
        except click.UsageError as e:
            name = args[0] if args else ""
            if name and not name.startswith("-") and self.get_command(ctx, name) is None:
                from ..errors import did_you_mean

                e.message = e.message.rstrip(".") + did_you_mean(name, self.list_commands(ctx))
            raise


class LazyGroup(Group):
    """A group whose sub-commands live in modules imported on first use.

    ``lazy`` maps a command name to ``("module", "attribute", "short help")``; the short help
    is kept here so that ``--help`` lists every command without importing any of them.
    """

    def __init__(self, *args, lazy=None, **kwargs):
        super().__init__(*args, **kwargs)
        self.lazy = dict(lazy or {})

    def list_commands(self, ctx):
        return sorted(set(super().list_commands(ctx)) | set(self.lazy))

    def get_command(self, ctx, name):
        if name in self.commands:
            return self.commands[name]
        spec = self.lazy.get(name)
        if spec is None:
            return None
        import importlib

        cmd = getattr(importlib.import_module(spec[0], __package__), spec[1])
        self.commands[name] = cmd
        return cmd

    def make_context(self, info_name, args, parent=None, **extra):
        if parent is None and "terminal_width" not in extra:
            # what click would compute, without importing shutil (and bz2, lzma) at every --help
            extra["terminal_width"] = _help_width(self.context_settings.get("max_content_width") or 80)
        return super().make_context(info_name, args, parent=parent, **extra)

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as e:
            # Ctrl-C or SIGTERM: past click, which would print a blank line and say "Aborted!"
            raise Stopped(_signals.exit_status(e)) from None
        except BrokenPipeError:
            # Raised past click (which would exit 1): the reader of stdout went away.
            if _stdout_closed():
                raise PipeClosed() from None
            raise

    def format_commands(self, ctx, formatter):
        rows = []
        width = formatter.width or 80
        for name in self.list_commands(ctx):
            if name in self.commands:
                cmd = self.commands[name]
                if cmd.hidden:
                    continue
                text = cmd.get_short_help_str(limit=width - 6 - len(name))
            else:
                text = self.lazy[name][2]
            rows.append((name, text))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


def _debug_callback(ctx, param, value):
    if value:
        os.environ["ZKZAP_DEBUG"] = "1"
    return value


def version_option(prog: str):
    """``-V/--version``: print ``PROG (zkzap) VERSION`` and exit. (click.version_option would look
    up its message catalogue at import, on every start.)"""
    text = f"{prog} {__version__}" if prog == "zkzap" else f"{prog} (zkzap) {__version__}"

    def callback(ctx, param, value):
        if value and not ctx.resilient_parsing:
            click.echo(text)
            ctx.exit()

    return click.option("-V", "--version", is_flag=True, expose_value=False, is_eager=True, callback=callback,
                        help="Show the version and exit.")


debug_option = click.option(
    "--debug", is_flag=True, expose_value=False, is_eager=True, callback=_debug_callback,
    help="Show Python tracebacks on errors (also ZKZAP_DEBUG=1).")

CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}

ZK_COMMANDS = {
    "send": (".zk.send", "send", "Compose a control command and send it (or print it with -n)."),
    "decode": (".zk.decode", "decode", "Decode ZK frames from hex or a binary capture."),
    "monitor": (".zk.monitor", "monitor", "Show or log the ECU's status frames as they arrive."),
    "profile": (".zk.profile", "profile", "Run a throttle schedule on the engine and log telemetry."),
    "check": (".zk.check", "check", "Pre-flight check: watch the ECU, test limits, give a verdict."),
    "report": (".zk.report", "report", "Render a run's CSV (or raw log) as a report with plots."),
    "logbook": (".zk.logbook", "logbook", "List the runs in an engine logbook, with totals."),
    "sensor": (".zk.sensor", "sensor", "An external sensor of the stand: read, tare, calibrate."),
    "states": (".zk.tables", "states", "List the engine states (appendix table)."),
    "errors": (".zk.tables", "errors", "List the engine error codes (appendix table)."),
    "fields": (".zk.tables", "fields", "List every control and status field with bits, unit and range."),
    "detect": (".zk.detect", "detect", "Find the ECU's baud rate and stop bits by listening."),
    "batch": (".zk.batch", "batch", "Run many zk commands over one open port (JSON Lines)."),
}
ZAP_COMMANDS = {
    "echo": (".zap.compose", "echo", "Echo: check that an actuator answers."),
    "load": (".zap.compose", "load", "Load Data: read a register."),
    "store": (".zap.compose", "store", "Store Data: write a register."),
    "send": (".zap.compose", "send_data", "Send Data: stage a write, applied by execute."),
    "execute": (".zap.compose", "execute", "Execution: apply staged writes."),
    "factory-reset": (".zap.compose", "factory_reset", "Factory Reset: restore factory settings."),
    "restart": (".zap.compose", "restart", "Restart the actuator."),
    "sync-move": (".zap.compose", "sync_move", "Symmetric Store: move several actuators at once."),
    "raw": (".zap.compose", "raw", "Send any instruction with hex parameters."),
    "decode": (".zap.decode", "decode", "Decode mightyZAP packets from hex or a binary capture."),
    "scan": (".zap.scan", "scan", "Find every actuator on the bus (IDs and baud rates)."),
    "detect": (".zap.scan", "detect", "Say which protocol (IR or Modbus) and baud rate the bus speaks."),
    "dump": (".zap.scan", "dump", "Read back the whole register map of one actuator."),
    "move": (".zap.scan", "move", "Move to a position, optionally waiting until it stops."),
    "set-id": (".zap.scan", "set_id", "Give an actuator a new ID, verified by read-back."),
    "set-baud": (".zap.scan", "set_baud", "Change an actuator's baud rate, verified."),
    "registers": (".zap.tables", "registers", "List the register map (12Lf)."),
    "backup": (".zap.fleet", "backup", "Back up every register of every actuator to a file."),
    "diff": (".zap.fleet", "diff", "Compare two fleets: backup files or the live bus."),
    "apply": (".zap.fleet", "apply", "Make the bus match a backup, skipping writes that change nothing."),
    "setup": (".zap.fleet", "setup", "Guided ID setup, one actuator at a time, resumable."),
    "watch": (".zap.watch", "watch", "Poll registers of several actuators live, or log them."),
    "check": (".zap.check", "check", "Self-check actuators: echo, voltage, errors, a full-stroke move."),
    "batch": (".zap.batch", "batch", "Run many zap commands over one open port (JSON Lines)."),
    "play": (".zap.motion", "play", "Play a timed path of goal positions on several actuators."),
    "teach": (".zap.motion", "teach", "Record present positions as waypoints, for zap play."),
    "calibrate": (".zap.motion", "calibrate", "Teach the two ends of the stroke, for millimetres."),
    "cycle": (".zap.cycle", "cycle", "Endurance cycles of one actuator, measured, resumable, with a report."),
}
ROOT_COMMANDS = {
    "zk": (".zk", "zk", "ZK turbine ECU: send, monitor, profile, decode."),
    "zap": (".zap", "zap", "mightyZAP actuators: scan, move, load, store, decode."),
    "crc": (".crc", "crc", "Compute or check CRCs and checksums of both protocols."),
    "sim": (".sim", "sim", "Run the built-in ECU or actuator-bus simulator."),
    "sniff": (".sniff", "sniff", "Watch a live ZK or mightyZAP link passively (never transmits)."),
    "shell": (".shell", "shell", "An interactive zap or zk session over one open port."),
    "web": (".web", "web", "A browser console for the actuator bus or the engine (extra 'web')."),
    "ports": (".ports", "ports", "List serial ports, with adapter hints."),
    "completion": (".completion", "completion", "Print the shell completion script."),
}


@click.group(cls=LazyGroup, lazy=ROOT_COMMANDS, context_settings=CONTEXT, epilog=EXIT_EPILOG)
@version_option("zkzap")
@debug_option
def root():
    """zkzap: the ZK turbine ECU protocol and mightyZAP actuators from the command line.

    Data goes to stdout, messages to stderr. Ports are device paths or pyserial URLs
    (socket://, rfc2217://, loop://, spy://, hwgrep://); every command that talks to a device
    also runs against the built-in simulators (--sim, or 'zkzap sim').
    """


def _help_width(max_width):
    from click import formatting

    if formatting.FORCED_WIDTH is not None:     # click's test runner fixes the width
        return None
    try:
        columns = int(os.environ.get("COLUMNS", ""))
    except ValueError:
        columns = 0
    if columns <= 0:
        try:
            columns = os.get_terminal_size(sys.__stdout__.fileno()).columns
        except (AttributeError, ValueError, OSError):
            columns = 80
    return max(min(columns, max_width) - 2, 50)


class Stopped(Exception):
    """Ctrl-C (code 130) or SIGTERM (143) ended the command."""

    def __init__(self, code):
        super().__init__(code)
        self.code = code


class PipeClosed(Exception):
    """stdout's reader went away (``zkzap ... | head``): end quietly."""


def _stdout_closed() -> bool:
    """Whether stdout is a pipe or socket whose reading end is closed."""
    try:
        import select

        p = select.poll()
        p.register(sys.stdout.fileno(), select.POLLOUT)
        return any(ev & select.POLLERR for _, ev in p.poll(0))
    except (AttributeError, ValueError, OSError):
        return True


#: The longest error message printed whole (characters); a longer one (it quotes a line of
#: some input at length) keeps its start and its end.
MAX_MESSAGE = 1000


#: Control characters a message may quote from an input, shown escaped (a crafted file must not
#: move the cursor or colour the terminal through an error message).
_CONTROLS = {c: f"\\x{c:02x}" for c in (*range(0x20), 0x7f, *range(0x80, 0xa0)) if c not in (9, 10, 13)}
_CONTROLS.update({0x2028: "\\u2028", 0x2029: "\\u2029"})


def one_line(message: str) -> str:
    """``message`` as one line of reasonable length: line breaks (a database's or a library's
    text) become spaces, other control characters are escaped, and the middle of an over-long
    message is cut."""
    if "\n" in message or "\r" in message:
        import re

        message = re.sub(r"\s*[\r\n]+\s*", " ", message).strip()
    if not message.isprintable():
        message = message.translate(_CONTROLS)
    if len(message) > MAX_MESSAGE:
        message = message[:MAX_MESSAGE * 2 // 3] + " [...] " + message[-MAX_MESSAGE // 4:]
    return message


def _error(message: str, prog: str = "zkzap") -> None:
    from ..io.term import color_enabled, style

    click.echo(f"{prog}: {style('error:', sys.stderr, fg='red', bold=True)} {one_line(message)}", err=True,
               color=color_enabled(sys.stderr))


#: Runs in progress: a shell's commands run inside the shell's own run.
_RUNS = 0


def run(cmd, prog_name=None, args=None, **extra) -> int:
    """Run a click command with zkzap's error conventions; returns the exit status. ``extra``
    goes to the command's context (``default_map``)."""
    global _RUNS
    debug = bool(os.environ.get("ZKZAP_DEBUG")) or "--debug" in (args if args is not None else sys.argv[1:])
    said = getattr(sys.modules.get(__name__ + ".options"), "_SAID_PORTS", None)
    if said and not _RUNS:
        said.clear()                       # a new run says its port hints again (not a shell's command)
    _RUNS += 1
    try:
        _signals.running()
        rv = cmd.main(args=args, prog_name=prog_name, standalone_mode=False, **extra)
        return rv if isinstance(rv, int) else 0
    except click.exceptions.Exit as e:
        return e.exit_code
    except _NO_ARGS_IS_HELP as e:
        e.show()                                   # a bare group: its help
        return e.exit_code
    except click.ClickException as e:
        # one line like every other error: "zk: error: <what> (see 'zk send control --help')"
        message = " ".join(e.format_message().split())
        ctx = getattr(e, "ctx", None)
        if isinstance(e, click.UsageError) and ctx is not None:
            message = message.rstrip(".") + f" (see '{ctx.command_path} --help')"
        _error(message, prog_name or "zkzap")
        return e.exit_code
    except Stopped as e:
        return _interrupted(e.code)
    except click.exceptions.Abort:
        return INTERRUPTED                 # click already ended the ^C line
    except KeyboardInterrupt as e:
        return _interrupted(_signals.exit_status(e))
    except (BrokenPipeError, PipeClosed):
        _quiet_stdout()
        return 0
    except ZkzapError as e:
        if debug:
            raise
        from .hints import with_hint

        _error(with_hint(e), prog_name or "zkzap")
        return e.code
    except OSError as e:
        if not debug and _terminal_gone(e):
            # the terminal hung up (its SIGHUP ended the session, whose abort went out first):
            # nothing can be said on it any more
            _quiet_stdout()
            from ..errors import OUTPUT_ERROR

            first = _signals.first()
            return _signals.status(first) if first is not None else OUTPUT_ERROR
        # stdout on a full disk (> /dev/full): a dry run, a table, --help, a completion script
        if debug or not _output_full(e):
            raise
        return _output_failed(e, prog_name)
    finally:
        _RUNS -= 1


def _interrupted(code) -> int:
    """Ctrl-C (130) or SIGTERM (143): end quietly; after ^C, end the terminal's line."""
    if code == INTERRUPTED:
        try:
            click.echo("", err=True)
        except (OSError, ValueError):
            pass
    return code


#: click >= 8.2 raises this for a bare group (it shows the group's help); 8.1 exits 0 instead.
_NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", ())


def _quiet_stdout():
    """After EPIPE: point stdout at /dev/null so the interpreter's final flush is silent."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def _terminal_gone(e) -> bool:
    """A write to a terminal that hung up (EIO): the terminal closed, ssh dropped."""
    import errno

    return e.errno == errno.EIO


def _output_full(e) -> bool:
    """The output cannot take more: disk full, quota exceeded, file too large."""
    import errno

    return e.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def _output_failed(e, prog_name=None) -> int:
    """stdout (or a file the error names) could not be written: one line, exit 7. What could
    not be written is dropped so the interpreter's own final flush stays quiet."""
    from ..errors import OUTPUT_ERROR

    name = e.filename if isinstance(getattr(e, "filename", None), str) else "stdout"
    _quiet_stdout()
    _error(f"output: cannot write {name}: {e.strerror or e}", prog_name or "zkzap")
    return OUTPUT_ERROR


def _exit(code, prog_name=None):
    offload = sys.modules.get("zkzap.offload")
    if offload is not None and offload.abandoned():
        # an output still blocked (a pipe nobody reads): its stream holds the lock of a write
        # that may never end, and the interpreter's final flush would wait on it for ever
        try:
            sys.stderr.flush()
        finally:
            os._exit(code if isinstance(code, int) else 1)
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        _quiet_stdout()
    except OSError as e:
        if code in (0, None) and _output_full(e):
            code = _output_failed(e, prog_name)
        else:
            _quiet_stdout()
    except ValueError:
        pass
    sys.exit(code)


def _start(cmd, prog):
    """Run ``cmd`` as the process's program and exit with its status.

    The objects imported so far (click's and zkzap's modules, classes, tables) live until the
    process ends. ``gc.freeze()`` moves them out of the cyclic collector's sight, so neither the
    collections during the run nor the ones the interpreter makes at exit traverse them: about
    4 ms of a 55 ms dry-run. Objects the command creates afterwards are collected as usual.
    """
    import gc

    _signals.running()
    gc.freeze()
    _exit(run(cmd, prog), prog)


def main():
    _start(root, "zkzap")


def zk_main():
    from .zk import zk

    _start(zk, "zk")


def zap_main():
    from .zap import zap

    _start(zap, "zap")
