"""Which console requests need a person's confirmation: the command line's consent rules, for
the pages.

The rules are the command line's (``--yes``, ``--force``): on a real port (anything but the
in-process simulator and ``loop://``) writing stored (NV) settings, a factory reset, an ID or
baud-rate change, a check's full-stroke moves and a ZK frame that can start the engine or run
ECU hardware need consent; on every port, a write of a setting that changes how an actuator is
reached or answers (id, baud-rate, protocol-type, feedback-return-mode) needs ``force`` as
well. The page asks; the request comes back with the permissions granted.

Every console request that needs one goes through :class:`Policy`, which raises
:class:`Needed` naming the permission when it is not granted. This module is the one adapter
between the consoles and the policy: when the library checks permissions itself (an API call
that raises a :class:`~zkzap.errors.ZkzapError` naming the permission unless it is given),
this module passes the permissions on and turns that error into :class:`Needed`, and nothing
else changes.
"""

from __future__ import annotations

from ..api.fleet import PROTECTED
from ..codec import zap, zk

#: Permissions a page can grant, with what the person is asked.
STORED = "stored-write"
FORCE = "force"
ENGINE = "engine"
MOVE = "move"
PERMISSIONS = (STORED, FORCE, ENGINE, MOVE)


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
    """True for ports where nothing real can be harmed (no consent there), as on the command line."""
    return bool(url) and str(url).startswith(("sim://", "loop://"))


class Policy:
    """The consent rules for one port ``url``."""

    def __init__(self, url: str):
        self.url = url
        self.real = not simulated(url)

    def _need(self, permission, granted, text):
        if permission not in granted:
            raise Needed(permission, text)

    # -- mightyZAP ------------------------------------------------------------------------------

    def zap_packets(self, packets, granted=()) -> None:
        """Command packets about to go out: force for a protected setting (on every port),
        consent for stored writes (on a real port)."""
        protected = []
        names = []
        for p in packets:
            cmd = zap.Command(p)
            for name in PROTECTED:
                if cmd.written_value(name) and name not in protected:
                    protected.append(name)
            for n in cmd.stored_writes:
                if n not in names:
                    names.append(n)
        self.zap_protected(protected, granted)
        if names and self.real:
            self._need(STORED, granted, f"This writes stored settings on {self.url} ({', '.join(names)}). They "
                                        "survive power-off, and each write wears the actuator's memory.")

    def zap_protected(self, names, granted=()) -> None:
        """Force for writing settings that change how an actuator is reached or answers."""
        if names:
            self._need(FORCE, granted, f"{', '.join(names)} changes how the actuator is reached or answers "
                                       "(a wrong value can make it unreachable). Tick 'force' to write it.")

    def zap_identity(self, what, granted=()) -> None:
        """An ID or baud-rate change (verified by reading back): force, and consent on a real port."""
        self.zap_protected([what.split(" ", 1)[0]], granted)
        if self.real:
            self._need(STORED, granted, f"This changes the {what} on {self.url}, a stored setting that survives "
                                        "power-off.")

    def zap_check(self, ids, move, granted=()) -> None:
        """A self-check's full-stroke moves (a real port only)."""
        if move and self.real:
            many = len(ids) > 1
            self._need(MOVE, granted, f"The check moves actuator{'s' if many else ''} "
                                      f"{', '.join(map(str, ids))} on {self.url} through "
                                      f"{'their' if many else 'its'} full stroke.")

    def zap_apply(self, writes, granted=()) -> None:
        """A fleet apply's planned writes."""
        self.zap_protected(sorted({w.register.name for w in writes if w.register.name in PROTECTED}), granted)
        stored = sum(1 for w in writes if w.register.stored)
        if stored and self.real:
            self._need(STORED, granted, f"The apply makes {len(writes)} write{'s' if len(writes) != 1 else ''} "
                                        f"on {self.url}, {stored} of them stored settings that survive power-off.")

    # -- ZK -----------------------------------------------------------------------------------

    def zk_frames(self, frames, granted=()) -> None:
        """Control frames about to go out: consent for one that can start the engine or run ECU
        hardware (a real port only)."""
        if not self.real:
            return
        for f in frames:
            hazard = zk.ControlFrame(f).hazard
            if hazard:
                self._need(ENGINE, granted, f"{zk.ControlFrame(f).frame.hex(' ').upper()} to {self.url}: {hazard}.")

