"""Invocations for every command of a class, built from what each command declares.

A test that holds for "every command that talks to a device" walks :func:`cmdtree.commands`,
keeps the commands whose parameters say so (:func:`protocol`: the port options of a protocol
group) and invokes each with :func:`invocation`: values for its required parameters come from
tables keyed by *parameter name* (``sw``, ``reg``, ``schedule``), never by command, so a command
added later is covered by its parameters — or fails loudly (:class:`MissingValue`) until its new
parameter gets a value here.
"""

from __future__ import annotations

import click


class MissingValue(LookupError):
    """A required parameter nobody gave a value for: add it to the tables."""


def protocol(cmd):
    """``"zk"`` or ``"zap"`` for a command that opens a port of that protocol (its port or baud
    option defaults from ``ZKZAP_ZK_*`` / ``ZKZAP_ZAP_*``), else None."""
    for p in cmd.params:
        if p.name in ("port", "baud") and isinstance(p, click.Option):
            env = p.envvar or ""
            if env.startswith("ZKZAP_ZK_"):
                return "zk"
            if env.startswith("ZKZAP_ZAP_"):
                return "zap"
    return None


def has(cmd, name) -> bool:
    """Whether ``cmd`` declares a parameter ``name``."""
    return any(p.name == name for p in cmd.params)


def invocation(cmd, values, bounds=None) -> list:
    """Arguments for ``cmd``: every required parameter (and every argument) from ``values``
    (name -> str or list of str; a callable gets the command), then the options of ``bounds``
    (name -> value; a callable gets the command, and None leaves the option out) the command
    declares. Raises :class:`MissingValue`."""
    positional, options = [], []
    for p in cmd.params:
        # an optional argument (a schedule, a batch file) is what such a command works on: give it
        if not (p.required or (isinstance(p, click.Argument) and p.name in values)):
            continue
        if p.name not in values:
            raise MissingValue(f"{cmd.name}: no value for its required parameter {p.name!r}")
        value = values[p.name]
        value = value(cmd) if callable(value) else value
        items = [value] if isinstance(value, str) else list(value)
        if isinstance(p, click.Argument):
            positional += items
        else:
            options += [_flag(p)] + items
    for name, value in (bounds or {}).items():
        value = value(cmd) if callable(value) else value
        if value is None:
            continue
        for p in cmd.params:
            if p.name == name and isinstance(p, click.Option) and not p.required:
                options += [_flag(p)] + ([] if value is True else [str(value)])
    return positional + options


def _flag(p):
    longs = [o for o in p.opts if o.startswith("--")]
    return longs[0] if longs else p.opts[0]
