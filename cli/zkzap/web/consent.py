"""Which console requests need a person's confirmation: the library's permissions
(:mod:`zkzap.codec.permissions`), asked for on the page.

The rules are not this module's. What a frame needs is decided once, on the typed frame
(:meth:`zkzap.codec.zap.Command.needs`, :meth:`zkzap.codec.zk.ControlFrame.needs`), and
enforced where every frame goes out (the bus and the ZK link), for the command line, the
library and the consoles alike: a stored write, a factory reset and a ZK frame that can start
the engine or run ECU hardware need consent on a real port (a simulator waives it); a direct
write of id, baud-rate or protocol-type, an undocumented address or value, a partial register
a write after which the actuator stops answering (feedback-return-mode 0, protocol-type 0) and
a broadcast of those need force on every port. ``zap set-id`` and ``zap set-baud``, the
checked ways, need the stored-write consent only.

This module is the one adapter between the pages and that mechanism: :meth:`Policy.allow`
turns what a page granted into the ``allow=`` the library's calls take, and a
:class:`~zkzap.errors.PermissionNeeded` the library raises (nothing sent) becomes
:class:`Needed` — the permission the page asks for, with the words of its dialog; the request
then comes back with it granted. Only a self-check's full-stroke moves are asked here
(:data:`MOVE`, as ``zap check --yes`` asks on the command line): they are a procedure's effect,
not a frame's permission.
"""

from __future__ import annotations

import contextlib

from ..codec import permissions as P
from ..codec import zap, zk
from ..codec.permissions import Permission

#: Permissions a page can grant, with what the person is asked.
STORED = "stored-write"
FORCE = "force"
ENGINE = "engine"
MOVE = "move"
PERMISSIONS = (STORED, FORCE, ENGINE, MOVE)

#: What each grant of a page gives the library (``allow=``).
GRANTS = {
    STORED: Permission.STORED | Permission.FACTORY,
    FORCE: P.FORCE,
    ENGINE: Permission.ENGINE,
}
#: Registers the console writes the checked way (``Bus.set_id``, ``Bus.set_baud``), not directly.
CHECKED = ("id", "baud-rate")


class Needed(Exception):
    """A request that needs ``permission`` (one of :data:`PERMISSIONS`); ``text`` says why, in
    words for the confirmation dialog."""

    def __init__(self, permission: str, text: str):
        super().__init__(text)
        self.permission = permission
        self.text = text

    def message(self) -> dict:
        return {"permission": self.permission, "text": self.text}


def simulated(url: str) -> bool:
    """True for ports where nothing real can be harmed (the library waives consent there):
    the in-process simulator and ``loop://``."""
    from ..link.zap_bus import is_simulated

    return is_simulated(url)


def _direct_write(reg, value) -> bytes:
    return zap.packet(1, zap.STORE_DATA, bytes((reg.address,)) + reg.to_bytes(value))


def _write_permissions(reg, value, regmap=None):
    """What the console's direct write of ``value`` to ``reg`` needs, decided on the frame it
    sends: an IR Store Data, or on a Modbus map (``regmap``) a Write Multiple Registers."""
    if regmap is not None and regmap.protocol == "modbus":
        from ..codec import modbus

        return modbus.Request(modbus.write_registers(1, reg.address, [value])).permissions(regmap)
    return zap.Command(_direct_write(reg, value)).permissions


def force_values(reg, regmap=None) -> list:
    """The values of register ``reg`` whose direct write from the console needs force, as the
    library decides it on the packet (:meth:`zkzap.codec.zap.Command.needs`): every value of a
    register whose write changes where or how the actuator answers (protocol-type), the values
    after which it stops answering (feedback-return-mode 0), none of most. id and baud-rate are
    written the checked way (set-id, set-baud), which does not need force. A register with a
    range (no choices) is asked at both ends."""
    if reg.name in CHECKED or not reg.writable:
        return []
    values = sorted(reg.choices) if reg.choices else sorted({reg.lo, reg.hi})
    return [v for v in values if _write_permissions(reg, v, regmap) & P.FORCE]


