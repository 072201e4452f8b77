"""Options and helpers shared by every command module (one definition each).

Nothing here imports rich or pyserial: both are loaded by the functions that need them.
"""

from __future__ import annotations

import os
import sys

import click

from ..errors import UsageError
from ..io import FORMATS
from . import Command

#: Environment variables giving defaults, one pair per protocol group.
ENV = {
    "zk": {"port": "ZKZAP_ZK_PORT", "baud": "ZKZAP_ZK_BAUD"},
    "zap": {"port": "ZKZAP_ZAP_PORT", "baud": "ZKZAP_ZAP_BAUD"},
}
#: Default baud rates: the mightyZAP factory default is 57600 (code 32); the ZK document lists
#: 2400..115200 as configurable without a default, and 115200 is the common ECU setting.
DEFAULT_BAUD = {"zk": 115200, "zap": 57600}


class SignedCommand(Command):
    """A command whose positional arguments may be negative numbers (``ignition-voltage -0.5``).

    click would read ``-0.5`` as an unknown option and never name the field: a token that looks
    like a negative number, is no option of this command and is not an option's value is moved
    behind ``--`` (keeping the arguments' order), so the field's own range check reports it.
    """

    negative_numbers = True


def note(message: str) -> None:
    """A message for the person (stderr), never mixed with data."""
    click.echo(f"note: {message}", err=True)


def warn(message: str) -> None:
    from ..io.term import color_enabled, style

    click.echo(f"{style('warning:', sys.stderr, fg='yellow', bold=True)} {message}", err=True,
               color=color_enabled(sys.stderr))


def format_option(*, choices=FORMATS, help_extra=""):
    """``--format``/``-f``: default a table on a terminal, JSON Lines otherwise."""
    return click.option(
        "-f", "--format", "fmt", type=click.Choice(choices), default=None,
        help="Output format (default: table on a terminal, jsonl otherwise)." + help_extra)


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


def output_options(f):
    f = click.option("--append", is_flag=True, help="Append to --output instead of replacing it.")(f)
    f = click.option("-o", "--output", type=FilePath(),
                     help="Write records to FILE instead of stdout.")(f)
    return f


def open_output(path, append=False):
    """(stream, had_content): a line-buffered text stream for ``path`` ('-' or None: stdout)."""
    if not path or path == "-":
        return sys.stdout, False
    try:
        had = append and os.path.exists(path) and os.path.getsize(path) > 0
        return open(path, "a" if append else "w", encoding="utf-8", newline=""), had
    except OSError as e:
        raise UsageError(f"output: cannot open {path}: {e.strerror}") from None


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
    singular noun, ``frame`` or ``packet``)."""
    if framer.bad or framer.skipped:
        note(f"{plural(framer.frames, what)} decoded; {framer.bad} bad ({check}), "
             f"{plural(framer.skipped, 'byte')} skipped")


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
         "prompts and a script is refused (sim:// and --sim never ask).")

protocol_version_option = click.option(
    "--protocol-version", type=click.IntRange(1, 63), default=None, metavar="N",
    help="ECU protocol version assumed until a status ID 6 frame reveals it "
         "(sets the voltage unit: 0.1 V up to 3, 0.2 V from 4; default 4).")


def apply_options(f, options):
    """Apply option decorators listed in help order to a function or to a click Command (a
    Command lists its options in the order they are added; a function's decorators apply in
    reverse)."""
    for opt in (options if isinstance(f, click.Command) else reversed(options)):
        f = opt(f)
    return f


def port_options(group: str):
    """``-p/--port``, ``-b/--baud``, ``--timeout`` and ``--sim`` for a protocol group."""
    env = ENV[group]
    options = [
        click.option("-p", "--port", envvar=env["port"], metavar="PORT", default=None,
                     shell_complete=lambda ctx, param, incomplete: _complete_ports(ctx, param, incomplete, group),
                     help=f"Serial device or pyserial URL (socket://host:port, rfc2217://, "
                          f"loop://, spy://, hwgrep://) [env {env['port']}]."),
        click.option("-b", "--baud", type=click.IntRange(300, 4_000_000), envvar=env["baud"],
                     default=DEFAULT_BAUD[group], show_default=True,
                     help=f"Baud rate [env {env['baud']}]."),
        click.option("--timeout", type=click.FloatRange(0.001, 3600), default=None, metavar="SECONDS",
                     help="Reply timeout (default: derived from the baud rate)."),
        click.option("--sim", is_flag=True, help="Talk to the built-in simulator instead of a port."),
    ]
    return lambda f: apply_options(f, options)


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


def read_hex_input(args, *, what="hex input") -> bytes:
    """Hex bytes from the arguments (joined), or from stdin when there are none or one is ``-``."""
    from ..codec.hexfmt import parse_hex

    if not args or list(args) == ["-"]:
        if sys.stdin is None or (sys.stdin.isatty() and not args):
            raise UsageError(f"{what}: none given; pass hex bytes as arguments or on stdin")
        return parse_hex(sys.stdin.read(), what="stdin")
    return parse_hex(" ".join(a for a in args), what=what)


def consent(action: str, yes: bool) -> None:
    """Ask before something hazardous. ``--yes`` consents; a terminal prompts; anything else
    (a script, CI, no stdin) is refused with exit status 2 and nothing is sent."""
    if yes:
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
