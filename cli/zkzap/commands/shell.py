"""``zkzap shell zap|zk``: the commands of one protocol at an interactive prompt, over one open
port, with completion (commands, options, register names, choices) and history (readline).

Each line is a command without the program name and the port options, as in a batch
(:mod:`.batch`); its output is the command's own (a table on a terminal). Standard input that
is not a terminal is read line by line without a prompt, so a shell session can be scripted.
"""

from __future__ import annotations

import os
import shlex
import sys

import click

from ..errors import MORE_TO_DO, OK, UsageError
from . import CONTEXT, Command, Group
from .batch import EXCLUDED, PORT_TOKENS, STAND_BUILTINS, _batch_capture, port_tokens
from .options import exits, port_options

BUILTINS = ("help", "exit", "quit")


def history_path() -> str:
    """Where the history is kept: $ZKZAP_HISTORY, else $XDG_STATE_HOME/zkzap/history
    (~/.local/state/zkzap/history)."""
    given = os.environ.get("ZKZAP_HISTORY")
    if given:
        return given
    state = os.environ.get("XDG_STATE_HOME") or os.path.join(os.path.expanduser("~"), ".local", "state")
    return os.path.join(state, "zkzap", "history")


class Completer:
    """readline completion from the click application: sub-commands, options, and the values
    their types complete (register names, choices, 'broadcast')."""

    def __init__(self, group, protocol):
        self.group = group
        self.protocol = protocol
        self.matches = []

    def candidates(self, buffer: str, text: str) -> list:
        """Completions of ``text``, the last word of ``buffer`` (the line up to the cursor)."""
        from click.shell_completion import ShellComplete

        head = buffer[:len(buffer) - len(text)]
        try:
            args = shlex.split(head)
        except ValueError:
            args = head.split()
        if not args:
            names = [n for n in self.group.list_commands(click.Context(self.group))
                     if n not in EXCLUDED[self.protocol]]
            own = list(BUILTINS) + list(STAND_BUILTINS.get(self.protocol, ()))
            return sorted(n for n in list(names) + own if n.startswith(text))
        comp = ShellComplete(self.group, {}, self.protocol, "_ZKZAP_COMPLETE")
        try:
            items = comp.get_completions(args, text)
        except Exception:  # noqa: BLE001 - a half-typed line: nothing to offer
            return []
        return [i.value for i in items if i.type == "plain" and i.value not in PORT_TOKENS]

    def __call__(self, text, state):
        if state == 0:
            import readline

            self.matches = self.candidates(readline.get_line_buffer()[:readline.get_endidx()], text)
        return self.matches[state] + " " if state < len(self.matches) else None


def _defaults_for(group, tokens, defaults) -> dict:
    """The nested default_map giving the command a line names (``send control``) ``defaults``."""
    ctx = click.Context(group)
    path, cmd = [], group
    for name in tokens:
        if not isinstance(cmd, click.Group):
            break
        sub = cmd.get_command(ctx, name)
        if sub is None:
            break
        path.append(name)
        cmd, ctx = sub, click.Context(sub, info_name=name, parent=ctx)
    dm = dict(defaults)
    for name in reversed(path):
        dm = {name: dm}
    return dm


def _help(group, protocol):
    ctx = click.Context(group, info_name=protocol)
    rows = [(n, group.lazy[n][2] if n in getattr(group, "lazy", {}) else "") for n in group.list_commands(ctx)
            if n not in EXCLUDED[protocol]]
    width = max(len(n) for n, _ in rows)
    click.echo("\n".join(f"  {n:<{width}}  {h}" for n, h in rows))
    if protocol == "zk":
        click.echo("  alarms  the alarm list of this shell's sessions (a trip latches until 'ack'); ack acknowledges")
    click.echo("  'COMMAND --help' for its options; exit [N], quit [N] or Ctrl-D to leave.")


