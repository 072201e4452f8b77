"""What sending a frame needs from whoever sends it: one policy for both protocols.

A typed frame answers it once: :meth:`zkzap.codec.zk.ControlFrame.needs` and
:meth:`zkzap.codec.zap.Command.needs` give ``{Permission: reason}`` for the frame, and their
``permissions`` the union. The sessions of the library (:class:`zkzap.Bus`, :class:`zkzap.Ecu`)
refuse a frame whose permissions were not given (:class:`zkzap.errors.PermissionNeeded`, nothing
sent); the command line maps ``--yes`` onto :data:`CONSENT` and ``--force`` onto :data:`FORCE`.

Two kinds:

- :data:`CONSENT` (``ENGINE``, ``STORED``, ``FACTORY``): what can harm real hardware. Needed on a
  real port only; a simulator (``sim://``, ``loop://`` for mightyZAP) never needs it.
- :data:`FORCE` (``IDENTITY``, ``SILENCING``, ``UNDOCUMENTED``, ``PARTIAL``, ``BROADCAST``):
  deliberate acts that skip a safer way, leave the documentation or can leave an actuator that
  no longer answers. Needed everywhere, the simulator too: they are as surprising there as on a
  bench.

The rule for a write that can make an actuator stop answering is one entry of this table
(``SILENCING``), decided from the register map (a register's ``silences=V`` values:
feedback-return-mode 0, after which the actuator answers Echo only, and protocol-type 0, after
which it answers Modbus RTU only) and, for Factory Reset, from its flags (resetting the ID or the
baud rate moves the actuator to ID 0 or 57600 baud: ``IDENTITY``). The command line, the Python
API, ``zap apply`` and the browser console all ask the typed frame, so they cannot disagree.
"""

from __future__ import annotations

import enum

from .fields import FieldValueError

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Iterable, Mapping, Union

    from typing_extensions import TypeAlias


class Permission(enum.Flag):
    """Permissions a frame may need (combine with ``|``)."""

    NONE = 0
    #: Can start the engine or run ECU hardware (state run, drain, test actions, pump on).
    ENGINE = enum.auto()
    #: Writes stored (NV) memory: it survives power-off and wears the actuator's memory.
    STORED = enum.auto()
    #: Changes where or how the actuator answers: its ID, baud rate or protocol type.
    IDENTITY = enum.auto()
    #: Can make the actuator stop answering (feedback-return-mode 0: Echo only; protocol-type 0).
    SILENCING = enum.auto()
    #: Factory reset (0xF6) or IR Robot's system write (0xF9, their library's factory reset).
    FACTORY = enum.auto()
    #: An address, instruction or value the 12Lf documentation does not give (0x05, 0x97 lock,
    #: alarm-led 2, bulk-write, ...).
    UNDOCUMENTED = enum.auto()
    #: A write that covers only some bytes of a multi-byte register (0x87: goal-position's high byte).
    PARTIAL = enum.auto()
    #: Any of the above sent to every actuator at once (ID 254).
    BROADCAST = enum.auto()


if TYPE_CHECKING:
    #: What ``allow=`` takes: a :class:`Permission`, True (every one), False or None (none), or
    #: permissions and their names (``["stored", "identity"]``).
    AllowSpec: TypeAlias = Union[Permission, bool, None, str, Iterable[Union[Permission, str]]]
else:
    AllowSpec = "Permission | bool | None | str | Iterable[Permission | str]"

#: What ``--yes`` grants: hazards to real hardware, never needed on a simulator.
CONSENT = Permission.ENGINE | Permission.STORED | Permission.FACTORY
#: What ``--force`` grants: deliberate acts, needed everywhere.
FORCE = (Permission.IDENTITY | Permission.SILENCING | Permission.UNDOCUMENTED | Permission.PARTIAL
         | Permission.BROADCAST)
#: Every permission.
ALL = CONSENT | FORCE

#: How a permission is named in messages.
NAMES = {
    Permission.ENGINE: "engine start",
    Permission.STORED: "stored write",
    Permission.IDENTITY: "identity change",
    Permission.SILENCING: "stops answering",
    Permission.FACTORY: "factory reset",
    Permission.UNDOCUMENTED: "undocumented",
    Permission.PARTIAL: "partial register",
    Permission.BROADCAST: "broadcast",
}


