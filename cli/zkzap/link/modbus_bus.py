"""Modbus RTU transactions with mightyZAP 17Lf actuators, on the IR bus's discipline.

:class:`ModbusBus` is a :class:`~zkzap.link.zap_bus.ZapBus` whose protocol family is Modbus
RTU (:class:`ModbusFamily`): the same timing policy (nothing transmitted while a reply may still
be due, one attempt one window, the learned latency per actuator), the same attribution of
late, stray and garbled bytes, the adapter's echo recognised and skipped, retries, permissions
and captures. What is Modbus's own:

- **One outstanding request**, and **3.5 characters of silence** before every request
  (:func:`zkzap.codec.modbus.silence`: 3.5 x 11 bits, 1.75 ms above 19200 baud) after the last
  byte on the line, sent or received.
- **Every unicast request is answered** (broadcast ID 0 never): a reply or an exception reply.
  An exception reply is :class:`~zkzap.codec.modbus.ExceptionReply` (exit 5), a named error
  with its code and meaning; a reply with another function is a
  :class:`~zkzap.codec.modbus.ReplyMismatch` (``wrong-function``); another ID, a bad CRC, a short
  frame are the bus's BadReply kinds, never a value.
- **Writes go as Write Multiple Registers** (0x10), one frame for a run of adjacent registers:
  its reply (``ID 10 start count``) cannot be mistaken for the adapter's echo, which a Write
  Single Register's reply (an echo of the request) can. A 0x06 frame given to :meth:`command`
  is waited for like the IR protocol's Restart (its reply is a copy: the whole window, copies
  counted against the known echo).
"""

from __future__ import annotations

import time

from ..codec import modbus
from ..codec.framing import RtuFramer
from ..codec.permissions import as_permission, require
from ..codec.regmap import RegisterMap, default_map
from ..errors import UsageError
from .zap_bus import Reply, ZapBus

__all__ = ["ModbusBus", "ModbusFamily", "ModbusReply"]


class ModbusReply(Reply):
    """A checked Modbus reply: ``ident``, ``error`` (the exception code, 0 for a normal reply),
    ``data`` (the bytes between function and CRC), ``packet``, ``rtt``, ``latency``;
    :attr:`function` and :attr:`values` (a read's registers)."""

    __slots__ = ()

    @property
    def function(self) -> int:
        return self.packet[1] & 0x7F

    @property
    def exception(self) -> bool:
        return bool(self.packet[1] & modbus.EXCEPTION_BIT)

    @property
    def errors(self) -> list[str]:
        return [modbus.exception_name(self.error)] if self.error else []

    @property
    def values(self) -> list[int]:
        """The registers a read reply carries (big-endian words)."""
        d = self.data[1:]
        return [int.from_bytes(d[i:i + 2], "big") for i in range(0, len(d) - 1, 2)]

    @property
    def value(self) -> int:
        v = self.values
        return v[0] if len(v) == 1 else int.from_bytes(self.data, "big")

    def __repr__(self) -> str:
        return f"ModbusReply(id={self.ident}, function=0x{self.packet[1]:02x}, data={self.data.hex(' ')})"