def loop(group, protocol, defaults, *, interactive) -> int:
    """Read and run lines until exit or end of input; returns the shell's exit status:

    - ``exit N`` / ``quit N``: N;
    - ``exit``, ``quit``, Ctrl-D or the end of piped input: 0 at a terminal (the user asked to
      leave); with piped input the status of the last command that failed, so a script can
      tell. A command stopped by Ctrl-C (130) returns to the prompt and does not count: the
      user stopped it on purpose;
    - SIGTERM, at the prompt or during a command, ends the shell with 143 (every other signal
      that ends a program likewise, with 128 + its number: 129 for SIGHUP)."""
    from . import run

    if interactive:
        import readline

        path = history_path()
        try:
            readline.read_history_file(path)
        except OSError:
            pass
        readline.set_history_length(1000)
        readline.set_completer_delims(" \t\n")
        readline.set_completer(Completer(group, protocol))
        readline.parse_and_bind("tab: complete")
    from .. import signals
    from ..errors import INTERRUPTED, USAGE
    from ..link import stop

    failed = 0
    try:
        while True:
            signals.forget()             # the last command's Ctrl-C is over: the next one counts
            try:
                text = input(f"{protocol}> ") if interactive else sys.stdin.readline()
            except signals.Terminated as e:
                return signals.exit_status(e)
            except KeyboardInterrupt:
                click.echo("", err=True)
                continue
            except EOFError:
                if interactive:
                    click.echo("", err=True)
                break
            if not interactive and not text:
                break
            text = text.strip()
            if not text or text.startswith("#"):
                continue
            try:
                tokens = shlex.split(text, comments=True)
            except ValueError as e:
                click.echo(f"{protocol}: error: {e}", err=True)
                failed = USAGE
                continue
            if not tokens:
                continue
            if tokens[0] in ("exit", "quit"):
                code = _exit_code(tokens, protocol)
                if code is None:
                    failed = USAGE
                    continue
                return code if code >= 0 else (0 if interactive else failed)
            if tokens[0] == "help":
                _help(group, protocol)
                continue
            if tokens[0] in STAND_BUILTINS.get(protocol, ()):
                failed = _alarm_builtin(tokens) or failed
                continue
            bad = port_tokens(tokens)
            if bad or tokens[0] in EXCLUDED[protocol]:
                what = (f"{bad[0]}: the port is the shell's" if bad
                        else f"{tokens[0]}: not in a shell")
                click.echo(f"{protocol}: error: {what}", err=True)
                failed = USAGE
                continue
            with stop.deferring():       # Ctrl-C: the command stops after its current transaction
                code = run(group, protocol, tokens, default_map=_defaults_for(group, tokens, defaults))
            if signals.terminated_status(code):
                return code              # SIGTERM (SIGHUP, ...) ends the shell too, once the command has stopped
            if code and code != INTERRUPTED:
                failed = code
    finally:
        if interactive:
            import readline

            try:
                os.makedirs(os.path.dirname(history_path()), exist_ok=True)
                readline.write_history_file(history_path())
            except OSError:
                pass
    return 0 if interactive else failed


def _alarm_builtin(tokens) -> int:
    """``alarms``: the list (newest first) and whether a start is allowed; ``ack [ID ...] [--by
    NAME]``: acknowledge the latched alarms (as in a batch, :func:`..batch.run_builtin`).
    Returns an exit status (2: bad usage)."""
    from .batch import operator, parse_builtin, run_builtin

    try:
        parsed = parse_builtin(tokens)
    except UsageError as e:
        click.echo(f"zk: error: {e}", err=True)
        return 2
    code, result = run_builtin(parsed, operator())
    if parsed["op"] == "ack" or code:
        return code
    for a in result["alarms"]:
        state = "LATCHED" if a["latched"] else ("acknowledged" if a["acked_by"] else a["level"])
        by = f" (by {a['acked_by']} at {a['acked_at']})" if a["acked_by"] else ""
        click.echo(f"{a['id']:>3}  {a['time']}  {state:<12}  {a['text']}{by}")
    if not result["alarms"]:
        click.echo("no alarm", err=True)
    click.echo(result["start"] or "a start is allowed", err=True)
    return 0


def _exit_code(tokens, protocol):
    """``exit`` -> -1 (the default status), ``exit N`` -> N; None (after a message) for a bad N."""
    if len(tokens) == 1:
        return -1
    if len(tokens) == 2 and tokens[1].isdigit() and int(tokens[1]) <= 255:
        return int(tokens[1])
    click.echo(f"{protocol}: error: {tokens[0]}: {' '.join(tokens[1:])!r} is not an exit status; "
               "allowed 0..255", err=True)
    return None


