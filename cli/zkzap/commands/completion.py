"""``zkzap completion SHELL``: print the shell completion script (for pipx and user installs)."""

from __future__ import annotations

import sys

import click

from . import CONTEXT, Command
from .options import Choice


@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("shell", type=Choice(["bash", "zsh", "fish"]))
@click.option("--prog", type=Choice(["zkzap", "zk", "zap"]), default="zkzap", show_default=True,
              help="The command to complete: zkzap, or the direct entry points zk and zap.")
def completion(shell, prog):
    """Print the completion script of SHELL for zkzap (or zk, zap with --prog).

    Completion offers sub-commands, options, choices (formats, engine states, actions),
    register names, the field names of 'zk send raw', baud rates for 'zap scan -b', fault kinds
    for --fault, file paths (schedules, --binary inputs, -o) and, for --port, the serial ports
    present, the URL schemes and sim://zk or sim://zap; it asks the installed program
    at each Tab, so it never goes out of date. Install it once per command and shell; a
    wheel install already puts the scripts in share/ (bash-completion, zsh site-functions,
    fish vendor_completions.d).

    \b
    Examples:
      zkzap completion bash > ~/.local/share/bash-completion/completions/zkzap
      zkzap completion bash --prog zk > ~/.local/share/bash-completion/completions/zk
      zkzap completion zsh > ~/.zfunc/_zkzap      # with fpath+=(~/.zfunc) before compinit
      zkzap completion fish > ~/.config/fish/completions/zkzap.fish
      eval "$(zkzap completion bash)"             # this shell only
    """
    from ..docs.completions import INSTALL, script

    click.echo(script(shell, prog), nl=False)
    if sys.stdout.isatty():
        click.echo(f"# install: {INSTALL[shell].format(prog=prog)}", err=True)