class ModbusFamily:
    """Modbus RTU's answers to what the bus's transactions ask of a protocol family (see
    :class:`zkzap.link.zap_bus.IrFamily`), against a register map."""

    name = "modbus"
    BROADCAST = modbus.BROADCAST
    #: Bytes of a reply besides its data: ID, function, CRC.
    OVERHEAD = 4
    framer = RtuFramer

    def __init__(self, regmap: RegisterMap) -> None:
        self.regmap = regmap

    @staticmethod
    def ident(p) -> int:
        return p[0]

    @staticmethod
    def is_request(p) -> bool:
        return modbus.frame_kind(p) == "request" and p[1] != modbus.WRITE_SINGLE

    @classmethod
    def fits(cls, p, data_len) -> bool:
        return data_len is None or len(p) - cls.OVERHEAD == data_len or modbus.is_exception(p)

    @staticmethod
    def restarts(pkt) -> bool:
        return False

    def stored(self, pkt) -> bool:
        req = modbus.Request(pkt)
        return any(self.regmap.owner.get(a) is not None and self.regmap.owner[a].stored
                   for addr, values in req.blocks() for a in range(addr, addr + len(values)))

    @staticmethod
    def copy_reply(pkt) -> bool:
        return pkt[1] == modbus.WRITE_SINGLE

    @staticmethod
    def ack_len(pkt):
        """Data bytes of a write's reply: its address and count (or value), 4."""
        return 4

    @staticmethod
    def cut_short(tail: bytes) -> bool:
        return True

    @staticmethod
    def reply(p, rtt, latency, copy=False):
        p = bytes(p)
        error = p[2] if modbus.is_exception(p) else 0
        return ModbusReply(p[0], error, p[2:-2], p, rtt, latency)

    # -- what a scan asks (zkzap.link.zap_scan) ------------------------------------------------------

    #: A scan's probe (a one-register read: 8 bytes; its reply 7).
    PROBE_LEN = 8

    def probe(self, ident):
        """``(request, data_len)`` asking only whether ``ident`` answers: a read of the map's first
        register (Modbus RTU has no Echo)."""
        return modbus.read_registers(ident, self.regmap.registers[0].address, 1), 3

    def _run(self, *names):
        """``(address, count)`` of the adjacent registers ``names`` that the map has, from the first."""
        regs = [self.regmap.by_name.get(n) for n in names]
        first = regs[0] if regs[0] is not None else self.regmap.registers[0]
        count = 1
        for r in regs[1:]:
            if r is None or r.address != first.address + count:
                break
            count += 1
        return first.address, count

    def info_request(self, ident):
        """``(request, data_len)``: model-number and firmware-version (the map's first register
        where it has no model-number)."""
        address, count = self._run("model-number", "firmware-version")
        return modbus.read_registers(ident, address, count), 1 + 2 * count

    def info_values(self, reply) -> dict:
        values = [] if reply.exception else reply.values
        names = [n for n in ("model-number", "firmware-version") if n in self.regmap.by_name]
        got = dict(zip(names, values))
        return {"model": got.get("model-number"), "firmware": got.get("firmware-version"), "return_mode": None}

    def live_request(self, ident):
        address, count = self._run("present-position", "present-current")
        return modbus.read_registers(ident, address, count), 1 + 2 * count