def needs_force(reg, value=None, regmap=None) -> bool:
    """Whether the console's direct write of register ``reg`` needs force: of ``value``, or
    (None) whatever value is written (protocol-type: the page marks its button); ``regmap``:
    a Modbus map (its frames decide)."""
    if value is not None:
        return reg.name not in CHECKED and bool(_write_permissions(reg, value, regmap) & P.FORCE)
    values = sorted(reg.choices) if reg.choices else sorted({reg.lo, reg.hi})
    return bool(values) and force_values(reg, regmap) == values


class Policy:
    """The permissions of the requests on one port ``url``; ``simulated``: whether the library
    waives consent there (default: as :func:`simulated` says of ``url``)."""

    def __init__(self, url: str, simulated_port=None):
        self.url = url
        self.simulated = simulated(url) if simulated_port is None else bool(simulated_port)
        self.real = not self.simulated

    @staticmethod
    def allow(granted=()) -> Permission:
        """The library's ``allow=`` for what a page granted."""
        out = Permission.NONE
        for g in granted:
            out |= GRANTS.get(g, Permission.NONE)
        return out

    def needed(self, e) -> Needed:
        """The page's question for the library's :class:`~zkzap.errors.PermissionNeeded` ``e``:
        force first (the dialog's checkbox), then the engine, then the stored write."""
        missing = e.missing
        reasons = getattr(e, "reasons", None) or {}

        def why(perms):
            return "; ".join(dict.fromkeys(r for p, r in reasons.items() if p & perms)) or str(e)

        if missing & P.FORCE:
            return Needed(FORCE, f"{why(P.FORCE)}. This changes how the actuator is reached or answers, or "
                                 "goes beyond what its register map documents (a wrong value can make it "
                                 "unreachable). Tick 'force' to send it.")
        if missing & Permission.ENGINE:
            frame = getattr(e, "frame", b"") or b""
            return Needed(ENGINE, f"{frame.hex(' ').upper()} to {self.url}: {why(Permission.ENGINE)}.")
        frame = getattr(e, "frame", b"") or b""
        names = []
        if len(frame) > 5:
            try:
                names = zap.Command(frame).stored_writes
            except (zap.PacketError, ValueError):
                names = []
        what = ", ".join(names) or why(Permission.STORED | Permission.FACTORY)
        return Needed(STORED, f"This writes stored settings on {self.url} ({what}). They survive power-off, "
                              "and each write wears the actuator's memory.")

    @contextlib.contextmanager
    def asking(self):
        """``with policy.asking():`` a library call; its PermissionNeeded (nothing was sent)
        becomes :class:`Needed`."""
        from ..errors import PermissionNeeded

        try:
            yield
        except PermissionNeeded as e:
            raise self.needed(e) from None

    def _require(self, needs, granted, what, frame) -> None:
        with self.asking():
            P.require(needs, self.allow(granted), simulated=self.simulated, what=what, frame=frame)

    # -- before a request's first frame -----------------------------------------------------------

    def zap_packets(self, packets, granted=()) -> None:
        """Command packets about to go out, every one checked before the first (what the bus
        checks as each goes out)."""
        for p in packets:
            cmd = zap.Command(p)
            self._require(cmd.needs(), granted, cmd.describe(), p)

    def zk_frames(self, frames, granted=()) -> None:
        """Control frames a session is about to send, every one checked before the first (what
        the ZK link checks as each goes out)."""
        for f in frames:
            cf = zk.ControlFrame(f)
            self._require(cf.needs(), granted, f"{cf.frame.hex(' ').upper()}", cf.frame)

    def zap_check(self, ids, move, granted=()) -> None:
        """A self-check's full-stroke moves (a real port only)."""
        if move and self.real and MOVE not in granted:
            many = len(ids) > 1
            raise Needed(MOVE, f"The check moves actuator{'s' if many else ''} {', '.join(map(str, ids))} on "
                               f"{self.url} through {'their' if many else 'its'} full stroke.")
