"""mightyZAP transactions: send a packet, wait for exactly the feedback the actuator will give.

Which commands are answered depends on the actuator's feedback-return mode (register 0x10):
0 answers Echo only; 1 (the default) Load Data and Echo; 2 every command; a broadcast (ID 254)
never. The mode is an actuator's own: :attr:`ZapBus.devices` keeps one
:class:`~zkzap.link.devices.Device` per ID with the mode learned of it (read by a scan's
identification or :meth:`ZapBus.detect_return_mode`, or written by this bus), and
``return_mode`` (default 1) is only what is assumed of an actuator nothing was learned of. The
bus waits only when a reply will come.

Every transaction follows the bus's one timing policy (:mod:`zkzap.link.zap_timing`):

- **Nothing is transmitted while a reply may still be due.** Before every write the bus
  listens until the late window of everything sent before has closed (and the memory pause
  after a stored write, the quiet time after a restart, have passed); a write that an actuator
  in another return mode might acknowledge anyway keeps the line for that actuator's learned
  latency. Only a scan's first pass moves on early (``early=True``).
- **One attempt, one window.** An attempt waits for its reply until the late window
  (:data:`~zkzap.link.zap_timing.LATE_WINDOW`, 150 ms; ``timeout`` replaces it) has closed
  after the request's last byte, plus the reply's time on the wire and the host margin. A
  reply that comes ends the wait at once: the window costs time only when nothing comes. Once
  reply bytes arrive the wait extends to :data:`~zkzap.link.zap_timing.INTER_BYTE` (or 4x the
  variation learned of the actuator's latency, when larger: a jittery adapter) after the
  latest one while a packet is incomplete (devices and adapters that trickle their bytes). A
  retry goes out only after the window of the attempt before it has closed, so a late reply is
  always the answer to the attempt it answers, and its round trip (:attr:`Reply.rtt`) is true.
- **Learned latency.** Every answer is a latency sample of its actuator (the time from the
  request's last byte leaving to the first reply byte, as the host sees it); the estimators
  live in the port's :class:`~zkzap.link.zap_timing.Policy`, shared by every bus on that port
  in this process. A reply after its actuator's learned timeout is counted late.
- **Attribution.** Bytes that arrive between transactions are read and examined, never thrown
  away unseen: a reply to an attempt whose window is open (a scan's quick probe) or closed
  only lately is that attempt's, counted late and reported as an event (for scans), never the
  answer to another request; acknowledgements nobody waited for are skipped; bytes that make no
  packet are reported as garbled (a collision or a line fault).

Every reply is checked: checksum (through :class:`~zkzap.codec.framing.ZapFramer`), ID, data
length. A half-duplex adapter that echoes our own bytes is recognised (a copy of what we sent)
and the copy skipped. A failed attempt is retried ``retries`` times; then the failure is raised
as :class:`~zkzap.errors.NoReply` (exit 3), :class:`~zkzap.errors.BadReply` (exit 6; a garbled
reply is named a collision or line fault); error bits in a reply as
:class:`~zkzap.errors.DeviceError` (exit 5, the reply attached as ``.reply``); a port that fails
or vanishes as :class:`~zkzap.errors.PortError` (exit 4).

Permissions: every command packet goes through :meth:`ZapBus.command`, which sends it only when
the permissions it needs (:meth:`zkzap.codec.zap.Command.needs`) are given: the bus's
:attr:`ZapBus.allow` or the call's ``allow=``; a simulated port (:func:`is_simulated`) gives the
consent permissions by itself. Otherwise :class:`~zkzap.errors.PermissionNeeded` (exit 2), and
nothing is sent.
"""

from __future__ import annotations

import os
import select
import sys
import time
from collections import deque
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from typing import Optional

from ..codec import zap
from ..codec.framing import ZapFramer
from ..codec.permissions import Permission, as_permission, require
from ..errors import BadReply, DeviceError, NoReply, OutputError, PortError, UsageError
from . import stop
from .devices import ByBaud, Devices
from .port import close_port, wire_time
from .zap_timing import (FLOOR, HORIZON, K, INTER_BYTE, LATE_WINDOW, MARGIN, NETWORK_MARGIN, NV_PAUSE,
                         QUICK_MARGIN, RESTART_PAUSE, RETRIES, RETRY_GRACE, horizon_for, host_margin, policy_for, usb_latency,
                         window_for)

__all__ = ["ZapBus", "Reply", "open_bus", "device_error", "error_message", "stored_writes", "leaves_protocol",
           "is_simulated", "host_margin", "usb_latency", "wire_time", "FLOOR", "INTER_BYTE",
           "LATE_WINDOW", "MARGIN", "NETWORK_MARGIN", "NV_PAUSE", "QUICK_MARGIN", "RESTART_PAUSE", "RETRIES"]

#: Read granularity on ports without a file descriptor (URL ports).
QUANTUM = 0.001
#: The most a read of a serial port's descriptor takes at once (a reply is at most 255 bytes).
READ_CHUNK = 4096
#: How long after its window closed a reply is still recognised as the answer of an old attempt
#: (and never taken for another's), as a multiple of the window.
MEMORY = 2.0
#: Spare time: work handed to :meth:`ZapBus.spare` starts after a write only within this share of
#: the request's own time on the wire. No reply byte can come before the request has crossed the
#: line, so work done by then delays nothing; work that runs past it (a blocked output) makes the
#: reply's latency unknown (not learned), never longer.
SPARE_SHARE = 0.5
#: Garbled bytes and collisions kept for scans (events), at most.
MAX_EVENTS = 4096
#: How long what an identity change left known (:meth:`ZapBus.heard_out`) answers a census, if
#: nothing is sent meanwhile (seconds): the change that undoes it asks nothing again.
HEARD_OUT = 2.0
#: Instructions that write nothing.
_READS = (zap.ECHO, zap.LOAD_DATA)


#: Instructions that never need a permission (they write nothing by themselves).
_FREE = frozenset((zap.ECHO, zap.LOAD_DATA, zap.EXECUTION, zap.RESTART))


def is_simulated(url) -> bool:
    """True for ports where nothing real can be harmed: the in-process simulator and loop://."""
    return bool(url) and str(url).startswith(("sim://", "loop://"))


#: Why a reply marked :attr:`Reply.doubt` may not answer the request it came after.
DOUBT = "it may answer an earlier request that went unanswered in its window"


#: Why a reply of an ID that lately sent replies where none was due is marked :attr:`Reply.doubt`.
TWICE = "its ID lately sent a reply where none was due: it may be another actuator's"


class Reply:
    """A checked feedback packet: ``ident``, ``error`` (bits), ``data`` (parameter bytes),
    ``packet`` (the whole packet), ``rtt`` (seconds from just before the write of the attempt it
    answers to the reply's last byte read) and ``latency`` (seconds from the request's last byte
    leaving to the reply's first byte read: what the actuator and the adapter took; None when
    not measured). ``doubt`` is None for the answer to this very request, else why it may
    answer an earlier one (only where any reply of the ID will do: whether an ID answers at all;
    its ``rtt`` is then not that request's)."""

    __slots__ = ("ident", "error", "data", "packet", "rtt", "latency", "doubt")

    def __init__(self, ident: int, error: int, data: bytes, packet: bytes, rtt: float = 0.0,
                 latency: Optional[float] = None, doubt: Optional[str] = None) -> None:
        self.ident, self.error, self.data, self.packet, self.rtt = ident, error, data, packet, rtt
        self.latency = latency
        self.doubt = doubt

    @property
    def errors(self) -> list[str]:
        """The names of the error bits set (``overload``, ``input-voltage``)."""
        return zap.error_names(self.error)

    @property
    def value(self) -> int:
        """The parameter bytes as one little-endian integer."""
        return int.from_bytes(self.data, "little")

    def __repr__(self) -> str:
        return f"Reply(id={self.ident}, error=0x{self.error:02x}, data={self.data.hex(' ')})"


def error_message(reply: Reply) -> str:
    texts = [zap.ERROR_TEXT.get(n, n) for n in reply.errors]
    return f"ID {reply.ident} reports error 0x{reply.error:02X}: " + "; ".join(texts)


def device_error(reply: Reply) -> DeviceError:
    """The :class:`DeviceError` for a reply with error bits (``reply``, ``ident``, ``errors`` attached)."""
    return DeviceError(error_message(reply), reply=reply, ident=reply.ident, errors=reply.errors)


def stored_writes(pkt: bytes) -> list:
    """Names of the stored (NV) settings a command packet writes (see :class:`zap.Command`)."""
    return zap.Command(pkt).stored_writes


def leaves_protocol(pkt: bytes) -> bool:
    """True when the packet writes 0 (Modbus RTU) to protocol-type (see :class:`zap.Command`)."""
    return zap.Command(pkt).leaves_protocol