class ModbusBus(ZapBus):
    """Transactions with Modbus RTU actuators on one port (see the module's description).
    ``regmap`` is the actuators' register map (default: the 17Lf's)."""

    def __init__(self, port, *, regmap: RegisterMap = None, **kw):
        self.family = ModbusFamily(regmap or default_map("modbus"))
        super().__init__(port, return_mode=2, **kw)
        self._line_free = 0.0               # when the last byte on the line (sent or received) ended

    @property
    def regmap(self) -> RegisterMap:
        return self.family.regmap

    # -- the line: 3.5 characters of silence before every request ---------------------------------

    def _read(self, n: int, deadline: float) -> bytes:
        data = super()._read(n, deadline)
        if data:
            self._line_free = time.monotonic()
        return data

    def _write(self, pkt: bytes) -> float:
        self._drain()
        wait = self._line_free + modbus.silence(self.baud) - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        t0 = super()._write(pkt)
        self._line_free = max(self._line_free, t0 + self.wire(len(pkt)))
        return t0

    # -- what a request gets ------------------------------------------------------------------------

    def expects_reply(self, pkt: bytes, return_mode=None) -> bool:
        return pkt[0] != modbus.BROADCAST

    def mode_dependent(self, pkt: bytes) -> bool:
        return False

    def authorize(self, pkt: bytes, allow=None) -> None:
        req = modbus.Request(pkt)
        needs = req.needs(self.regmap)
        if needs:
            require(needs, self.allow | as_permission(allow), simulated=self.simulated,
                    what=req.describe(self.regmap), frame=pkt)

    def command(self, pkt: bytes, *, check=True, optional=None, allow=None, retries=None, window=None):
        """Send any request frame (after its permissions) and wait for its reply (None for a
        broadcast). An exception reply raises :class:`~zkzap.codec.modbus.ExceptionReply`
        unless ``check=False``; a reply with another function raises ReplyMismatch. ``window``:
        this transaction's late window (a player's read that must end before its next step)."""
        pkt = bytes(pkt)
        self.authorize(pkt, allow)
        req = modbus.Request(pkt)
        want = req.reply_length()
        kw = {"data_len": None if want is None else want - ModbusFamily.OVERHEAD}
        if req.writes and req.address is not None:
            ids = self.regmap.by_name.get("id")
            if ids is not None and req.address <= ids.address < req.address + req.count:
                kw["accept_ids"] = {pkt[0], req.values[ids.address - req.address]}
        if optional is not None:
            kw["optional"] = optional
        if window is not None:
            kw["window"] = window
        reply = self.transact(pkt, check=False, retries=retries, **kw)
        if reply is None:
            return None
        if reply.exception:
            if check:
                raise modbus.ExceptionReply(reply.ident, req.function, reply.error)
            return reply
        if reply.function != req.function:
            raise modbus.ReplyMismatch("wrong-function", f"ID {reply.ident}: a reply with function "
                                       f"0x{reply.function:02X} to a request with 0x{req.function:02X}",
                                       ident=reply.ident, function=reply.function, protocol="modbus")
        return reply

    # -- registers ----------------------------------------------------------------------------------

    def read_values(self, ident: int, address: int, count: int = 1, **kw) -> list[int]:
        """``count`` registers from ``address`` (one Read Holding Registers)."""
        return self.command(modbus.read_registers(ident, address, count), **kw).values

    def read_registers(self, ident: int, address: int, count: int = 1, **kw):
        """(Reply, [(Register, raw), ...]): the registers of one read, named by the map."""
        reply = self.command(modbus.read_registers(ident, address, count), **kw)
        values = reply.values if not reply.exception else []
        out = []
        for i, v in enumerate(values):
            reg = self.regmap.by_address.get(address + i)
            out.append((reg if reg is not None else _anonymous(address + i), v))
        return reply, out

    def read_block(self, ident: int, address: int, count: int, **kw):
        """(Reply, [(Register, raw), ...]): ``count`` registers from ``address`` (a watch's read)."""
        return self.read_registers(ident, address, count, **kw)

    def read(self, ident: int, reg, **kw) -> int:
        return self.read_values(ident, self.regmap.register(reg).address, 1, **kw)[0]

    def write_frames(self, ident: int, values, *, force: bool = False) -> list[bytes]:
        """The frames writing ``values`` ({register: value}): one Write Multiple Registers per
        run of adjacent registers (checked against the map before anything is sent)."""
        return modbus.write_frames(ident, values, self.regmap, force=force)

    def write(self, ident: int, values, *, force: bool = False, **kw):
        """Write ``values`` ({register: value}); every frame's permissions are checked before the
        first goes out. Returns the replies (None for a broadcast)."""
        frames = self.write_frames(ident, values, force=force)
        for f in frames:
            self.authorize(f, kw.get("allow"))
        return [self.command(f, **kw) for f in frames]

    def store(self, ident: int, reg, value: int, *, force=False, **kw):
        return self.write(ident, {self.regmap.register(reg).name: value}, force=force, **kw)[0]

    # -- presence -----------------------------------------------------------------------------------

    def ping(self, ident: int, *, timeout=None, retries=0, quick=False, early=False, window=None):
        """A read of register 0 (the model number) that returns None when nothing answers; an
        exception reply is an answer too (somebody is there)."""
        probe, n = self.family.probe(ident)
        return self.transact(probe, reply=True, data_len=n, timeout=timeout,
                             retries=retries, optional=True, check=False, quick=quick, early=early, window=window)

    def echo(self, ident: int, *, retries=None, **kw):
        """:meth:`ping`, whose silence is :class:`~zkzap.errors.NoReply` (the connection check)."""
        r = self.ping(ident, retries=self.retries if retries is None else retries)
        if r is None:
            from ..errors import NoReply

            raise NoReply(f"no reply from ID {ident} at {self.baud} baud within {self.window * 1000:.1f} ms",
                          ident=ident, baud=self.baud, protocol="modbus")
        return r

    def detect_return_mode(self, ident: int) -> int:
        return 2                            # a Modbus actuator answers every unicast request

    def _not_modbus(self, what):
        raise UsageError(f"{what}: an IR protocol instruction; Modbus RTU has no such function", protocol="modbus")

    def load(self, ident, address, length, **kw):
        self._not_modbus("load data")

    def send_data(self, *a, **kw):
        self._not_modbus("send data")

    def execute(self, *a, **kw):
        self._not_modbus("execution")

    def restart(self, *a, **kw):
        self._not_modbus("restart (no source gives the 17Lf's restart an address)")

    def factory_reset(self, *a, **kw):
        self._not_modbus("factory reset (no source gives the 17Lf's factory reset an address)")

    def symmetric_store(self, reg, targets, *, allow=None, **kw):
        """One register of several actuators (``targets``: (ID, value) pairs): Modbus RTU has no
        multi-actuator write, so one Write Multiple Registers per ID
        (:func:`zkzap.codec.modbus.sync_frames`), every frame's permissions checked before the
        first goes out. Returns the replies."""
        frames = modbus.sync_frames(self.regmap.register(getattr(reg, "name", reg)).name, list(targets), self.regmap)
        for f in frames:
            self.authorize(f, allow)
        return [self.command(f, allow=allow) for f in frames]


def _anonymous(address):
    from ..codec.regmap import Register

    return Register(address, str(address), 2, "R", help="not in the map", documented=False, byteorder="big")
