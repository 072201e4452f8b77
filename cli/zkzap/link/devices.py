"""What a bus knows of each device on it: one :class:`Device` per address, never one for the bus.

A half-duplex bus with many devices (mightyZAP actuators on the IR protocol, the same actuators
over Modbus RTU) keeps some facts per device that the framing does not carry: how it answers
(a mightyZAP's feedback-return mode), the line speed it was last heard at, and what the bus
asked it that has not been answered yet. A fact learned of one device (one actuator told to
answer every command) says nothing of another: the bus keeps it on that device's record, and
:attr:`Devices.default` stands for what is assumed of a device nothing was learned of.

The latency learned of each device lives in the port's
:class:`~zkzap.link.zap_timing.Policy` (shared by every bus on that port in one process); a
device's record refers to it by address.

Nothing here imports pyserial; nothing here knows a framing.
"""

from __future__ import annotations

from typing import Optional

__all__ = ["Device", "Devices", "ByBaud"]


class Device:
    """One device on a bus: ``ident`` (its address), ``return_mode`` (how it answers, as
    learned: None until the bus learned it, then the device's own), ``baud`` (the line speed it
    last answered at, None before), ``late`` (replies that came after their attempt's window),
    ``doubts`` (replies the bus could not attribute with certainty: never taken for an
    answer), ``extra`` (replies with its address that no request was owed: two where one
    was due, from two devices sharing the address or a line fault), ``replies`` (every
    reply with its address heard, however it was attributed) and ``asked`` (every request sent
    to its address that a device could answer). One device never gives more replies than it
    was asked: once ``replies`` exceeds ``asked`` (:attr:`shared`), two devices answer to the
    address (or one sent a reply twice), and no reply of it can be told to answer the request
    it came after, whatever order they came in."""

    __slots__ = ("ident", "return_mode", "baud", "late", "doubts", "extra", "extra_at", "replies", "asked",
                 "shared")

    def __init__(self, ident: int) -> None:
        self.ident = ident
        self.return_mode: Optional[int] = None
        self.baud: Optional[int] = None
        self.late = 0
        self.doubts = 0
        self.extra = 0
        self.replies = 0
        self.extra_at: Optional[float] = None    # when the last of those came
        self.asked = 0
        self.shared = False                      # more replies heard than requests sent (see above)

    def heard(self) -> None:
        """A reply with this address was heard (however it is attributed)."""
        self.replies += 1
        if self.replies > self.asked:
            self.shared = True

    def cleared(self) -> None:
        """A census found exactly one device at this address: what was counted before it is
        settled (every reply owed has come or can no longer come)."""
        self.shared = False
        self.asked = self.replies

    def __repr__(self) -> str:
        return (f"Device(id={self.ident}, return_mode={self.return_mode}, baud={self.baud}, "
                f"late={self.late}, doubts={self.doubts}, extra={self.extra}, "
                f"replies={self.replies}/{self.asked}{', shared' if self.shared else ''})")


class Devices:
    """The devices of one bus by address. ``default`` is the return mode assumed of a device
    whose own was never learned (the bus's ``return_mode`` setting)."""

    __slots__ = ("_by_id", "default")

    def __init__(self, default: int = 1) -> None:
        self._by_id: dict[int, Device] = {}
        self.default = default

    def __getitem__(self, ident: int) -> Device:
        dev = self._by_id.get(ident)
        if dev is None:
            dev = self._by_id[ident] = Device(ident)
        return dev

    def get(self, ident: int) -> Optional[Device]:
        return self._by_id.get(ident)

    def __iter__(self):
        return iter(sorted(self._by_id.values(), key=lambda d: d.ident))

    def __len__(self) -> int:
        return len(self._by_id)

    def mode(self, ident: int) -> int:
        """The return mode of ``ident``: its own when learned, else :attr:`default`."""
        dev = self._by_id.get(ident)
        if dev is None or dev.return_mode is None:
            return self.default
        return dev.return_mode

    def learn_mode(self, ident: int, mode: int, broadcast: Optional[int] = None) -> None:
        """``ident`` answers in ``mode`` now; ``broadcast`` (its address): every device does, and
        the default becomes ``mode``."""
        if broadcast is not None and ident == broadcast:
            self.default = mode
            for dev in self._by_id.values():
                dev.return_mode = mode
            return
        self[ident].return_mode = mode

    def moved(self, old: int, new: int) -> None:
        """The device at ``old`` now answers at ``new`` (an ID change): its record goes along,
        and nothing is known any more of ``old``."""
        dev = self._by_id.pop(old, None)
        self._by_id.pop(new, None)
        if dev is not None:
            dev.ident = new
            self._by_id[new] = dev
            # a late reply to what was asked of it at the old address is still one it owed
            self[old].asked = max(0, dev.asked - dev.replies)

    def forget(self, ident: int) -> None:
        self._by_id.pop(ident, None)

    def take(self, ident: int) -> Optional[Device]:
        """The record of ``ident``, removed (a device that moved to another line speed)."""
        return self._by_id.pop(ident, None)

    def put(self, dev: Device) -> None:
        """Keep ``dev`` (a record taken from another line speed's) under its address."""
        self._by_id[dev.ident] = dev


class ByBaud:
    """The devices of one port at each line speed: devices at different baud rates never hear
    each other's line, so one address can be two devices (one at each rate), each with its own
    facts. :attr:`current` is the :class:`Devices` of the rate the port is at."""

    __slots__ = ("current", "baud", "_other")

    def __init__(self, current: Devices, baud: Optional[int]) -> None:
        self.current, self.baud = current, baud
        self._other: dict = {}

    def switch(self, baud: int) -> Devices:
        """The port is at ``baud`` now: its devices (a fresh record where nothing was learned at
        that rate, assuming what the others assume)."""
        if baud != self.baud:
            self._other[self.baud] = self.current
            self.current = self._other.pop(baud, None) or Devices(self.current.default)
            self.baud = baud
        return self.current

    def at(self, baud: int) -> Devices:
        """The devices at ``baud`` (created when none were)."""
        if baud == self.baud:
            return self.current
        found = self._other.get(baud)
        if found is None:
            found = self._other[baud] = Devices(self.current.default)
        return found

    def bauds_of(self, ident: int) -> list:
        """The baud rates at which a device with ``ident`` answered (learned on this port)."""
        out = []
        for baud, devs in [(self.baud, self.current), *self._other.items()]:
            dev = devs.get(ident)
            if dev is not None and dev.baud == baud:
                out.append(baud)
        return sorted(out)