class IrFamily:
    """What the bus's transactions need to know of the IR protocol's packets (the protocol
    family seam: :mod:`zkzap.link.modbus_bus` gives Modbus RTU's): how packets are framed, who
    sent one, whether it is a request, how long a reply of ``data_len`` data bytes is, whether
    a reply is a copy of its request."""

    name = "ir"
    regmap = zap.MAP
    BROADCAST = zap.BROADCAST
    #: Bytes of a reply besides its data (header, ID, SIZE, error, checksum).
    OVERHEAD = 7
    framer = ZapFramer

    @staticmethod
    def ident(p) -> int:
        return p[3]

    @staticmethod
    def is_request(p) -> bool:
        return zap.is_command(p[5])

    @classmethod
    def fits(cls, p, data_len) -> bool:
        """Whether ``p`` has the length of a reply of ``data_len`` data bytes (None: any)."""
        return data_len is None or len(p) - cls.OVERHEAD == data_len

    @staticmethod
    def restarts(pkt) -> bool:
        return pkt[5] in zap.RESTART_CODES

    @staticmethod
    def stored(pkt) -> bool:
        return pkt[5] not in _READS and bool(stored_writes(pkt))

    @staticmethod
    def copy_reply(pkt) -> bool:
        """Whether the reply is a copy of the request (Restart's feedback)."""
        return pkt[5] in zap.RESTART_CODES

    @staticmethod
    def ack_len(pkt):
        """Data bytes of the acknowledgement a write may get from an actuator in another return
        mode: none (a status packet), or None where it is a copy of the request (Restart)."""
        return None if pkt[5] in zap.RESTART_CODES else 0

    @staticmethod
    def cut_short(tail: bytes) -> bool:
        """Whether bytes held at the end look like the start of a reply (not line noise)."""
        return tail.startswith(b"\xff")

    @staticmethod
    def reply(p, rtt, latency, copy=False):
        if copy:
            return Reply(p[3], 0, b"", p, rtt, latency)
        return Reply(p[3], p[5], p[6:-1], p, rtt, latency)

    # -- what a scan asks (zkzap.link.zap_scan) ------------------------------------------------------

    #: A scan's probe (Echo) and its reply, in bytes.
    PROBE_LEN = 7

    @staticmethod
    def probe(ident):
        """``(request, data_len)`` asking only whether ``ident`` answers: Echo."""
        return zap.echo(ident), 0
    _INFO = (zap.REGISTER_BY_NAME["model-number"], zap.REGISTER_BY_NAME["feedback-return-mode"])
    _LIVE = (zap.REGISTER_BY_NAME["present-position"], zap.REGISTER_BY_NAME["present-voltage"])

    @classmethod
    def info_request(cls, ident):
        """``(request, data_len)`` identifying an actuator: model number .. feedback-return-mode."""
        first, last = cls._INFO
        length = last.address + last.size - first.address
        return zap.load(ident, first.address, length), length

    @classmethod
    def info_values(cls, reply) -> dict:
        """``{"model", "firmware", "return_mode"}`` from the reply to :meth:`info_request`."""
        values = {reg.name: raw for reg, raw in zap._register_values(cls._INFO[0].address, reply.data)}
        return {"model": values.get("model-number"), "firmware": values.get("firmware-version"),
                "return_mode": values.get("feedback-return-mode")}

    @classmethod
    def live_request(cls, ident):
        """``(request, data_len)`` of live registers, which differ between two units with one ID."""
        first, last = cls._LIVE
        length = last.address + last.size - first.address
        return zap.load(ident, first.address, length), length


class _Owed:
    """An attempt whose reply has not come: it may still come until ``until`` (its window);
    before ``keep`` (its grace) nothing is sent whose reply could be taken for it; and until
    ``horizon`` a reply that fits it is recognised as possibly its, never taken for another
    request's answer. ``kind`` is ``reply`` (an expected reply) or ``ack`` (a write an actuator
    in another return mode may acknowledge)."""

    __slots__ = ("token", "ids", "data_len", "t0", "sent", "until", "keep", "horizon", "kind")

    def __init__(self, token, ids, data_len, t0, sent, until, keep, kind="reply", horizon=None):
        self.token, self.ids, self.data_len, self.t0, self.sent = token, ids, data_len, t0, sent
        self.until, self.keep, self.kind = until, keep, kind
        self.horizon = keep if horizon is None else max(keep, horizon)

    def matches(self, p, family=IrFamily) -> bool:
        return family.ident(p) in self.ids and family.fits(p, self.data_len)

    def conflicts(self, ids, data_len) -> bool:
        """Whether a reply to a request to ``ids`` carrying ``data_len`` bytes could be taken
        for this attempt's (or this one's for it): same ID, same length (or either unknown)."""
        return self.kind == "reply" and not self.ids.isdisjoint(ids) and (
            self.data_len is None or data_len is None or self.data_len == data_len)


class Event:
    """Something the bus heard that was not the answer in hand, for scans: ``kind`` ``late`` (a
    reply to an earlier attempt: ``ident``, ``t0`` of that attempt, ``packet``), ``stray`` (a
    reply nobody asked for), ``garbled`` (bytes that made no packet: a collision or a line
    fault; ``packet`` holds the bytes read with them); ``lo`` .. ``hi`` is when it arrived (from
    the last time nothing was waiting to the read)."""

    __slots__ = ("kind", "ident", "lo", "hi", "t0", "packet")

    def __init__(self, kind, ident, lo, hi, t0=None, packet=None):
        self.kind, self.ident, self.lo, self.hi, self.t0, self.packet = kind, ident, lo, hi, t0, packet

    def __iter__(self):                   # (kind, ident, time), as scans unpacked them
        return iter((self.kind, self.ident, self.hi))

    def __repr__(self):
        return f"Event({self.kind}, id={self.ident}, {self.lo:.4f}..{self.hi:.4f})"