@click.group(cls=Group, context_settings=CONTEXT)
def shell():
    """An interactive zap or zk session over one open port, with completion and history.

    \b
    Examples:
      zkzap shell zap -p /dev/ttyUSB0
      zkzap shell zk --sim
      printf 'load present-position --id 1\\n' | zkzap shell zap --sim --sim-ids 1
    """


def _description(protocol):
    return (f"Run {protocol} commands at a '{protocol}> ' prompt over one open port.\n\n"
            "Each line is a command as on the command line without the program name and the port "
            f"options (as in '{protocol} batch'); its output is the command's own. TAB completes "
            "commands, options, register names and choices; the history is kept in "
            "$ZKZAP_HISTORY (default ~/.local/state/zkzap/history). 'help' lists the commands; "
            "exit, quit or Ctrl-D leaves; Ctrl-C stops the running command after its current "
            "transaction (a ZK session sends its abort as usual) and returns to the prompt. Consent is asked per command on a "
            "real port (--yes on the line). Standard input that is not a terminal is run line "
            "by line without a prompt.\n\nExit status: 'exit N' gives N; exit, quit or Ctrl-D give 0 at a "
            "terminal, and with piped input the status of the last command that failed (a command "
            "stopped by Ctrl-C does not count: it returned to the prompt as asked); SIGTERM ends "
            "the shell with 143.")


#: A shell at a terminal ends well however its commands ended; piped, it reports the last failure.
_SHELL_MEANINGS = {OK: "exit, quit or Ctrl-D (piped: every command succeeded)"}
_SHELL_TAIL = " Piped, any other status is the last failed command's; exit N gives N."
SHELL_EXITS = exits(_SHELL_MEANINGS, tail=_SHELL_TAIL)
#: The mightyZAP shell: piped, a 'setup --no-wait' that stopped with IDs pending is "more to do" (8).
ZAP_SHELL_EXITS = exits({**_SHELL_MEANINGS,
                         MORE_TO_DO: "piped, the last failed command was a setup that stopped with IDs pending"},
                        tail=_SHELL_TAIL)


def _make_zap():
    from .options import protocol_options
    from .zap.compose import link_options

    @ZAP_SHELL_EXITS
    @click.command("zap", cls=Command, context_settings=CONTEXT, help=_description("zap") + """

\b
Examples:
  zkzap shell zap -p /dev/ttyUSB0
  zkzap shell zap --sim --sim-ids 1,2
  zkzap shell zap --protocol modbus -p /dev/ttyUSB0   # every line speaks Modbus RTU""")
    @link_options
    @protocol_options
    def zap_shell(**common):
        from ..link.shared import sharing
        from .zap import zap as group
        from .zap.compose import line_defaults, open_link, shared_bus_args

        defaults = line_defaults(common)
        args = shared_bus_args(common, [0])
        if common["sim"]:
            args["sim_ids"] = common["sim_ids"] or ",".join(map(str, args["ids"]))
        with open_link(**args) as bus, sharing("zap", bus), _batch_capture():
            code = loop(group, "zap", defaults, interactive=_interactive())
        if code:
            raise click.exceptions.Exit(code)

    return zap_shell


def _make_zk():
    @SHELL_EXITS
    @click.command("zk", cls=Command, context_settings=CONTEXT, help=_description("zk") + """

\b
Examples:
  zkzap shell zk -p /dev/ttyUSB0
  zkzap shell zk -p 'sim://zk?speed=10'""")
    @port_options("zk")
    def zk_shell(port, baud, stop_bits, timeout, sim):
        from ..link.zk_port import ZkLink
        from ..link.shared import sharing
        from .zk import zk as group
        from .zk.telemetry import resolve_port

        url = resolve_port(port, sim)
        defaults = {"port": url, "sim": False, "baud": baud}
        if timeout is not None:
            defaults["timeout"] = timeout
        link = ZkLink.open(url, baud, stop_bits=stop_bits)
        from ..api.stand import shared_stand
        from .options import note

        try:
            with sharing("zk", link), _batch_capture(), shared_stand(notify=note):
                code = loop(group, "zk", defaults, interactive=_interactive())
        finally:
            link.close()
        if code:
            raise click.exceptions.Exit(code)

    return zk_shell


def _interactive() -> bool:
    from ..io.term import is_tty

    return is_tty(sys.stdin) and is_tty(sys.stdout)


shell.add_command(_make_zap())
shell.add_command(_make_zk())