#: What needs each permission (the policy of :meth:`zkzap.codec.zap.Command.needs` and
#: :meth:`zkzap.codec.zk.ControlFrame.needs`, in words, for the reference documentation).
WHAT = {
    Permission.ENGINE: "a ZK control frame that can start the engine or run ECU hardware: ID 1 or 6 with state "
                       "run, an action that drains fuel, tests hardware or turns the pump on",
    Permission.STORED: "a mightyZAP write to stored (NV) memory: a stored register, or an address the map "
                       "does not name below 0x80 (where every stored register lies)",
    Permission.FACTORY: "Factory Reset (0xF6), and IR Robot's system write (0xF9), which their Python "
                        "library sends as its factory reset",
    Permission.IDENTITY: "a direct write of id, baud-rate or protocol-type: it changes where or how the "
                         "actuator answers (set-id and set-baud are the checked ways); a Factory Reset that "
                         "resets the ID or the baud rate",
    Permission.SILENCING: "a write after which the actuator stops answering: feedback-return-mode 0 (it then "
                          "answers Echo only, never a read) and protocol-type 0 (Modbus RTU only); the map "
                          "marks such values (silences=V)",
    Permission.UNDOCUMENTED: "an address the 12Lf map does not give (0x05, IR Robot's lock 0x97), a read-only "
                             "register, a value outside a register's documented range, bits or choices, an "
                             "instruction the 12Lf does not document (but 0xF9)",
    Permission.PARTIAL: "a write that starts or ends inside a multi-byte register (0x87: goal-position's "
                        "high byte)",
    Permission.BROADCAST: "any of the above to every actuator at once (ID 254; a Symmetric Store names its "
                          "targets)",
}


def members(perm: Permission) -> list[Permission]:
    """The single permissions in ``perm``, in declaration order (a Flag is not iterable on
    every Python this runs on)."""
    return [p for p in NAMES if p & perm]


def describe(perm: Permission) -> str:
    """``"IDENTITY (identity change), BROADCAST (broadcast)"``."""
    return ", ".join(f"{p.name} ({NAMES[p]})" for p in members(perm))


def waived(simulated: bool) -> Permission:
    """What a port grants by itself: the consent permissions on a simulator, nothing otherwise."""
    return CONSENT if simulated else Permission.NONE


def missing(needs: Mapping[Permission, str], allowed: Permission,
            simulated: bool = False) -> dict[Permission, str]:
    """The entries of ``needs`` ({Permission: reason}) that ``allowed`` (and a simulator's
    waiver) does not cover."""
    have = allowed | waived(simulated)
    return {p: why for p, why in needs.items() if not p & have}


def as_permission(value: AllowSpec) -> Permission:
    """``allow=`` as given: a :class:`Permission`, ``True`` (everything), ``False``/``None``
    (nothing), or an iterable of permissions or their names (``["stored", "identity"]``)."""
    if value is None or value is False:
        return Permission.NONE
    if value is True:
        return ALL
    if isinstance(value, Permission):
        return value
    if isinstance(value, str):
        value = [value]
    out = Permission.NONE
    for v in value:
        if isinstance(v, Permission):
            out |= v
            continue
        key = str(v).strip().upper().replace("-", "_").replace(" ", "_")
        try:
            out |= Permission[key]
        except KeyError:
            from ..errors import unknown_name

            raise unknown_name("allow", v, [p.name.lower() for p in members(ALL)], noun="permission",
                               cls=FieldValueError) from None
    return out


def require(needs: Mapping[Permission, str], allowed: Permission, *, simulated: bool = False,
            what: str = "the frame", frame: bytes = b"") -> None:
    """Raise :class:`zkzap.errors.PermissionNeeded` (nothing may be sent) when ``needs``
    ({Permission: reason}) holds a permission that ``allowed`` does not give and the port does
    not waive (a simulator waives :data:`CONSENT`)."""
    lacking = missing(needs, allowed, simulated)
    if not lacking:
        return
    from ..errors import PermissionNeeded

    gone = Permission.NONE
    for p in lacking:
        gone |= p
    needed = Permission.NONE
    for p in needs:
        needed |= p
    names = " and ".join(p.name for p in lacking)
    why = "; ".join(lacking.values())
    raise PermissionNeeded(f"not sent: {what} needs permission {names} ({why})", missing=gone, needed=needed,
                           reasons=lacking, frame=bytes(frame), simulated=simulated)