class ZapBus:
    """Transactions on one port (of the protocol family :attr:`family`). ``return_mode`` is the feedback-return mode (0, 1, 2) assumed of
    an actuator whose own the bus has not learned (:attr:`devices`);
    ``timeout`` (seconds) replaces the late window; ``retries`` after a failure; ``latency``
    (seconds) is what the actuators are known to take before any was measured (``--latency``);
    ``margin`` replaces the host margin derived from the port."""

    #: The protocol family of the packets (see :class:`IrFamily`).
    family = IrFamily

    def __init__(self, port, *, return_mode: int = 1, timeout=None, retries: int = RETRIES, margin=None,
                 url=None, latency=None, policy=None):
        self.port = port
        # the port's own clock where it has a virtual one (a simulator whose time passes only
        # while the host waits), else the system's
        clock = getattr(port, "clock", None)
        self.virtual = bool(getattr(clock, "virtual", False))
        self.now = clock.now if self.virtual else time.monotonic
        self._sleep = clock.advance if self.virtual else time.sleep
        self.url = url if url is not None else getattr(port, "port", None) or getattr(port, "portstr", "")
        self.allow = Permission.NONE       # the permissions given to every command (see command())
        self.simulated = is_simulated(self.url)
        self.devices = Devices(return_mode)   # what is known of each actuator (see mode_of)
        self.by_baud = ByBaud(self.devices, getattr(port, "baudrate", None))   # ... at each line speed
        self.timeout = timeout
        self.retries = retries
        self.latency = latency
        self.policy = policy if policy is not None else policy_for(self.url, margin)
        if getattr(port, "baudrate", None) is not None:
            self.policy.switch(port.baudrate)      # the latencies learned at the port's rate
        self.adapter_echo = False          # learned: the adapter echoes what we send
        self.low_latency = None            # True/False: what --low-latency achieved (None: not asked)
        self._recent = deque(maxlen=8)     # packets we sent lately (their echoes are skipped)
        self._unechoed = {}                # write time -> packet, until its clean echo came back
        self._owed = deque()               # attempts whose reply may still come
        self._owed_at = {}                 # baud -> those of the other line speeds
        self._current = None               # the request in hand (the token of its attempts)
        self._caught = None                # its earlier attempt's reply, heard between attempts
        self._answer = None                # (packet, when read, writes by then): the last reply heard (_twin)
        self._spare = deque()              # work for the time a reply is on its way (spare())
        self._framer = self.family.framer()     # bytes read between transactions
        self._held = None                  # [lo, hi]: when the bytes the framer holds were read
        self._quiet_until = 0.0
        self._seen_empty = self.now()
        self._port_timeout = object()
        self._line = (None, 0.0)           # (baud, one byte's time on the line)
        fd = getattr(port, "fd", None)
        self._fd = fd if isinstance(fd, int) and hasattr(port, "in_waiting") else None
        # pyserial's own posix port (not a wrapper that sees what is read, as a capture's):
        # its descriptor is read directly
        posix = sys.modules.get("serial.serialposix")
        self._raw = self._fd is not None and posix is not None and type(port) is posix.Serial
        self.events = []                   # Event: late, stray and garbled, for scans
        self.noted = set()                 # what a scan says once per bus (its notes)
        self._heard_out = None             # (writes by then, when, {(baud, ID): census verdict})
        self.monitor = None                # monitor(direction "tx"/"rx", bytes): every write and read
        self.last_sent = 0.0               # when the last write began
        self.sent = 0
        self.replies = 0
        self.retried = 0
        self.late = 0                      # replies after their actuator's timeout, or to earlier attempts
        self.stale = 0                     # stray packets skipped (acknowledgements nobody waited for)
        self.garbled = 0                   # bursts of bytes that made no packet (collisions, line faults)

    # -- the actuators -----------------------------------------------------------------------

    @property
    def return_mode(self) -> int:
        """The feedback-return mode assumed of an actuator whose own was never learned."""
        return self.devices.default

    @return_mode.setter
    def return_mode(self, value: int) -> None:
        self.devices.default = int(value)

    def mode_of(self, ident: int) -> int:
        """The feedback-return mode of actuator ``ident``: learned, else :attr:`return_mode`."""
        return self.devices.mode(ident)

    # -- line -----------------------------------------------------------------------------------

    @property
    def baud(self) -> int:
        return self.port.baudrate

    @property
    def stop_bits(self) -> int:
        return int(getattr(self.port, "stopbits", 1) or 1)

    @property
    def margin(self) -> float:
        """The host margin added to every deadline (see :class:`~zkzap.link.zap_timing.Policy`)."""
        return self.policy.margin

    @property
    def window(self) -> float:
        """The late window: how long after a request's last byte its reply may begin (``timeout``,
        else :data:`~zkzap.link.zap_timing.LATE_WINDOW`, widened for a ``latency`` hint)."""
        return window_for(self.timeout, self.latency)

    def wire(self, nbytes: int) -> float:
        """Seconds ``nbytes`` take on the line at the port's baud rate and stop bits."""
        baud = self.port.baudrate
        if baud != self._line[0]:
            self._line = (baud, wire_time(1, baud, self.stop_bits))
        return nbytes * self._line[1]

    def set_baud(self, baud: int) -> None:
        """Switch the port's line speed, once nothing said at the old one may still be answered
        and what was sent has left."""
        self.quiet()
        was = self.port.baudrate
        if baud == was:
            return
        try:
            self.port.flush()
        except Exception:  # noqa: BLE001 - a port without tcdrain; the pause below covers it
            pass
        self._settle()
        try:
            self.port.baudrate = baud
        except (ValueError, OSError) as e:
            raise PortError(f"port {self.url}: cannot set {baud} baud: {e}") from None
        except Exception as e:  # serial.SerialException
            raise PortError(f"port {self.url}: cannot set {baud} baud: {e}") from None
        # what was said at the old speed is answered at it: those attempts are remembered with
        # it (a reply that comes after the host has switched back is still theirs), and none of
        # them is heard at the new one
        self._owed_at[was] = self._owed
        self._owed = self._owed_at.pop(baud, deque())
        self.devices = self.by_baud.switch(baud)   # the actuators at that rate (another ID 1 there)
        self.policy.switch(baud)                   # ... and their latencies
        self._expire(self.now())
        self._framer = self.family.framer()
        self._held = None

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` pass on the bus's clock (model time on a virtual simulator)."""
        if seconds > 0:
            self._sleep(seconds)

    def close(self) -> None:
        self.run_spare()
        close_port(self.port)

    def spare(self, task) -> None:
        """Run ``task()`` in the bus's next spare moment: right after a request has gone out,
        while its reply cannot have arrived yet (:data:`SPARE_SHARE`), or at :meth:`run_spare`.
        For work that must be done but not before the next transaction (a batch's output). A task
        keeps what it raises to itself: it runs inside a transaction."""
        self._spare.append(task)

    def run_spare(self) -> None:
        """Run the work handed to :meth:`spare` now, in order."""
        while self._spare:
            self._spare.popleft()()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def reply_timeout(self, tx_bytes: int, rx_bytes: int, extra: float = 0.0) -> float:
        """How long an attempt waits for its reply at most (from just before its write): both
        packets on the wire + the late window + the host margin + ``extra``."""
        return self.wire(tx_bytes + rx_bytes) + self.window + self.margin + extra

    def quick_timeout(self, tx_bytes: int, ident=None) -> float:
        """A scan's first-pass wait: our packet and the reply's first byte on the wire, plus
        :data:`~zkzap.link.zap_timing.QUICK_MARGIN` and, for an ID measured before, its own
        timeout (it is probably there: its reply must not meet the next probe), else the
        latency an unknown ID is allowed (see :meth:`zap_timing.Policy.quick`)."""
        wait = self.policy.measured(ident, self.window)
        if wait is None:
            wait = self.policy.quick(self.latency, self.window)
        return self.wire(tx_bytes + 1) + wait + QUICK_MARGIN

    def courtesy(self, ident: int, window=None) -> float:
        """How long the line stays quiet after a write the return mode does not answer: what
        ``ident`` was measured to take (its timeout), else the bus-typical allowance of a
        scan's first pass (an acknowledgement that an actuator set to another mode gives
        anyway must not meet the next request)."""
        window = self.window if window is None else window
        measured = self.policy.measured(ident, window)
        return measured if measured is not None else self.policy.courtesy(self.latency, window)

    def expects_reply(self, pkt: bytes, return_mode=None) -> bool:
        ins = zap.INSTRUCTION_BY_CODE.get(pkt[5])
        mode = self.devices.mode(pkt[3]) if return_mode is None else return_mode
        return ins is not None and ins.answered(mode, pkt[3])

    # -- reading ----------------------------------------------------------------------------------

    def _port_error(self, e) -> PortError:
        from .port import port_failed

        return port_failed(self.url, e)

    def _fd_failed(self, what: str, e: OSError) -> PortError:
        """The descriptor's ``what`` ("read", "write") failed: in pyserial's words, made plain."""
        return self._port_error(OSError(e.errno, f"{what} failed: [Errno {e.errno}] {e.strerror}"))

    def _set_timeout(self, value) -> None:
        if self._port_timeout != value:
            self.port.timeout = value
            self._port_timeout = value

    def _read(self, n: int, deadline: float) -> bytes:
        """Bytes received by ``deadline`` (returns as soon as some are there; at most ``n`` on
        ports read by size). Past the deadline it still returns what is already waiting: a host
        held up (a loaded machine) must not take a reply that arrived meanwhile for silence.
        Keeps :attr:`_seen_empty`, the last time nothing was waiting."""
        try:
            if self._fd is not None:
                self._set_timeout(0)
                left = deadline - self.now()
                ready, _, _ = select.select([self._fd], [], [], max(0.0, left))
                if not ready:
                    self._seen_empty = self.now()
                    return b""
                data = self._read_fd() if self._raw else self.port.read(max(1, self.port.in_waiting))
            else:
                left = deadline - self.now()
                before = self.now()
                # (on a virtual clock a read moves time on by what it waits: never by less than a
                # nanosecond, which a float could round away)
                self._set_timeout((max(left, 1e-9) if self.virtual else QUANTUM) if left > 0 else 0)
                data = self.port.read(n)
                if not data:
                    self._seen_empty = before
            if data and self.monitor is not None:
                self.monitor("rx", data)
            return data
        except Exception as e:
            if isinstance(e, (KeyboardInterrupt, PortError, OutputError)):   # OutputError: the capture's
                raise
            raise self._port_error(e) from None

    def _read_fd(self) -> bytes:
        """Everything waiting on a serial port's descriptor, in one read (what pyserial's read of
        ``in_waiting`` bytes does, without its ioctl, select and timer on every call), with its
        words for a port that fails or went away."""
        try:
            data = os.read(self._fd, READ_CHUNK)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError as e:
            raise self._fd_failed("read", e) from None
        if not data:
            raise self._port_error(Exception("device reports readiness to read but returned no data "
                                             "(device disconnected or multiple access on port?)"))
        return data

    def _write_fd(self, pkt: bytes) -> None:
        """``pkt`` to a serial port's descriptor in one write (what pyserial's write does, without
        its timer and its select after the write); what the driver did not take at once goes
        through pyserial's write, which waits for room. Fails in pyserial's words."""
        try:
            n = os.write(self._fd, pkt)
        except (BlockingIOError, InterruptedError):
            n = 0
        except OSError as e:
            raise self._fd_failed("write", e) from None
        if n < len(pkt):
            self.port.write(pkt[n:])

    def _waiting(self):
        """Bytes waiting to be read (None on a port that cannot tell)."""
        try:
            n = self.port.in_waiting
        except Exception:  # noqa: BLE001 - a port without in_waiting (or a vanished one)
            return None
        if not n:
            self._seen_empty = self.now()
        return n

    def _event(self, kind, ident, lo, hi, t0=None, packet=None) -> None:
        if kind == "garbled":
            self.garbled += 1
        if len(self.events) < MAX_EVENTS:
            self.events.append(Event(kind, ident, lo, hi, t0, packet))

    def take_events(self) -> list:
        """The late, stray and garbled :class:`Event` s seen since the last call (for scans)."""
        out, self.events = self.events, []
        return out

    def _expire(self, now) -> None:
        owed = self._owed
        if owed and any(o.horizon <= now for o in owed):
            self._owed = deque(o for o in owed if o.horizon > now)

    def _owe(self, token, accept, data_len, t0, tx, span) -> None:
        """An attempt sent at ``t0`` went unanswered through its window (``span``): its reply may
        still come. The bus listens through its grace before sending a request whose reply
        could be taken for it, and recognises a reply that fits it until its horizon."""
        self._owed.append(_Owed(token, accept, data_len, t0, t0 + tx, t0 + span, t0 + span * (1 + MEMORY),
                                horizon=t0 + horizon_for(span)))

    def _await_conflicts(self, accept, data_len, token) -> None:
        """Listen until no unanswered attempt of another request, whose reply this request's
        could be taken for, is in its grace: a late reply lands where it belongs (an event, the
        attempt's) instead of in this request's window."""
        while self._owed:
            now = self.now()
            self._expire(now)
            due = [o.keep for o in self._owed if o.keep > now and o.token is not token
                   and o.conflicts(accept, data_len)]
            if not due:
                return
            self._listen(min(due))

    def clear_at(self, ident: int, data_len=None) -> float:
        """When a request to ``ident`` whose reply carries ``data_len`` bytes goes out at once,
        with nothing to wait for: the horizon of every unanswered attempt its reply could be
        taken for (before it the bus listens through that attempt's grace, or asks an Echo
        first; :meth:`now` when none is owed). A caller with a deadline (a player's next step)
        asks before it sends."""
        now = self.now()
        self._expire(now)
        return max((o.horizon for o in self._owed if o.horizon > now and o.conflicts({ident}, data_len)),
                   default=now)

    def owes(self, ident=None) -> bool:
        """Whether a reply to an unanswered attempt to ``ident`` (None: to any ID) may still come."""
        now = self.now()
        self._expire(now)
        return any(ident is None or ident in o.ids for o in self._owed)

    def settle(self, ident=None) -> None:
        """Listen until no reply to an unanswered attempt to ``ident`` (None: to any ID) can
        come any more (every one's horizon has passed, or its reply came): after that, silence
        from ``ident`` is certain (see :meth:`answers`), and nothing owed can meet a request."""
        while True:
            now = self.now()
            self._expire(now)
            due = [o.horizon for o in self._owed if ident is None or ident in o.ids]
            if not due:
                break
            self._listen(min(due))
        self._drain()

    def _open_windows(self, now):
        return [o for o in self._owed if o.until > now]

    def _echoed(self, p) -> bool:
        """``p`` is a copy of a packet we sent lately (the adapter's echo): note it."""
        if p not in self._recent:
            return False
        for t, sent in self._unechoed.items():
            if sent == p:
                del self._unechoed[t]
                break
        return True

    def _stray(self, p: bytes, lo: float, hi: float, token=None):
        """Account for a packet that is not the answer in hand: our own echo, another master's
        command, a reply to an earlier attempt (late: counted, an event; for ``token``, or the
        request in hand (:attr:`_current`), an earlier attempt of the same request: returned as
        ``(owed, p)`` and kept in :attr:`_caught` for that request), an acknowledgement nobody
        waited for, or a reply nobody asked for (stray)."""
        token = token if token is not None else self._current
        if self._echoed(p):
            self.adapter_echo = True
            return None
        family = self.family
        if family.is_request(p):
            return None                    # another master's command
        if self._twin(p, lo, hi):
            return None
        owed = self._take_owed(p, hi)
        if owed is None:
            self.stale += 1
            self._extra(family.ident(p), hi)         # a reply where none was due
            self._event("stray", family.ident(p), lo, hi, None, p)
            return None
        if owed.kind == "ack":
            self.stale += 1                # an acknowledgement nobody waited for
            return None
        if token is not None and owed.token is token:
            if self._caught is None:
                self._caught = (owed, p, lo, hi)
            return owed, p
        self._late(p, lo, hi, owed)
        return None

    def _twin(self, p: bytes, lo: float, hi: float) -> bool:
        """Whether the reply ``p`` (its bytes read from ``lo`` to ``hi``) followed a reply of the
        same ID and length with no pause between (nothing sent since that one's last byte was read,
        and ``p`` read within its own time on the wire, two byte times and the host margin after
        it): a reply sent twice, or a second actuator with that ID, as well as the reply of an
        unanswered attempt (replies held up and delivered together), which the line cannot tell
        apart. Such a reply answers nothing: an attempt it might answer stays owed (the reply is
        counted late), so that its own reply, if it comes, is never another request's value;
        where none is owed it is a reply where none was due. Remembers ``p`` as the last reply heard."""
        family = self.family
        self.devices[family.ident(p)].heard()
        last, self._answer = self._answer, (p, hi, self.sent)
        if last is None:
            return False
        before, end, sent = last
        if not (len(p) == len(before) and family.ident(p) == family.ident(before) and self.sent == sent
                and hi - self.wire(len(p)) <= end + self.wire(2) + self.margin):
            return False
        if any(o.horizon >= hi and o.matches(p, family) for o in self._owed):
            self.late += 1
            self._event("late", family.ident(p), lo, hi, None, p)
        else:
            # none owed: a reply where none was due
            self.stale += 1
            self._extra(family.ident(p), hi)
            self._event("stray", family.ident(p), lo, hi, None, p)
        return True

    def _extra(self, ident: int, when: float) -> None:
        dev = self.devices[ident]
        dev.extra += 1
        dev.extra_at = when

    def _late(self, p, lo, hi, owed) -> None:
        """``p`` is (or may be) the late reply of the earlier attempt ``owed``: counted (for the
        bus and for that actuator), an event."""
        ident = self.family.ident(p)
        self.late += 1
        self.devices[ident].late += 1
        self._event("late", ident, lo, hi, owed.t0, p)

    def _take_owed(self, p, now):
        """The attempt a stray packet answers: the oldest one still recognised (an actuator
        answers in the order it was asked; a reply in a later attempt's open window may still
        be an earlier one's, slower than that window)."""
        found = [o for o in self._owed if o.horizon >= now and o.matches(p, self.family)]
        if not found:
            return None
        owed = min(found, key=lambda o: o.t0)
        self._owed.remove(owed)
        self._resolve(self.family.ident(p), owed.t0)
        return owed

    def _resolve(self, ident: int, t0: float) -> None:
        """``ident`` answered the attempt sent at ``t0``: an actuator answers in the order it
        was asked, so no reply to an earlier unanswered attempt to it will come any more."""
        owed = self._owed
        if owed and any(o.t0 < t0 and ident in o.ids for o in owed):
            self._owed = deque(o for o in owed if not (o.t0 < t0 and ident in o.ids))

    def _account(self, data: bytes, lo: float, hi: float) -> None:
        """Bytes read between transactions, through the idle framer. What they make is dated
        from the first of them still held (an incomplete packet read earlier) to this read."""
        framer = self._framer
        if self._held is not None:
            lo = self._held[0]
        bad, skipped = framer.bad, framer.skipped
        for p in framer.feed(data):
            self._stray(bytes(p), lo, hi)
        if framer.bad != bad or framer.skipped != skipped:
            self._event("garbled", None, lo, hi, None, bytes(data))
        self._held = [lo, hi] if framer.pending else None

    def _listen(self, until: float) -> bool:
        """Read until ``until`` or the next bytes; account for them. False when nothing came."""
        if self._waiting() is None:
            self._reset_input()
            return False
        data = self._read(64, until)
        if not data:
            if self._framer.pending and self.now() >= until:
                self._flush_idle()
            return False
        self._account(data, self._seen_empty, self.now())
        return True

    def _flush_idle(self) -> None:
        """The bytes the idle framer holds once no more came: dated when they were read, not now
        (a scan judges which windows they fell in)."""
        framer = self._framer
        if not framer.pending:
            return
        lo, hi = self._held if self._held is not None else (self._seen_empty, self.now())
        self._held = None
        bad, skipped = framer.bad, framer.skipped
        for p in framer.flush():
            self._stray(bytes(p), lo, hi)
        if framer.bad != bad or framer.skipped != skipped:
            self._event("garbled", None, lo, hi, None, b"")

    def _reset_input(self) -> None:
        try:
            self.port.reset_input_buffer()
        except Exception as e:
            if isinstance(e, KeyboardInterrupt):
                raise
            raise self._port_error(e) from None

    def _drain(self) -> None:
        """Read and account for whatever has arrived; a packet caught half-way is read to its end."""
        while True:
            waiting = self._waiting()
            if waiting is None:
                self._reset_input()
                return
            now = self.now()
            if waiting:
                data = self._read(waiting, now)
                if data:
                    self._account(data, self._seen_empty, self.now())
                continue
            if self._framer.pending:
                end = now + self.wire(1) + INTER_BYTE + self.margin
                if self._listen(end):
                    continue
                self._flush_idle()
            return

    def _settle(self) -> None:
        wait = self._quiet_until - self.now()
        if wait > 0:
            self._sleep(wait)

    def quiet(self) -> None:
        """Listen until no reply may still come: every open window closed (replies that come
        meanwhile are accounted for), then the quiet time after a stored write or a restart."""
        self._close_windows()
        self._drain()
        self._settle()

    def _close_windows(self) -> None:
        """Listen until every open window has closed (what :meth:`quiet` does before the
        drain; a transaction's write drains what came)."""
        while self._owed:
            now = self.now()
            self._expire(now)
            open_ = self._open_windows(now)
            if not open_:
                break
            self._listen(min(o.until for o in open_))

    def linger(self, seconds: float) -> None:
        """Keep listening for ``seconds`` (late replies are accounted for; see :attr:`events`)."""
        end = self.now() + seconds
        while self.now() < end:
            self._listen(end)
        self._drain()

    def echo_clean(self, t0: float):
        """Whether the packet written at ``t0`` came back clean through the adapter's echo (its
        bytes crossed the line undisturbed); None when the adapter does not echo."""
        if not self.adapter_echo:
            return None
        return t0 not in self._unechoed

    # -- writing ----------------------------------------------------------------------------------

    def _write(self, pkt: bytes) -> float:
        """Read what has arrived, then write ``pkt``; returns the time just before the write
        (round trips are measured from there, so a host that is preempted after writing never
        shortens them)."""
        self._drain()
        t0 = self.now()
        try:
            if self._raw:
                self._write_fd(pkt)
            else:
                self.port.write(pkt)
        except Exception as e:  # serial.SerialException, OSError: the port failed or vanished
            if isinstance(e, (KeyboardInterrupt, PortError, OutputError)):
                raise
            raise self._port_error(e) from None
        self.sent += 1
        self.last_sent = t0
        ident = self.family.ident(pkt)
        if ident != self.family.BROADCAST:
            self.devices[ident].asked += 1      # a reply it may give (see Device.shared)
        if self.monitor is not None:
            self.monitor("tx", bytes(pkt))
        self._recent.append(bytes(pkt))
        if len(self._unechoed) > 512:
            self._unechoed.pop(next(iter(self._unechoed)))
        self._unechoed[t0] = bytes(pkt)
        return t0

    # -- one transaction ----------------------------------------------------------------------

    def transact(self, pkt: bytes, *, reply=None, data_len=None, extra=0.0, timeout=None, retries=None,
                 accept_ids=None, check=True, optional=False, quick=False, early=False, window=None,
                 any_answer=False, persist=False):
        """Send ``pkt``; return its checked :class:`Reply`, or None when none is expected.

        ``reply``: whether a reply comes (default: from the instruction and ``return_mode``);
        ``data_len``: data bytes the reply must carry (None: any); ``extra``: seconds added to
        the wait; ``timeout`` or ``window``: this transaction's late window (default
        :attr:`window`); ``accept_ids``: IDs a reply may carry (default: the packet's);
        ``check``: raise DeviceError for error bits; ``optional``: no reply is not an error
        (None, without a retry: the command may have been carried out); ``quick``: wait only a
        scan's first-pass time for the first byte (:meth:`quick_timeout`; the window stays open
        and a later reply is an event); ``early``: transmit without waiting for earlier windows
        to close (a scan's first pass only); ``any_answer``: any reply of the ID will do, even
        one that may answer an earlier request (whether an ID answers at all; the reply is
        marked :attr:`Reply.doubt`); ``persist``: with ``optional``, silence is tried again
        ``retries`` times before it is taken for an answer.

        Attribution: before an attempt goes out the bus listens through the grace of every
        unanswered attempt of another request whose reply this one's could be taken for (same
        ID and length); a reply that fits an unanswered attempt is that attempt's (an event,
        counted late), and while such a reply may still come (its horizon,
        :func:`~zkzap.link.zap_timing.horizon_for`) a fitting reply is never returned as this
        request's value: this attempt waits on for its own.
        """
        stop.check()                       # a stop requested (a batch's Ctrl-C) ends the command here
        pkt = bytes(pkt)
        family = self.family
        ident = family.ident(pkt)
        if reply is None:
            reply = self.expects_reply(pkt)
        stored = family.stored(pkt)
        restart = family.restarts(pkt)
        extra = extra + (NV_PAUSE if stored else 0.0)
        tries = 1 + (self.retries if retries is None else retries)
        accept = set(accept_ids) if accept_ids else {ident}
        win = timeout if timeout is not None else (window if window is not None else self.window)
        if self.policy.estimators and not quick:
            win = self.policy.window_of(ident, win)   # an actuator learned to be slower than it
        tx = self.wire(len(pkt))
        if not reply:
            if not early:
                self.quiet()
            t0 = self._write(pkt)
            pause = RESTART_PAUSE if restart else (NV_PAUSE if stored else 0.0)
            self._quiet_until = t0 + tx + pause
            if ident != family.BROADCAST:
                # an actuator in another return mode acknowledges anyway: the line stays quiet for
                # its learned latency (the bus-typical one before it was measured), and that
                # acknowledgement is skipped when it comes
                until = t0 + tx + self.courtesy(ident, win) + self.wire(family.OVERHEAD) + self.margin
                # (an actuator known to answer after the window may acknowledge that late too, and
                # so may one whose return mode was only assumed: its acknowledgement is recognised
                # as one until the horizon, never taken for an answer)
                dev = self.devices[ident]
                unsure = dev.late or dev.return_mode is None
                horizon = t0 + horizon_for(until - t0 + win) if unsure else until + win
                self._owed.append(_Owed(None, accept, family.ack_len(pkt), t0, t0 + tx, until + pause, until + win,
                                         "ack", horizon=horizon))
            return None
        rx_len = family.OVERHEAD + (data_len or 0)
        span = tx + win + self.wire(rx_len) + self.margin + extra      # the whole window of an attempt
        token = object()
        problems = []
        limit = span
        dev = self.devices[ident]
        late0 = dev.late
        outer = self._current, self._caught      # (a sync Echo runs inside a request)
        self._current, self._caught = token, None
        try:
            for attempt in range(tries):
                if attempt:
                    if problems[-1][0] != "none":
                        self._idle()       # after a garbled reply: the rest of it has passed
                    else:
                        # after silence, listen on for half a window more: a reply a little
                        # later than the window is this request's, and its latency is known
                        self._linger_for(token, span * RETRY_GRACE)
                    if not early:
                        self._close_windows()
                        if not any_answer:
                            self._await_conflicts(accept, data_len, token)
                        self._settle()
                    self._drain()
                    if self._caught is not None:
                        # the late reply of an earlier attempt came before this one went out: the
                        # answer, and no retry meets it on the line
                        owed, p, lo, hi = self._caught
                        got = self._reply(p, hi - owed.t0, self._only(token, owed, lo))
                        return self._answered(got, pkt, restart, stored, check, win, any_answer)
                    self.retried += 1
                elif not early:
                    self._close_windows()  # then the quiet time; the write drains what came
                    if not any_answer:
                        self._await_conflicts(accept, data_len, token)
                        if self._owed:
                            self._sync(accept, data_len, token)
                    self._settle()
                got = self._attempt(pkt, accept, data_len, rx_len, tx, span, quick, extra, restart, token,
                                    any_answer)
                if isinstance(got, Reply):
                    return self._answered(got, pkt, restart, stored, check, win, any_answer)
                if got[0] == "none" and (quick or (optional and not persist)):
                    return None            # silence is a legitimate answer: do not repeat the command
                problems.append(got)
                limit = got[3]
            if not optional and dev.late and all(p[0] == "none" for p in problems):
                # an actuator known to answer late: before saying "no reply", listen on half a
                # window more, as before a retry; a
                # reply of this request that comes meanwhile is its answer (late), else the error
                # says whether replies of that ID come late (a fact: a longer window would do)
                until = [o.until for o in self._owed if o.token is token]
                end = max(until) + span * RETRY_GRACE if until else self.now()
                while self._caught is None and self.now() < end:
                    self._listen(end)
                if self._caught is not None:
                    owed, p, lo, hi = self._caught
                    got = self._reply(p, hi - owed.t0, self._only(token, owed, lo))
                    return self._answered(got, pkt, restart, stored, check, win, any_answer)
        finally:
            self._current, self._caught = outer
        return self._fail(pkt, [p[:3] for p in problems], limit, tries, optional,
                          late=dev.late - late0, late_before=late0)

    def _linger_for(self, token, seconds) -> None:
        """Listen up to ``seconds`` past the window of the latest attempt of ``token``, or until
        the reply of an attempt of it came."""
        owed = [o for o in self._owed if o.token is token]
        if not owed:
            return
        end = owed[-1].until + seconds
        while self._caught is None and self.now() < end:
            self._listen(end)

    def _sync(self, accept, data_len, token) -> None:
        """Before a request whose reply could be taken for that of an unanswered attempt of
        another request (past its grace: a lost request, or an actuator slower than that), ask
        each such ID for an Echo, whose reply cannot be taken for it (another length): an
        actuator answers in order, so its Echo reply means no reply to those attempts will come
        any more. Echo attempts unanswered are no obstacle to this (an Echo reply that may
        answer one is marked, not taken for a value). Nothing is done where nothing is owed."""
        if data_len == 0:
            return
        for ident in sorted(accept):
            for _ in range(3):
                if not any(o.token is not token and o.kind == "reply" and ident in o.ids and
                           o.conflicts(accept, data_len) for o in self._owed):
                    break
                probe, n = self.family.probe(ident)
                r = self.transact(probe, reply=True, data_len=n, retries=0, optional=True,
                                  check=False, any_answer=True)
                if r is None:
                    break                  # it does not answer now: the request will say so

    def _timely(self, ident: int, now_latency: float, old_latency: float) -> bool:
        """Whether a reply is this attempt's by the latency learned of ``ident``: within its
        timeout after this attempt, and far beyond it after the earlier attempt it could also
        answer. False before anything was learned of ``ident`` (then it is a doubt)."""
        est = self.policy.estimators.get(ident)
        if est is None or not est.samples or est.srtt is None:
            return False
        limit = est.srtt + max(MARGIN, K * est.rttvar) + self.margin
        return now_latency <= limit and old_latency > 2 * limit + self.margin

    def _only(self, token, owed, lo):
        """The latency of a reply to ``owed`` heard between attempts (its first byte when ``lo``
        is known): None while another attempt of the same request is unanswered (either may be
        the one it answers)."""
        if any(o.token is token for o in self._owed):
            return None
        return max(0.0, lo - owed.sent)

    def _attempt(self, pkt, accept, data_len, rx_len, tx, span, quick, extra, restart, token, any_answer):
        """One attempt: write, wait; a Reply or a problem ``(kind, detail, bytes, limit)``."""
        t0 = self._write(pkt)
        limit = (self.quick_timeout(len(pkt), self.family.ident(pkt)) + extra) if quick else span
        try:
            got = self._await(pkt, accept, data_len, rx_len, t0, limit, self.family.copy_reply(pkt), token,
                              any_answer)
        except BaseException:
            # interrupted (Ctrl-C) while its reply was on its way: that reply is still owed. The
            # line stays quiet for the time the actuator is known to take (the request that
            # follows, a stop's, must not meet it on the line), not for the whole window; and
            # when it comes it is this attempt's (late), never a reply where none was due, which
            # would make its ID suspect for the stop
            ident = self.family.ident(pkt)
            quiet = min(t0 + span, t0 + tx + self.courtesy(ident, span) + self.wire(rx_len) + self.margin + extra)
            self._owed.append(_Owed(token, accept, data_len, t0, t0 + tx, quiet, quiet,
                                    horizon=t0 + horizon_for(span)))
            raise
        if isinstance(got, Reply):
            if got.doubt is not None:
                # the reply may be an earlier attempt's: this one's own may still come, and is
                # this attempt's, never another request's
                self._owe(token, accept, data_len, t0, tx, span)
            return got
        # its window (still open after a quick probe) and then some: a reply that comes is this
        # attempt's, never the answer to another request. So after bytes that were not its answer
        # too (garbled, another ID's, a wrong length): they may have been another reply, and the
        # actuator heard the request all the same
        self._owe(token, accept, data_len, t0, tx, span)
        return got + (limit,)

    def _answered(self, got, pkt, restart, stored, check, win, any_answer=False):
        self.replies += 1
        dev = self.devices[got.ident]
        if dev.baud is None:
            dev.baud = self.port.baudrate      # it answers at this rate
        if not any_answer:
            self.refuse_shared(got)
        if dev.extra_at is not None and self.now() - dev.extra_at < HORIZON and got.doubt is None:
            # that ID lately sent a reply where none was due (two actuators answering to it, or a
            # reply sent twice): an answer of it may be the other's, never a value
            if got.data:
                raise BadReply(f"ID {got.ident}: a reply came where none was due within the last {HORIZON:g} s "
                               "(two actuators answering to this ID, or a reply sent twice): this answer may be "
                               "the other's", kind="twice", ident=got.ident, baud=self.baud,
                               received=bytes(got.packet), collision=True, duplicate=True,
                               protocol="zap" if self.family.name == "ir" else self.family.name)
            got.doubt = TWICE
        if got.latency is not None and self.policy.learn(got.ident, got.latency, win):
            self.late += 1                 # after its actuator's learned timeout: still the answer
        if restart:
            self._quiet_until = self.now() + RESTART_PAUSE
        elif stored:
            self._quiet_until = self.now() + NV_PAUSE
        if check and got.error:
            raise device_error(got)
        return got

    def refuse_shared(self, got: Reply) -> None:
        """Raise :class:`~zkzap.errors.BadReply` (kind ``shared``, a duplicate) when more replies
        of ``got``'s ID were heard than requests went to it (:attr:`Device.shared
        <zkzap.link.devices.Device>`): two actuators answer to it (or one sent a reply twice), and
        a reply can be the other's answer to an earlier request, however they are ordered. Holds
        until a census finds one actuator there (:meth:`census`; set-id, set-baud, the fleet
        reads)."""
        dev = self.devices.get(got.ident)
        if dev is None or not dev.shared:
            return
        raise BadReply(f"ID {got.ident} at {self.baud} baud: more replies came from this ID than requests went "
                       "to it (two actuators answering to this ID, or a reply sent twice): this answer may be "
                       "the other's, to an earlier request", kind="shared", ident=got.ident, baud=self.baud,
                       received=bytes(got.packet), collision=True, duplicate=True,
                       protocol="zap" if self.family.name == "ir" else self.family.name)

    def _idle(self) -> None:
        """Before a retry after a garbled reply: listen until the line has been idle for one
        inter-byte allowance (the rest of a collision has passed)."""
        while self._listen(self.now() + self.wire(1) + INTER_BYTE + self.margin):
            pass
        self._flush_idle()

    def _await(self, pkt, accept, data_len, rx_len, t0, limit, copy_reply, token, any_answer=False):
        """Read until a valid reply or the deadline (``limit`` after ``t0``, for the first reply
        byte; extended while reply bytes trickle in). Returns a Reply (``rtt`` from the attempt
        that was answered, ``latency`` its first byte after the request left) or a problem tuple
        (kind, detail, received bytes)."""
        tx = self.wire(len(pkt))
        overran = False
        if self._spare and self.now() - t0 < tx * SPARE_SHARE:
            self.run_spare()               # the request is still on the wire: the host's time is free
            overran = self.now() - t0 > tx       # a reply byte may have waited for the work
        family = self.family
        ident_of = family.ident
        framer = family.framer()
        received = bytearray()
        echo_known = self.adapter_echo
        state = {"copies": 0, "want": rx_len + (len(pkt) if echo_known else 0), "mismatch": None,
                 "explained": 0, "first": None, "lo": self._seen_empty, "hi": None, "doubted": 0,
                 "doubt_reply": None, "at": 0}
        wrong = []
        deadline = base = t0 + limit
        gap = self.policy.inter_byte(ident_of(pkt), self.window)

        def examine(packets, lo, hi):
            got = judge(packets, lo, hi)
            if isinstance(got, Reply):
                # what came with the answer (a second reply where one was due, a late one) is
                # accounted for by the idle framer, never thrown away unseen
                rest = b"".join(bytes(p) for p in packets[state["at"] + 1:])
                if framer.pending:
                    rest += bytes(received[-framer.pending:])
                if rest:
                    self._account(rest, hi, hi)
            return got

        def judge(packets, lo, hi):
            for state["at"], p in enumerate(packets):
                p = bytes(p)
                state["explained"] += len(p)
                if p == pkt:
                    state["copies"] += 1
                    self.adapter_echo = True
                    self._echoed(p)
                    state["want"] = max(state["want"], len(received) + rx_len)
                    continue
                if p in self._recent or family.is_request(p):
                    self._echoed(p)
                    continue                      # a late echo of an earlier packet, another master
                if self._twin(p, lo, hi):
                    state["want"] = len(received) + rx_len
                    continue
                now = self.now()
                # A reply that fits an unanswered earlier attempt is that attempt's first: an
                # actuator answers in the order it was asked, so the oldest such attempt it may
                # answer is the one it does (whatever the time: a link that is not a UART at its
                # baud rate answers sooner than the wire could carry it). An acknowledgement
                # nobody waited for is only ever another request's when this one's cannot fit it.
                ours = ident_of(p) in accept and family.fits(p, data_len)
                owed = next((o for o in self._owed if o.matches(p, family) and o.horizon >= now), None) \
                    if self._owed else None
                if owed is not None and ours and owed.kind == "reply" and owed.token is not token:
                    f = state["first"] if state["first"] is not None else hi
                    if self._timely(ident_of(p), f - t0 - tx, f - owed.sent):
                        # what the actuator is known to take says it answers this attempt: the
                        # earlier one was lost (and so is every one before it)
                        self._resolve(ident_of(p), t0)
                        owed = None
                        state["guessed"] = True   # judged by the estimator: never taught to it
                if owed is not None:
                    self._owed.remove(owed)
                    self._resolve(ident_of(p), owed.t0)
                    if owed.kind == "ack":
                        self.stale += 1           # the acknowledgement of an earlier write
                        if ours:
                            # ... or this attempt's answer: not a value; its own may follow
                            self.devices[ident_of(p)].doubts += 1
                            state["doubted"] += 1
                            state["doubt_reply"] = (p, hi)
                    elif owed.token is token:
                        # the earlier attempt's late reply answers this request (this attempt's
                        # reply, when it comes, is recognised as late)
                        span = deadline - t0
                        self._owed.append(_Owed(token, accept, data_len, t0, t0 + tx, deadline,
                                                deadline + span * MEMORY, horizon=t0 + horizon_for(span)))
                        return self._reply(p, hi - owed.t0, None)
                    else:
                        self._late(p, lo, hi, owed)
                        if ours:
                            # it may be this attempt's answer, or that attempt's late one: never a
                            # value; this attempt's own reply, if it comes, follows it
                            self.devices[ident_of(p)].doubts += 1
                            state["doubted"] += 1
                            state["doubt_reply"] = (p, hi)
                    state["want"] = len(received) + rx_len
                    continue
                if ident_of(p) not in accept:
                    wrong.append(p)
                    self._extra(ident_of(p), hi)             # a reply where none was due
                    self._event("stray", ident_of(p), lo, hi, None, p)
                    state["want"] = len(received) + rx_len
                    continue
                if not family.fits(p, data_len):
                    self.stale += 1               # an ack nobody waited for; the reply may follow
                    state["mismatch"] = (len(p) - family.OVERHEAD, bytes(p))
                    state["want"] = len(received) + rx_len
                    continue
                if framer.bad or framer.skipped:
                    # bytes that made no packet came first: a collision, for scans
                    self._event("garbled", None, state["lo"], hi, None, bytes(received))
                    if data_len and not any_answer:
                        # they may be another reply that met this request on the line (then the
                        # actuator never heard it), and this one a reply to an earlier request:
                        # never a value; this attempt's own reply, if it comes, follows it
                        self.devices[ident_of(p)].doubts += 1
                        state["doubted"] += 1
                        state["want"] = len(received) + rx_len
                        continue
                first = state["first"] if state["first"] is not None else hi
                self._resolve(ident_of(p), t0)    # this attempt's answer: earlier ones are lost
                if any(o.token is token for o in self._owed):
                    # an earlier attempt of this request is still owed: this may be its reply, so
                    # this attempt's may still come; the line stays quiet for its window
                    self._owed.append(_Owed(token, accept, data_len, t0, t0 + tx, deadline,
                                            deadline + (deadline - t0) * MEMORY,
                                            horizon=t0 + horizon_for(deadline - t0)))
                    return self._reply(p, hi - t0, None)
                guessed = overran or state.get("guessed")
                return self._reply(p, hi - t0, None if guessed else first - t0 - tx - self.wire(1))
            return None

        while True:
            lo = self._seen_empty
            chunk = self._read(max(1, state["want"] - len(received)), deadline)
            if not chunk:
                if self.now() >= deadline:
                    break
                continue
            hi = state["hi"] = self.now()
            if state["first"] is None and not (echo_known and len(received) + len(chunk) <= len(pkt)
                                               and pkt.startswith(bytes(received) + chunk)):
                state["first"] = hi               # the first byte that is not our own echo
                state["lo"] = lo
            received += chunk
            got = examine(framer.feed(chunk), lo, hi)
            if got is not None:
                return got
            # bytes of an incomplete packet: give the rest time to trickle in (only while they do)
            deadline = max(base, self.now() + self.wire(1) + gap + self.margin) if framer.pending else base
        pending, bad_before = framer.pending, framer.bad
        # what the bytes held make is dated when they were read, not at the deadline
        last = state["hi"] if state["hi"] is not None else self.now()
        got = examine(framer.flush(), state["lo"], last)   # a packet held back to rule out a rival
        if framer.bad or len(received) > state["explained"]:
            self._event("garbled", None, state["lo"], last, None, bytes(received))   # a collision or a line fault
        if got is not None:
            return got
        if any_answer and state["doubt_reply"] is not None:
            # an ID that answers at all is what was asked: the reply, marked
            p, hi = state["doubt_reply"]
            return self._reply(p, hi - t0, None, doubt=DOUBT)
        copies = state["copies"]
        # The documented Restart feedback is a copy of the command itself: accept a copy that
        # is more than the adapter's known echo.
        if copy_reply and not wrong and copies >= (2 if echo_known else 1):
            return self._reply(pkt, self.now() - t0, None, copy=True)
        if wrong:
            ids = ", ".join(str(ident_of(p)) for p in wrong)
            return ("wrong-id", f"reply from ID {ids}, expected ID {min(accept)}", bytes(received))
        if state["mismatch"] is not None:
            n = state["mismatch"][0]
            return ("length", f"reply carries {n} data bytes, expected {data_len}", bytes(received))
        if pending and not bad_before and family.cut_short(bytes(received[-pending:])):
            return ("truncated", f"truncated reply ({pending} bytes of an incomplete packet: a collision "
                                 "or a line fault)", bytes(received))
        if framer.bad:
            return ("checksum", "garbled reply (checksum mismatch: a collision, two actuators answering at "
                                "once, or a line fault)", bytes(received))
        if len(received) > state["explained"]:
            return ("garbage", "unreadable bytes instead of a reply (a collision, a line fault or a wrong "
                               "baud rate)", bytes(received))
        if state["doubted"]:
            return ("none", "doubt", bytes(received))
        return ("none", "echo only" if copies else "", bytes(received))

    def _reply(self, p, rtt, latency, copy=False, doubt=None):
        r = self.family.reply(p, rtt, latency, copy)
        if doubt is not None:
            r.doubt = doubt
        return r

    def _fail(self, pkt, problems, limit, tries, optional, late=0, late_before=0):
        """Raise what went wrong. A NoReply's facts say how many replies of that ID came after
        their window while this request was in hand (``late``) and before it (``late_before``):
        an actuator slower than the window."""
        ident = self.family.ident(pkt)
        kinds = [p[0] for p in problems]
        if all(k == "none" for k in kinds):
            if optional:
                return None
            ms = self.window * 1000
            echo = any(p[1] == "echo only" for p in problems)
            note = " (only our own bytes came back: the adapter echoes)" if echo else ""
            raise NoReply(f"no reply from ID {ident} at {self.baud} baud within {ms:.1f} ms "
                          f"({tries} {'try' if tries == 1 else 'tries'}){note}",
                          ident=ident, baud=self.baud, timeout=limit, window=self.window, tries=tries,
                          echo_only=echo, mode_dependent=self.mode_dependent(pkt),
                          protocol="zap", late=late, late_before=late_before)
        bad = [p for p in problems if p[0] != "none"][-1]
        seen = bad[2].hex(" ").upper() if bad[2] else "nothing"
        if len(seen) > 120:
            seen = seen[:117] + "..."
        raise BadReply(f"ID {ident}: {bad[1]} after {tries} {'try' if tries == 1 else 'tries'}; received {seen}",
                       kind=bad[0], ident=ident, baud=self.baud, timeout=limit, tries=tries, received=bad[2],
                       collision=bad[0] in ("checksum", "garbage", "truncated"), protocol="zap")

    # -- instructions -------------------------------------------------------------------------

    def mode_dependent(self, pkt: bytes) -> bool:
        """Whether an answer to ``pkt`` depends on the actuator's feedback-return mode."""
        ins = zap.INSTRUCTION_BY_CODE.get(pkt[5])
        return ins is not None and ins.reply != "always"

    def authorize(self, pkt: bytes, allow=None) -> None:
        """Raise :class:`~zkzap.errors.PermissionNeeded` unless ``pkt`` may be sent: the
        permissions it needs are :attr:`allow`'s, ``allow``'s, or waived by a simulated port."""
        if pkt[5] in _FREE:
            return                                  # Echo, Load Data, Execution, Restart
        cmd = zap.Command(pkt)
        needs = cmd.needs()
        if needs:
            require(needs, self.allow | as_permission(allow), simulated=self.simulated, what=cmd.describe(),
                    frame=pkt)

    def command(self, pkt: bytes, *, check=True, optional=None, allow=None):
        """Send any command packet and wait for what it gets (inferred from the packet): Load
        Data's data length, an ID change answered by the new ID, an unknown instruction's
        optional reply. ``allow``: permissions for this packet besides :attr:`allow`."""
        pkt = bytes(pkt)
        self.authorize(pkt, allow)
        code, params = pkt[5], pkt[6:-1]
        kw = {}
        if code == zap.LOAD_DATA and len(params) == 2:
            kw["data_len"] = params[1]
        if code == zap.STORE_DATA and len(params) == 2 and params[0] == zap.REGISTER_BY_NAME["id"].address:
            kw["accept_ids"] = {pkt[3], params[1]}
        if code == zap.STORE_DATA and len(params) == 2 and params[0] == zap.REGISTER_BY_NAME["feedback-return-mode"].address \
                and pkt[3] != zap.BROADCAST and params[1] <= 2:
            # the reply follows the old or the new mode (firmware-dependent): wait if either answers
            new = params[1]
            old = self.devices.mode(pkt[3])
            kw["reply"] = self.expects_reply(pkt, old) or self.expects_reply(pkt, new)
            kw["optional"] = self.expects_reply(pkt, old) != self.expects_reply(pkt, new)
            try:
                return self.transact(pkt, check=check, **kw)
            finally:
                # that actuator's mode, not the bus's (a broadcast: every actuator's)
                self.devices.learn_mode(pkt[3], new, broadcast=zap.BROADCAST)
        ins = zap.INSTRUCTION_BY_CODE.get(code)
        if (ins is None or not ins.documented) and pkt[3] != zap.BROADCAST:
            kw["reply"] = True
            kw["optional"] = True
        elif code != zap.LOAD_DATA and "data_len" not in kw:
            kw["data_len"] = 0             # an acknowledgement carries no data
        if optional is not None:
            kw["optional"] = optional
        return self.transact(pkt, check=check, **kw)

    def echo(self, ident: int, **kw) -> Reply:
        """Echo: the reply of ``ident`` (one that may answer an earlier unanswered Echo or Load
        of it is marked :attr:`Reply.doubt`: an Echo carries no value, and its round trip is
        then not known)."""
        kw.setdefault("any_answer", True)
        r = self.transact(zap.echo(ident), reply=True, data_len=0, **kw)
        if r is not None:
            self.refuse_shared(r)          # whether that ID answers this Echo: the line cannot tell
        return r

    def load(self, ident: int, address: int, length: int, **kw) -> Reply:
        """Load Data: ``length`` bytes from ``address``."""
        if self.devices.mode(ident) == 0:
            raise UsageError(f"load: ID {ident} is in feedback-return-mode 0: Load Data is never answered",
                             ident=ident, return_mode=0,
                             assumed_mode=getattr(self.devices.get(ident), "return_mode", None) is None)
        return self.transact(zap.load(ident, address, length), reply=True, data_len=length, **kw)

    def read(self, ident: int, reg, **kw) -> int:
        reg = zap.register(reg)
        return self.load(ident, reg.address, reg.size, **kw).value

    def read_block(self, ident: int, address: int, length: int, **kw):
        """(Reply, [(Register, raw), ...]): the block a watch reads (:func:`zkzap.api.watch.plan_reads`):
        ``length`` bytes from ``address`` in one Load Data."""
        return self.read_registers(ident, address, length, **kw)

    def read_registers(self, ident: int, address: int, length: int, **kw):
        """(Reply, [(Register, raw), ...]): registers from one multi-byte Load Data."""
        r = self.load(ident, address, length, **kw)
        return r, zap._register_values(address, r.data)

    def store(self, ident: int, reg, value: int, *, force=False, **kw):
        return self.command(zap.store(ident, reg, value, force=force), **kw)

    def send_data(self, ident: int, reg, value: int, *, force=False, **kw):
        return self.command(zap.send_data(ident, reg, value, force=force), **kw)

    def execute(self, ident: int = zap.BROADCAST, **kw):
        return self.command(zap.execute(ident), **kw)

    def restart(self, ident: int, **kw):
        return self.command(zap.restart(ident), **kw)

    def factory_reset(self, ident: int, reset_id=False, reset_baud=False, **kw):
        return self.command(zap.factory_reset(ident, reset_id, reset_baud), **kw)

    def symmetric_store(self, reg, targets, **kw) -> None:
        packets = zap.symmetric_store(reg, targets)
        for pkt in packets:
            self.authorize(pkt, kw.get("allow"))    # every packet before the first goes out
        for pkt in packets:
            self.command(pkt, **kw)

    def ping(self, ident: int, *, timeout=None, retries=0, quick=False, early=False, window=None):
        """Echo that returns None when nothing answers (for scans); a corrupted reply is
        retried ``retries`` times and then raised as BadReply. ``quick``/``early``: a scan's
        first-pass probe (see :meth:`transact`); ``window``: this probe's late window. Any reply
        of the ID answers the question (whether it answers): one that may answer an earlier
        request is returned marked :attr:`Reply.doubt`."""
        return self.transact(zap.echo(ident), reply=True, data_len=0, timeout=timeout, retries=retries,
                             optional=True, check=False, quick=quick, early=early, window=window,
                             any_answer=True)

    def answers(self, ident: int, *, tries: int = 3, listen_out: bool = True) -> bool:
        """Whether any actuator answers to ``ident``: Echo with the whole window up to ``tries``
        times; a reply with error bits, a garbled reply or a late reply from ``ident`` all count
        as an answer. Only ``tries`` silences in a row, and then no reply to any of them until
        no reply can come any more (:meth:`settle`: the horizon of every attempt to ``ident``),
        say it is free: an actuator slower than the window is not taken for a free ID
        (``listen_out=False``: the silence of the tries' windows, where a census has just
        listened out the horizon of that ID)."""
        dev = self.devices[ident]
        late = dev.late
        try:
            probe, n = self.family.probe(ident)
            if self.transact(probe, reply=True, data_len=n, retries=tries - 1, optional=True,
                             persist=True, check=False, any_answer=True) is not None:
                return True
        except BadReply:
            return True
        if listen_out:
            self.settle(ident)
        return dev.late > late

    def moved_id(self, old: int, new: int) -> None:
        """The actuator at ``old`` now answers at ``new`` (an ID change, verified): its record
        goes along (its latency too), and nothing is known any more of ``old``."""
        self.devices.moved(old, new)
        self.policy.moved(old, new)

    def heard_out(self, verdicts) -> None:
        """What a verified identity change leaves known, ``{(baud, ID): "none" | "one"}`` (the
        actuator a census found alone at its ID is now the one at the new ID or rate, and none is
        left where it was): a census of those IDs right after it, with nothing sent meanwhile
        (within :data:`HEARD_OUT`), asks nothing again (set-id 1 -> 9 and back)."""
        self._heard_out = (self.sent, self.now(), dict(verdicts))

    def _known(self, ids):
        """The census verdicts of ``ids`` at this rate that :meth:`heard_out` left, if it left all
        of them, nothing was sent since and it was lately; else None."""
        known, self._heard_out = self._heard_out, None
        if known is None:
            return None
        sent, when, verdicts = known
        if sent != self.sent or self.now() - when > HEARD_OUT:
            return None
        out = {i: verdicts.get((self.baud, i)) for i in ids}
        if None in out.values():
            return None
        self._heard_out = known
        return out

    def census(self, ids, *, asks: int = 3, tries: int = 1) -> dict:
        """How many actuators answer to each of ``ids`` at this baud rate, as far as the line can
        tell: ``{ID: "none" | "one" | "shared"}``. Each ID is asked ``asks`` Echoes (each with
        the whole window and ``tries`` attempts: an ID is judged by the replies counted over the
        horizon, so a request lost on the line is made up by the next ask, not by waiting out
        a retry; an earlier attempt to it still owed counts as one of them), and the bus listens
        on until the horizon of the last, and of those, has passed
        (:func:`~zkzap.link.zap_timing.horizon_for`): an ID is ``shared`` when its replies came
        garbled every time, or when more replies came than were due (two actuators answering
        one request, however far apart: a second unit slower than the window; or a reply
        sent twice), or when two of its answered asks also heard bytes that made no packet (a
        second reply that met the first on the line; once is a line fault); ``none`` when
        nothing answered until the horizon. Costs about the horizon
        (1.5 s) in all, whatever the number of IDs; nothing right after an identity change
        that left them known (:meth:`heard_out`)."""
        ids = list(dict.fromkeys(ids))
        known = self._known(ids)
        if known is not None:
            return known
        # an attempt to one of them still owed counts as an ask (its reply, when it comes, is
        # counted against it), and its horizon is listened out with the census's own: the
        # horizon of an ID asked just before (set-id's check that the old ID is gone) is not
        # waited out twice
        now = self.now()
        self._expire(now)
        sent = {i: sum(1 for o in self._owed if i in o.ids) for i in ids}
        owed_until = max((o.horizon for o in self._owed if not o.ids.isdisjoint(ids)), default=now)
        extra = {i: self.devices[i].extra for i in ids}
        replies = {i: self.devices[i].replies for i in ids}
        late = {i: self.devices[i].late for i in ids}
        got = {i: 0 for i in ids}
        garbled = {i: 0 for i in ids}
        tails = {i: 0 for i in ids}       # answered asks whose window also held bytes that made no packet
        last = self.now()
        rounds, noisy = asks, 0
        span = self.reply_timeout(self.family.PROBE_LEN, self.family.PROBE_LEN)
        while rounds > 0:
            rounds -= 1
            before = self.garbled
            for ident in ids:
                probe, n = self.family.probe(ident)
                retried = self.retried
                noise = self.garbled
                try:
                    r = self.transact(probe, reply=True, data_len=n, retries=tries - 1, optional=True,
                                      persist=True, check=False, any_answer=True)
                except BadReply:
                    garbled[ident] += 1
                    r = None
                sent[ident] += 1 + self.retried - retried
                if r is not None:
                    got[ident] += 1
                    # the whole window, answered or not: a second actuator's reply comes as one
                    # where none was due, never where the next ask's is (nor over the next ask,
                    # which neither actuator would then hear)
                    self.linger(max(0.0, self.last_sent + span - self.now()))
                    if self.garbled != noise:
                        # a clean reply and bytes that made no packet in one window: a second
                        # reply that met it on the line (or a line fault, once)
                        tails[ident] += 1
                last = self.last_sent
            if self.garbled != before and noisy < asks:
                # bytes that made no packet may hide a second reply (one cut short): once more
                noisy += 1
                rounds += 1
        self.linger(max(0.0, max(last + horizon_for(span), owed_until) - self.now()))
        out = {}
        for ident in ids:
            dev = self.devices[ident]
            # (more replies than attempts, however they were attributed: a second actuator's
            # reply can come where the next ask's is due, and be taken for it)
            if dev.extra > extra[ident] or dev.replies - replies[ident] > sent[ident] \
                    or garbled[ident] >= asks or (garbled[ident] and got[ident]) or tails[ident] >= 2:
                out[ident] = "shared"
                dev.shared = True
            elif got[ident] or dev.late > late[ident]:
                out[ident] = "one"
                dev.cleared()          # one actuator there: what was counted before is settled
            else:
                out[ident] = "none"
                dev.cleared()
        return out

    def detect_return_mode(self, ident: int) -> int:
        """Ask the actuator: Load feedback-return-mode (answered in modes 1 and 2); no answer
        but an Echo reply means mode 0. The mode is that actuator's from now on (:meth:`mode_of`);
        returns it."""
        reg = zap.REGISTER_BY_NAME["feedback-return-mode"]
        r = self.transact(zap.load(ident, reg.address, 1), reply=True, data_len=1, optional=True, check=False)
        if r is not None and r.value in (0, 1, 2):
            self.devices.learn_mode(ident, r.value)
            return r.value
        self.echo(ident, check=False)
        self.devices.learn_mode(ident, 0)
        return 0

    def wait_ready(self, ident: int, within: float = 2.0, check=False) -> Reply:
        """Echo ``ident`` until it answers (after a restart or a baud change) or ``within``
        seconds pass (NoReply). Every Echo waits its whole window."""
        end = self.now() + within
        while True:
            r = self.ping(ident, retries=1)
            if r is not None:
                if check and r.error:
                    raise device_error(r)
                return r
            if self.now() >= end:
                raise NoReply(f"no reply from ID {ident} at {self.baud} baud within {within:g} s",
                              ident=ident, baud=self.baud, timeout=within, protocol="zap")

    def bauds_of(self, ident: int) -> list:
        """The baud rates at which an actuator with ``ident`` answered on this port (what this
        bus learned: a scan at several rates, a baud change)."""
        return self.by_baud.bauds_of(ident)

    def moved_to(self, ident: int, baud: int) -> None:
        """Actuator ``ident`` at this rate now answers at ``baud`` (a baud change): its record
        goes along (its latency too), and nothing is known any more of ``ident`` here."""
        self.policy.moved_to(ident, baud)
        dev = self.devices.take(ident)
        if dev is not None:
            dev.baud = baud
            there = self.by_baud.at(baud)
            if there is not self.devices:
                # a late reply to what was asked of it here is still one it owed
                self.devices[ident].asked = max(0, dev.asked - dev.replies)
            there.put(dev)

    def latencies(self) -> dict:
        """What the bus learned: {ID: {"latency_ms", "variation_ms", "samples", "late"}}."""
        return self.policy.summary()


def set_low_latency(port):
    """Ask the serial driver for low-latency mode (Linux ``ASYNC_LOW_LATENCY``: an FTDI adapter
    then uses a 1 ms latency timer). ``(True, None)`` when done, ``(False, reason)`` where the
    platform or the port has no such mode."""
    setter = getattr(port, "set_low_latency_mode", None)
    if setter is None:
        return False, "this port has no low-latency mode"
    try:
        setter(True)
    except (ValueError, OSError, NotImplementedError) as e:
        return False, str(e) or type(e).__name__
    except Exception as e:  # noqa: BLE001 - serial.SerialException from the ioctl
        return False, str(e) or type(e).__name__
    return True, None


def open_bus(port=None, baud=57600, *, sim=False, sim_ids=None, timeout=None, return_mode=1,
             retries=RETRIES, sim_options=None, stop_bits=1, latency=None, low_latency=False,
             allow=None, protocol="ir", regmap=None) -> ZapBus:
    """Open ``port`` (any pyserial URL or device, or the in-process simulator with ``sim``;
    ``sim_ids`` are the simulated bus's actuator IDs) and return a :class:`ZapBus` of the
    ``protocol`` family (``"modbus"``: a :class:`~zkzap.link.modbus_bus.ModbusBus` on ``regmap``,
    default the 17Lf's; ``return_mode`` and ``sim_options`` are the IR bus's). ``latency``
    (seconds) is the actuators' known latency before any is measured; ``low_latency`` asks the
    driver for its low-latency mode (:attr:`ZapBus.low_latency` says whether it could)."""
    from .port import sim_url

    modbus = protocol == "modbus"
    if sim:
        opts = dict(sim_options or {}) if not modbus else {"protocol": "modbus"}
        opts.setdefault("ids", sim_ids or ("1" if modbus else "0"))
        if modbus or baud in zap.BAUD_TO_CODE:
            opts.setdefault("baud", str(baud))
        url = sim_url("zap", **opts)
    else:
        if not port:
            raise UsageError("no port", no_port="zap")
        url = port
    if modbus:
        from .modbus_bus import ModbusBus

        return open_on(url, baud, stop_bits, allow, low_latency, ModbusBus, regmap=regmap, timeout=timeout,
                       retries=retries, latency=latency, speaks="modbus")
    return open_on(url, baud, stop_bits, allow, low_latency, ZapBus, return_mode=return_mode, timeout=timeout,
                   retries=retries, latency=latency)


def open_on(url, baud, stop_bits, allow, low_latency, cls, speaks=None, **kw):
    """A bus of class ``cls`` (``**kw``: its options) on the port ``url`` opened at ``baud``,
    given ``allow``, in the driver's low-latency mode when asked; ``speaks``: its protocol in a
    capture, where not the IR protocol's."""
    from .port import open_port

    p = open_port(url, baud, timeout=0.1, stop_bits=stop_bits, speaks=speaks)
    bus = cls(p, url=url, **kw)
    bus.allow = as_permission(allow)
    if low_latency:
        bus.low_latency, bus.low_latency_reason = set_low_latency(p)
    return bus
