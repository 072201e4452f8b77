"""The whole click command tree, for tests that must hold for every command.

A test that walks :func:`commands` covers a command added later without being told about it;
a hand-picked list of commands does not. Each entry is ``(path, command)`` with ``path`` the
words after ``zkzap`` (``("zk", "send", "control")``).
"""

from __future__ import annotations

import click


def commands(hidden: bool = True):
    """Every leaf command under the ``zkzap`` root, depth first, in listing order (hidden ones
    too unless ``hidden`` is false)."""
    from zkzap.commands import root

    def walk(cmd, path, ctx):
        if isinstance(cmd, click.Group):
            for name in cmd.list_commands(ctx):
                sub = cmd.get_command(ctx, name)
                if sub is None or (sub.hidden and not hidden):
                    continue
                yield from walk(sub, path + (name,), click.Context(sub, parent=ctx, info_name=name))
        else:
            yield path, cmd

    yield from walk(root, (), click.Context(root, info_name="zkzap"))


def groups(hidden: bool = True):
    """Every group under (and including) the root, as ``(path, group)``."""
    from zkzap.commands import root

    def walk(cmd, path, ctx):
        if isinstance(cmd, click.Group):
            yield path, cmd
            for name in cmd.list_commands(ctx):
                sub = cmd.get_command(ctx, name)
                if sub is None or (sub.hidden and not hidden):
                    continue
                yield from walk(sub, path + (name,), click.Context(sub, parent=ctx, info_name=name))

    yield from walk(root, (), click.Context(root, info_name="zkzap"))


def option_names(cmd) -> set:
    """Every spelling of every option of ``cmd`` (``{"-p", "--port", ...}``)."""
    return {o for p in cmd.params if isinstance(p, click.Option) for o in (*p.opts, *p.secondary_opts)}
