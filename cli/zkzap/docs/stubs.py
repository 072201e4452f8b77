"""The type stub ``cli/zkzap/api/_registers.pyi``: an :class:`~zkzap.api.zap.Actuator`'s
registers as typed attributes, written from the register table so that type checkers know
``act.goal_position`` (an ``int`` to read and write), ``act.present_voltage`` (a read-only
:class:`~zkzap.api.zap.Reading`) and refuse ``act.goal_positon``.

    python -m zkzap.docs all        # (this file is part of it)

At run time an Actuator reads and writes its registers through ``__getattr__`` and
``__setattr__``; the stub is only what type checkers see (the module is never imported).
"""

from __future__ import annotations

import os

from ..codec import zap

#: Where the stub lives, relative to the repository root.
PATH = os.path.join("cli", "zkzap", "api", "_registers.pyi")


def _attribute(reg: zap.Register) -> list:
    name = reg.name.replace("-", "_")
    kind = "Reading" if reg.unit else "int"
    memory = {"NV": "stored", "V": "volatile"}.get(reg.memory, "read-only")
    unit = f" {reg.scale:g} {reg.unit}" if reg.scale != 1 else (f" {reg.unit}" if reg.unit else "")
    doc = f'"""0x{reg.address:02X} {reg.name} ({memory}, {reg.size} byte{"s" if reg.size > 1 else ""}){unit}"""'
    lines = ["    @property", f"    def {name}(self) -> {kind}:", f"        {doc}"]
    if reg.writable:
        value = "int | Reading" if reg.unit else "int"
        lines += [f"    @{name}.setter", f"    def {name}(self, value: {value}) -> None: ..."]
    return lines


def render() -> str:
    """The whole stub."""
    out = ['"""An Actuator\'s registers as typed attributes, for type checkers only.',
           "",
           "Written by `python -m zkzap.docs all` from the register table (zkzap.codec.zap.REGISTERS):",
           "do not edit. Registers with a unit read as a Reading; read-only ones have no setter.",
           '"""',
           "",
           "from .zap import Reading",
           "",
           "",
           "class RegisterAttributes:",
           '    """The registers of the 12Lf data map, named as in ``zap registers`` with underscores."""',
           ""]
    for reg in zap.REGISTERS:
        out += _attribute(reg) + [""]
    return "\n".join(out).rstrip("\n") + "\n"


def generate(root: str) -> list:
    """Write the stub under the repository ``root``; returns the paths written."""
    path = os.path.join(root, PATH)
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(render())
    return [path]
