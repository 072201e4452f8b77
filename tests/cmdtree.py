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


# --- values from what a parameter declares ---------------------------------------------------

def declared(p):
    """The parameter's type and its zkzap class name (``"InputPath"``, ``"IdType"``, ...)."""
    return p.type, type(p.type).__name__


#: For zkzap's own parameter types: (a value it takes, a value it refuses).
EXAMPLES = {"IdType": ("1", "255"), "IntValue": ("100", "abc"), "RegisterType": ("goal-position", "no-such-register"),
            "IdList": ("1", "300"), "BaudType": ("57600", "12"), "BaudList": ("57600", "12"), "MapType": ("1:2", "1"),
            "RegisterList": ("goal-speed", "no-such-register"), "InstructionType": ("echo", "jump"),
            "TargetType": ("1:100", "1-2"), "FiniteFloat": ("1.0", "nan"),
            "PointType": ("98.0665=1002.4", "nan"), "NumberValue": ("100", "nan")}


def bad_value(p):
    """A value the parameter's declared type, choices or range refuses, or None when its type
    declares no domain to leave (free text, flags)."""
    t, name = declared(p)
    if getattr(p, "is_flag", False) or getattr(p, "count", False):
        return None
    if isinstance(t, click.Choice):
        return "no-such-choice"
    if name == "InputPath":
        return "/nonexistent-zkzap/input"
    if name == "OutputPath":
        return "/nonexistent-zkzap/dir/output" + ((t.suffixes or ("",))[0])
    if name in EXAMPLES:
        return EXAMPLES[name][1]
    if name in ("FieldFloat", "FieldInt"):
        r = t.field.physical_range()
        return None if r is None else str(r[1] + 1)
    if isinstance(t, (click.IntRange, click.FloatRange)):
        if t.max is not None:
            return str(t.max + 1)
        if t.min is not None:
            return str(t.min - 1)
    if isinstance(t, (click.types.IntParamType, click.types.FloatParamType)):
        return "x"
    return None


def valid_value(p, files):
    """A value the parameter's declared type takes (``files``: valid input files by what they
    hold, and a factory of output paths), or None."""
    t, name = declared(p)
    if name == "InputPath":
        return files[t.holds]
    if name == "OutputPath":
        return files["output"](t)
    if isinstance(t, click.Choice):
        return t.choices[0]
    if name in EXAMPLES:
        return EXAMPLES[name][0]
    if name in ("FieldFloat", "FieldInt"):
        r = t.field.physical_range()
        return str(r[0] if r is not None else 0)
    if isinstance(t, (click.IntRange, click.FloatRange)):
        lo = t.min if t.min is not None else (t.max - 1 if t.max is not None else 1)
        return str(lo + 1 if getattr(t, "min_open", False) else lo)
    if isinstance(t, click.types.IntParamType):
        return "1"
    if isinstance(t, click.types.FloatParamType):
        return "1.0"
    return None


def spelling(p):
    """How a user gives an option: its long spelling."""
    return next((o for o in p.opts if o.startswith("--")), p.opts[0])


class LocalServer:
    """A TCP server on 127.0.0.1 (``url``: ``socket://127.0.0.1:N``) that hands every accepted
    connection to :meth:`handle`, on its one accept thread, until :meth:`close`."""

    def __init__(self):
        import socket
        import threading

        self._srv = socket.socket()
        self._srv.bind(("127.0.0.1", 0))
        self._srv.listen(8)
        self._srv.settimeout(0.05)
        self.url = f"socket://127.0.0.1:{self._srv.getsockname()[1]}"
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self):
        import socket

        while not self._stop.is_set():
            try:
                conn, _ = self._srv.accept()
            except (socket.timeout, OSError):
                continue
            self.handle(conn)

    def handle(self, conn):
        raise NotImplementedError

    def close(self):
        self._stop.set()
        self._thread.join(1)
        self._srv.close()


class RecordingPort(LocalServer):
    """A TCP port (``socket://127.0.0.1:N``) that records every connection and byte sent to it."""

    def __init__(self):
        self.connections, self.data = 0, b""
        super().__init__()

    def handle(self, conn):
        self.connections += 1
        conn.settimeout(0.2)
        try:
            while chunk := conn.recv(4096):
                self.data += chunk
        except OSError:
            pass
        conn.close()

    def seen(self):
        return self.connections, self.data
