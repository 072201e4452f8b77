"""Safe ends and confirmed writes on a mightyZAP bus (no click: the commands only report).

- :func:`stop_where_it_is` stops a moving rod at once: its goal position becomes its present
  position (what ``zap move --wait`` does on Ctrl-C or SIGTERM).
- :func:`written` and :func:`verify_writes` read back what Store Data or Symmetric Store packets
  wrote. Outside feedback-return-mode 2 a write is never acknowledged, so on a port with nothing
  attached it "succeeds" silently; a read-back is the only confirmation.
"""

from __future__ import annotations

from ..codec import zap
from ..errors import CheckFailed, NoReply, UsageError

POSITION = zap.REGISTER_BY_NAME["goal-position"]
PRESENT = zap.REGISTER_BY_NAME["present-position"]
STORE = zap.INSTRUCTION_BY_NAME["store"].code
SYMMETRIC = zap.INSTRUCTION_BY_NAME["sync-move"].code
#: Registers a read-back at the same ID and baud cannot confirm (the actuator moves away).
UNVERIFIABLE = tuple(zap.REGISTER_BY_NAME[n].address for n in ("id", "baud-rate"))


def stop_where_it_is(bus, ident: int) -> int:
    """Make actuator ``ident`` stop now: read its present position and store it as the goal.
    Returns that position. Raises NoReply/BadReply/PortError like any transaction."""
    pos = bus.read(ident, PRESENT)
    bus.store(ident, POSITION, pos)
    return pos


def written(pkt: bytes) -> list:
    """``[(ident, address, data)]`` that a Store Data or Symmetric Store packet writes (one
    entry per addressed actuator; an empty list for any other packet)."""
    code, ident, params = pkt[5], pkt[3], bytes(pkt[6:-1])
    if code == STORE and params:
        return [(ident, params[0], params[1:])]
    if code == SYMMETRIC and len(params) >= 2:
        address, length = params[0], params[1]
        body = params[2:]
        return [(body[i], address, body[i + 1:i + 1 + length]) for i in range(0, len(body), 1 + length)
                if length]
    return []


def check_verifiable(packets) -> None:
    """Refuse ``--verify`` (exit 2, before anything is sent) where a read-back cannot work."""
    targets = [w for p in packets for w in written(p)]
    if not targets:
        raise UsageError("verify: only Store Data and Symmetric Store writes can be read back")
    for ident, address, _ in targets:
        if ident == zap.BROADCAST:
            raise UsageError("verify: a broadcast write cannot be read back; give the actuator's ID")
        if address in UNVERIFIABLE:
            name = zap.REGISTER_BY_ADDRESS[address].name
            raise UsageError(f"verify: {name} changes where the actuator answers; 'zap set-id' and "
                             f"'zap set-baud' change it and verify")


def verify_writes(bus, packets) -> list:
    """Read back every value ``packets`` wrote. Returns ``[(ident, register name, value)]``.

    A missing reply is :class:`~zkzap.errors.NoReply` (the write is unconfirmed: nothing may be
    attached); a different value is :class:`~zkzap.errors.CheckFailed` (exit 1)."""
    out = []
    for pkt in packets:
        for ident, address, data in written(pkt):
            reg = zap.REGISTER_BY_ADDRESS.get(address)
            name = reg.name if reg is not None else f"0x{address:02X}"
            try:
                reply = bus.load(ident, address, len(data))
            except NoReply as e:
                raise NoReply(f"write of {name} to ID {ident} unconfirmed: no reply to the read-back ({e})") from None
            got = bytes(reply.data[:len(data)])
            want = int.from_bytes(data, "little")
            value = int.from_bytes(got, "little")
            if got != bytes(data):
                raise CheckFailed(f"ID {ident}: {name} reads back {value}, not the {want} written")
            out.append((ident, name, value))
    return out


class interrupted_move:
    """``with interrupted_move(bus, ident):`` around a wait for a move: on Ctrl-C or SIGTERM
    (KeyboardInterrupt) the rod is stopped where it is (``stop``), ``notify`` says what
    happened (``why_not``: what to add when it was told not to stop), :attr:`stopped_at` keeps
    that position, and the interruption goes on (exit 130/143)."""

    def __init__(self, bus, ident, *, stop=True, notify=None, why_not=""):
        self.bus, self.ident, self.stop, self.why_not = bus, ident, stop, why_not
        self.notify = notify or (lambda message: None)
        self.stopped_at = None
        """The position the rod was stopped at (None unless it was)."""

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        if kind is None or not issubclass(kind, KeyboardInterrupt):
            return False
        if not self.stop:
            self.notify(f"interrupted: ID {self.ident} keeps moving to its goal{self.why_not}")
            return False
        from ..errors import ZkzapError

        try:
            pos = stop_where_it_is(self.bus, self.ident)
        except ZkzapError as e:
            self.notify(f"interrupted: could not stop ID {self.ident}: {e}")
            return False
        self.stopped_at = pos
        self.notify(f"interrupted: ID {self.ident} stopped at {pos} (goal-position set to the present position)")
        return False
