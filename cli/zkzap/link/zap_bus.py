"""mightyZAP transactions: send a packet, wait for exactly the feedback the actuator will give.

Which commands are answered depends on the actuator's feedback-return mode (register 0x10):
0 answers Echo only; 1 (the default) Load Data and Echo; 2 every command; a broadcast (ID 254)
never. :class:`ZapBus` is told the mode (``return_mode``, default 1, or :meth:`detect_return_mode`)
and waits only when a reply will come.

Timing policy (every figure in seconds, derived from the baud rate at 10 bits per byte):

- **Deadline for a reply**: both packets on the wire, plus the turnaround allowance
  (:data:`MAX_TURNAROUND`, 20 ms: real actuators and USB adapters answer up to that late), plus
  a host margin (:data:`MARGIN`, plus the USB adapter's latency timer when the port is a
  ``/dev/ttyUSB*`` with one, plus :data:`NETWORK_MARGIN` for a ``socket://``/``rfc2217://``
  port on another host), plus the memory pause after a write to stored registers. A reply
  that comes at once ends the wait at once: the allowance costs time only when nothing comes.
  ``timeout=`` replaces the whole figure.
- **Trickling bytes**: once reply bytes arrive, the deadline extends to :data:`INTER_BYTE`
  (plus one byte time and the margin) after the latest byte, as long as a packet is
  incomplete, so a device or adapter that sends its bytes 1 ms apart is read whole.
- **Learned turnaround**: every answered attempt gives a turnaround estimate (round trip
  minus both packets' wire time). Probes where silence is the expected answer (:meth:`ZapBus.ping`
  with ``quick=True``, used by scans) wait only for the first byte within the bus's typical
  turnaround (the median estimate, x1.25, at least :data:`TURNAROUND`), so a bus whose
  actuators answer in 2 ms is scanned at wire speed; a slower reply is caught as late.
- **Attribution**: before each attempt the bytes already received are read and examined
  (never thrown away unseen); every attempt that went unanswered is remembered for
  :data:`LATE_WINDOW` as owing a reply (its ID and the reply's data length). A reply that
  matches an owed attempt of another request is counted as late (:attr:`ZapBus.late`, and an
  event for scans) and never taken as the answer to the request in hand; a reply to an
  earlier attempt of the same request answers it, with the round trip measured from that
  attempt.

Every reply is checked: checksum (through :class:`~zkzap.codec.framing.ZapFramer`), ID, data
length. A half-duplex adapter that echoes our own bytes is recognised (a copy of what we sent)
and the copy skipped. A failed attempt is retried ``retries`` times; then the failure is raised
as :class:`~zkzap.errors.NoReply` (exit 3), :class:`~zkzap.errors.BadReply` (exit 6); error bits
in a reply as :class:`~zkzap.errors.DeviceError` (exit 5, the reply attached as ``.reply``); a
port that fails or vanishes as :class:`~zkzap.errors.PortError` (exit 4).
"""

from __future__ import annotations

import os
import select
import time
from collections import deque
from urllib.parse import urlsplit

from ..codec import zap
from ..codec.framing import ZapFramer
from ..errors import BadReply, DeviceError, NoReply, OutputError, PortError, UsageError
from . import stop
from .port import close_port, wire_time

#: The typical actuator turnaround (a 12Lf answers in about 2 ms): the floor of the quick
#: probes' allowance before any reply has been seen.
TURNAROUND = 0.002
#: The default allowance for the actuator's turnaround before its first reply byte.
MAX_TURNAROUND = 0.020
#: Allowance between two reply bytes (on top of one byte time and the margin).
INTER_BYTE = 0.010
#: Host allowance of a quick probe (a late reply is still recognised afterwards).
QUICK_MARGIN = 0.0005
#: How long an unanswered attempt may still be answered: its reply is then recognised as late.
LATE_WINDOW = 0.15
#: Read granularity on ports without a file descriptor (URL ports).
QUANTUM = 0.001
#: Host-side allowance: scheduling, pty/USB transfer.
MARGIN = 0.0025
#: Extra allowance for a socket:// or rfc2217:// port on another host.
NETWORK_MARGIN = 0.02
#: Allowance for the memory pause after a write to stored (NV) registers.
NV_PAUSE = 0.008
#: Quiet time after Restart / Factory Reset before the next command in the same run.
RESTART_PAUSE = 0.1
#: Default number of retries after a failed attempt.
RETRIES = 2

_LOOPBACK = ("localhost", "127.0.0.1", "::1", "")


def is_simulated(url) -> bool:
    """True for ports where nothing real can be harmed: the in-process simulator and loop://."""
    return bool(url) and str(url).startswith(("sim://", "loop://"))


def host_margin(url) -> float:
    """The host margin for ``url``: :data:`MARGIN`, plus a USB adapter's latency timer, plus
    :data:`NETWORK_MARGIN` for a remote network port."""
    margin = MARGIN
    if not url:
        return margin
    url = str(url)
    if "://" in url:
        parts = urlsplit(url)
        if parts.scheme in ("socket", "rfc2217") and (parts.hostname or "") not in _LOOPBACK:
            margin += NETWORK_MARGIN
        return margin
    latency = usb_latency(url)
    return margin + (latency or 0.0)


def usb_latency(device: str):
    """The latency timer (seconds) of a USB serial adapter (FTDI: 16 ms by default), or None."""
    try:
        name = os.path.basename(os.path.realpath(device))
        with open(f"/sys/bus/usb-serial/devices/{name}/latency_timer", encoding="ascii") as f:
            return int(f.read().strip()) / 1000.0
    except (OSError, ValueError):
        return None


class Reply:
    """A checked feedback packet: ``ident``, ``error`` (bits), ``data`` (parameter bytes),
    ``packet`` (the whole packet) and ``rtt`` (seconds from the end of our write)."""

    __slots__ = ("ident", "error", "data", "packet", "rtt")

    def __init__(self, ident: int, error: int, data: bytes, packet: bytes, rtt: float = 0.0) -> None:
        self.ident, self.error, self.data, self.packet, self.rtt = ident, error, data, packet, rtt

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


def writes_id(pkt: bytes) -> bool:
    """True when the packet writes the ID register (Store/Send Data, Symmetric Store)."""
    code, params = pkt[5], bytes(pkt[6:-1])
    addr = zap.REGISTER_BY_NAME["id"].address
    if code in (0xF3, 0xF4) and len(params) >= 2:
        return params[0] <= addr < params[0] + len(params) - 1
    if code == 0x73 and len(params) >= 2:
        return params[1] > 0 and params[0] <= addr < params[0] + params[1]
    return False


class _Owed:
    """An attempt that went unanswered: its reply may still come (late)."""

    __slots__ = ("token", "ids", "data_len", "t0", "until", "due")

    def __init__(self, token, ids, data_len, t0, until, due=None):
        self.token, self.ids, self.data_len, self.t0, self.until = token, ids, data_len, t0, until
        self.due = t0 if due is None else due     # by when the full allowance expected the reply

    def matches(self, p) -> bool:
        return p[3] in self.ids and (self.data_len is None or len(p) - 7 == self.data_len)


class ZapBus:
    """Transactions on one port. ``return_mode`` is the bus's feedback-return mode (0, 1, 2);
    ``timeout`` (seconds) overrides the derived reply timeout; ``retries`` after a failure;
    ``turnaround`` (seconds) is the allowance for the actuator's turnaround (default
    :data:`MAX_TURNAROUND`)."""

    def __init__(self, port, *, return_mode: int = 1, timeout=None, retries: int = RETRIES, margin=None,
                 url=None, turnaround=None):
        self.port = port
        self.url = url if url is not None else getattr(port, "port", None) or getattr(port, "portstr", "")
        self.return_mode = return_mode
        self.timeout = timeout
        self.retries = retries
        self.margin = host_margin(self.url) if margin is None else margin
        self.turnaround = MAX_TURNAROUND if turnaround is None else turnaround
        self.adapter_echo = False          # learned: the adapter echoes what we send
        self._recent = deque(maxlen=8)     # packets we sent lately (their echoes are skipped)
        self._owed = deque()               # unanswered attempts whose reply may still come
        self._turnarounds = deque(maxlen=32)   # turnaround estimates of answered attempts
        self.lateness = 0.0                # how far past the full allowance the slowest late reply came (s)
        self._quiet_until = 0.0
        self._port_timeout = object()
        fd = getattr(port, "fd", None)
        self._fd = fd if isinstance(fd, int) and hasattr(port, "in_waiting") else None
        self.events = []                   # ("late", ID, time) / ("garbled", None, time), for scans
        self.sent = 0
        self.replies = 0
        self.retried = 0
        self.late = 0                      # replies recognised as late (answers to earlier attempts)
        self.stale = 0                     # other stray packets skipped (acks nobody waited for)

    # -- line -----------------------------------------------------------------------------------

    @property
    def baud(self) -> int:
        return self.port.baudrate

    @property
    def stop_bits(self) -> int:
        return int(getattr(self.port, "stopbits", 1) or 1)

    def set_baud(self, baud: int) -> None:
        """Switch the port's line speed, once what was sent has left at the old speed."""
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
        self._owed.clear()                 # nothing said at the old speed is heard at the new one

    def close(self) -> None:
        close_port(self.port)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def reply_timeout(self, tx_bytes: int, rx_bytes: int, extra: float = 0.0) -> float:
        """The derived timeout: both packets on the wire + turnaround allowance + margin +
        ``extra`` (or ``timeout`` when given)."""
        if self.timeout is not None:
            return self.timeout
        return wire_time(tx_bytes + rx_bytes, self.baud, self.stop_bits) + self.turnaround + self.margin + extra

    def reply_timeout_derived(self, tx_bytes: int, rx_bytes: int, extra: float = 0.0) -> float:
        """The derived timeout, whatever ``timeout`` says."""
        return wire_time(tx_bytes + rx_bytes, self.baud, self.stop_bits) + self.turnaround + self.margin + extra

    def linger(self, seconds: float) -> None:
        """Keep reading for ``seconds`` (late replies are accounted for; see :attr:`events`)."""
        end = time.monotonic() + seconds
        while True:
            self._drain()
            left = end - time.monotonic()
            if left <= 0:
                break
            time.sleep(min(0.002, left))
        self._drain()

    @property
    def typical_turnaround(self):
        """The median turnaround estimate of the answered attempts so far (None before any)."""
        if not self._turnarounds:
            return None
        values = sorted(self._turnarounds)
        return values[len(values) // 2]

    def quick_timeout(self, tx_bytes: int) -> float:
        """A probe's wait when silence is the expected answer: our packet and the reply's first
        byte on the wire, plus the typical turnaround x1.25 (at least :data:`TURNAROUND` plus the
        adapter's latency), plus :data:`QUICK_MARGIN`. A slower reply is caught as late."""
        if self.timeout is not None:
            return self.timeout
        floor = TURNAROUND + max(0.0, self.margin - MARGIN)
        typical = self.typical_turnaround
        allowance = floor if typical is None else max(floor, typical * 1.25)
        allowance = min(allowance, self.turnaround + self.margin)
        return wire_time(tx_bytes + 1, self.baud, self.stop_bits) + allowance + QUICK_MARGIN

    def expects_reply(self, pkt: bytes, return_mode=None) -> bool:
        ins = zap.INSTRUCTION_BY_CODE.get(pkt[5])
        mode = self.return_mode if return_mode is None else return_mode
        return ins is not None and ins.answered(mode, pkt[3])

    def _port_error(self, e) -> PortError:
        from .port import port_failed

        return port_failed(self.url, e)

    def _write(self, pkt: bytes) -> float:
        """Drain, then write ``pkt``; returns the time just before the write (round trips are
        measured from there, so a host that is preempted after writing never shortens them)."""
        self._drain()
        t0 = time.monotonic()
        try:
            self.port.write(pkt)
        except Exception as e:  # serial.SerialException, OSError: the port failed or vanished
            if isinstance(e, (KeyboardInterrupt, PortError, OutputError)):
                raise
            raise self._port_error(e) from None
        self.sent += 1
        self._recent.append(bytes(pkt))
        return t0

    def _set_timeout(self, value) -> None:
        if self._port_timeout != value:
            self.port.timeout = value
            self._port_timeout = value

    def _read(self, n: int, deadline: float) -> bytes:
        """Bytes received by ``deadline`` (returns as soon as some are there; at most ``n`` on
        ports read by size). Past the deadline it still returns what is already waiting: a host
        held up (a loaded machine) must not take a reply that arrived meanwhile for silence."""
        try:
            if self._fd is not None:
                self._set_timeout(0)
                left = deadline - time.monotonic()
                if left > 0:
                    ready, _, _ = select.select([self._fd], [], [], left)
                    if not ready:
                        return b""
                return self.port.read(max(1, self.port.in_waiting))
            left = deadline - time.monotonic()
            # past the deadline (the host was held up): still take what has arrived meanwhile
            self._set_timeout(QUANTUM if left > 0 else 0)
            return self.port.read(n)
        except Exception as e:
            if isinstance(e, (KeyboardInterrupt, PortError)):
                raise
            raise self._port_error(e) from None

    def _drain(self, until=None, ids=None, token=None):
        """Read what has arrived since the last transaction and account for it: late replies to
        unanswered attempts are counted (and reported as events), the rest skipped as stale. A
        packet caught half-way is read to its end. With ``until``/``ids``: also wait (at most
        until ``until``) for the owed replies of those IDs. With ``token``: a late reply to an
        earlier attempt of that request is returned (as its :class:`Reply`), not counted."""
        framer = ZapFramer()
        answer = None
        while True:
            now = time.monotonic()
            while self._owed and self._owed[0].until < now:
                self._owed.popleft()
            try:
                waiting = self.port.in_waiting
            except Exception:  # noqa: BLE001 - a port without in_waiting (or a vanished one)
                waiting = None
            if waiting is None:
                try:
                    self.port.reset_input_buffer()
                except Exception as e:
                    if isinstance(e, KeyboardInterrupt):
                        raise
                    raise self._port_error(e) from None
                return None
            owed = ids is not None and any(o.token is not None and o.ids & ids for o in self._owed)
            if waiting:
                data = self._read(waiting, now) if self._fd is not None else self._read_waiting(waiting)
            elif framer.pending or owed:
                limit = now + wire_time(1, self.baud, self.stop_bits) + INTER_BYTE + self.margin
                if owed and not framer.pending:
                    limit = min(until, min(o.until for o in self._owed if o.token is not None and o.ids & ids))
                if now >= limit:
                    break
                data = self._read(64, limit)
                if not data and framer.pending and time.monotonic() >= limit:
                    break
            else:
                break
            for p in framer.feed(data) if data else ():
                answer = self._stray(bytes(p), token) or answer
        for p in framer.flush():
            answer = self._stray(bytes(p), token) or answer
        if framer.bad or framer.skipped:
            self.events.append(("garbled", None, time.monotonic()))
        return answer

    def _read_waiting(self, n: int) -> bytes:
        try:
            self._set_timeout(0)
            return self.port.read(n)
        except Exception as e:
            if isinstance(e, (KeyboardInterrupt, OutputError)):
                raise
            raise self._port_error(e) from None

    def _stray(self, p: bytes, token=None):
        """Account for a packet read between attempts: a late reply to an earlier attempt of
        request ``token`` is returned as its Reply; other late replies are counted."""
        if p in self._recent or zap.is_command(p[5]):
            return None                    # our own echo, or another master's command
        if token is not None:
            owed = self._take_owed(p, token)
            if owed is not None:
                return self._reply(p, time.monotonic() - owed.t0)
        owed = self._take_owed(p)
        if owed is not None and owed.token is not None:
            self._late(p, owed, time.monotonic())
            return None
        self.stale += 1
        return None

    def _late(self, p, owed, now) -> None:
        """Account for ``p``, the late reply to the unanswered attempt ``owed``: counted, reported
        to scans, and how far past its wait it came kept (:attr:`lateness`). Its round trip is
        not learned as a turnaround: quick probes stay quick, and a scan asks again around it."""
        self.late += 1
        self.events.append(("late", p[3], now))
        # how far past the full allowance its first byte came (a quick probe's shorter wait
        # says nothing of the actuator's speed)
        past = now - wire_time(len(p), self.baud, self.stop_bits) - owed.due
        self.lateness = min(LATE_WINDOW, max(self.lateness, past))

    def _take_owed(self, p, token=None):
        now = time.monotonic()
        for owed in self._owed:
            if owed.until >= now and owed.matches(p) and (token is None or owed.token is token):
                self._owed.remove(owed)
                return owed
        return None

    def take_events(self) -> list:
        """The late/garbled events seen since the last call (for scans)."""
        out, self.events = self.events, []
        return out

    def _settle(self) -> None:
        wait = self._quiet_until - time.monotonic()
        if wait > 0:
            time.sleep(wait)

    def _learn(self, rtt: float, tx: int, rx: int) -> None:
        self._turnarounds.append(max(0.0, rtt - wire_time(tx + rx, self.baud, self.stop_bits)))

    # -- one transaction ----------------------------------------------------------------------

    def transact(self, pkt: bytes, *, reply=None, data_len=None, extra=0.0, timeout=None, retries=None,
                 accept_ids=None, check=True, optional=False, quick=False):
        """Send ``pkt``; return its checked :class:`Reply`, or None when none is expected.

        ``reply``: whether a reply comes (default: from the instruction and ``return_mode``);
        ``data_len``: data bytes the reply must carry (None: any); ``extra``: seconds added to
        the derived timeout; ``accept_ids``: IDs a reply may carry (default: the packet's);
        ``check``: raise DeviceError for error bits; ``optional``: no reply is not an error
        (returns None at once, without a retry: the command may have been carried out);
        ``quick``: wait only the quick probe's time (:meth:`quick_timeout`) for a first byte.
        """
        stop.check()                       # a stop requested (a batch's Ctrl-C) ends the command here
        pkt = bytes(pkt)
        ident = pkt[3]
        if reply is None:
            reply = self.expects_reply(pkt)
        stored = stored_writes(pkt)
        restart = pkt[5] in zap.RESTART_CODES
        extra = extra + (NV_PAUSE if stored else 0.0)
        tries = 1 + (self.retries if retries is None else retries)
        accept = set(accept_ids) if accept_ids else {ident}
        if not reply:
            self._settle()
            self._write(pkt)
            gap = wire_time(len(pkt), self.baud, self.stop_bits)
            gap += RESTART_PAUSE if restart else (NV_PAUSE if stored else 0.0)
            self._quiet_until = time.monotonic() + gap
            if ident != zap.BROADCAST:
                # an actuator in another return mode may acknowledge anyway: skip that ack later
                now = time.monotonic()
                self._owed.append(_Owed(None, accept, None, now, now + LATE_WINDOW))
            return None
        rx_len = 7 + (data_len or 0)
        if timeout is not None:
            limit = timeout
        elif quick:
            limit = self.quick_timeout(len(pkt)) + extra
        else:
            limit = self.reply_timeout(len(pkt), rx_len, extra)
        # by when the full allowance expects a reply (a quick probe's own wait is shorter)
        full = self.reply_timeout(len(pkt), rx_len, extra) if quick and timeout is None else limit
        token = object()
        problems = []
        if any(o.token is not None and o.ids & accept for o in self._owed):
            # a reply to an earlier request to this actuator may still come: let it come (or its
            # window pass) so that it cannot be taken for the answer to this one
            self._drain(time.monotonic() + LATE_WINDOW, accept)
        for attempt in range(tries):
            got = None
            if attempt:
                self.retried += 1
                got = self._drain(token=token)     # the last attempt's reply, come just too late?
            if got is None:
                self._settle()
                t0 = self._write(pkt)
                got = self._await(pkt, accept, data_len, rx_len, t0, limit, restart, token, full)
            if isinstance(got, Reply):
                self.replies += 1
                self._learn(got.rtt, len(pkt), rx_len)
                if restart:
                    self._quiet_until = time.monotonic() + RESTART_PAUSE
                elif stored:
                    self._quiet_until = time.monotonic() + NV_PAUSE
                if check and got.error:
                    raise device_error(got)
                return got
            problems.append(got)
            if got[0] == "none":
                self._owed.append(_Owed(token, accept, data_len, t0, t0 + limit + LATE_WINDOW, t0 + full))
                if optional:
                    return None            # silence is a legitimate answer: do not repeat the command
        return self._fail(pkt, problems, limit, tries, optional)

    def _await(self, pkt, accept, data_len, rx_len, t0, limit, restart, token, full):
        """Read until a valid reply or the deadline (``limit`` after ``t0``; ``full`` is the
        full allowance, which a quick probe's ``limit`` is shorter than). Returns a Reply (``rtt``
        from the attempt that was answered) or a problem tuple (kind, detail, received bytes)."""
        framer = ZapFramer()
        received = bytearray()
        echo_known = self.adapter_echo
        state = {"copies": 0, "want": rx_len + (len(pkt) if echo_known else 0), "mismatch": None,
                 "explained": 0}
        wrong = []
        deadline = t0 + limit
        physical = wire_time(len(pkt) + rx_len, self.baud, self.stop_bits)

        def examine(packets):
            for p in packets:
                p = bytes(p)
                state["explained"] += len(p)
                if p == pkt:
                    state["copies"] += 1
                    self.adapter_echo = True
                    state["want"] = max(state["want"], len(received) + rx_len)
                    continue
                if p in self._recent or zap.is_command(p[5]):
                    continue                      # a late echo of an earlier packet, another master
                now = time.monotonic()
                owed = self._take_owed(p)
                if owed is not None and owed.token is None and p[3] in accept and data_len is not None:
                    self._owed.appendleft(owed)   # maybe an unasked ack; judged by its length below
                elif owed is not None and owed.token is None:
                    self.stale += 1               # an acknowledgement nobody waited for
                    continue
                elif owed is not None:
                    if owed.token is token and token is not None:
                        if now - t0 < physical:
                            # too early for this attempt: an earlier attempt's reply answers it
                            self._owed.append(_Owed(token, accept, data_len, t0, t0 + limit + LATE_WINDOW, t0 + full))
                            return self._reply(p, now - owed.t0)
                        self._owed.appendleft(owed)      # this attempt's; the earlier one stays owed
                    else:
                        self._late(p, owed, now)
                        state["want"] = len(received) + rx_len
                        continue
                if p[3] not in accept:
                    wrong.append(p)
                    state["want"] = len(received) + rx_len
                    continue
                data = p[6:-1]
                if data_len is not None and len(data) != data_len:
                    self.stale += 1               # an ack nobody waited for; the reply may follow
                    state["mismatch"] = (len(data), bytes(p))
                    state["want"] = len(received) + rx_len
                    continue
                if framer.bad or framer.skipped:
                    # bytes that made no packet came first: a collision (two actuators with one
                    # ID answering a probe that already gave up), for scans
                    self.events.append(("garbled", None, now))
                return self._reply(p, now - t0)
            return None

        while True:
            chunk = self._read(max(1, state["want"] - len(received)), deadline)
            if not chunk:
                if time.monotonic() >= deadline:
                    break
                continue
            received += chunk
            got = examine(framer.feed(chunk))
            if got is not None:
                return got
            if framer.pending:
                # bytes of an incomplete packet: give the rest time to trickle in
                more = time.monotonic() + wire_time(1, self.baud, self.stop_bits) + INTER_BYTE + self.margin
                deadline = max(deadline, more)
        pending, bad_before = framer.pending, framer.bad
        got = examine(framer.flush())               # a packet held back to rule out a rival
        if framer.bad or len(received) > state["explained"]:
            self.events.append(("garbled", None, time.monotonic()))   # a collision, for scans
        if got is not None:
            return got
        copies = state["copies"]
        # The documented Restart feedback is a copy of the command itself: accept a copy that
        # is more than the adapter's known echo.
        if restart and not wrong and copies >= (2 if echo_known else 1):
            return self._reply(pkt, time.monotonic() - t0, copy=True)
        if wrong:
            ids = ", ".join(str(p[3]) for p in wrong)
            return ("wrong-id", f"reply from ID {ids}, expected ID {min(accept)}", bytes(received))
        if state["mismatch"] is not None:
            n = state["mismatch"][0]
            return ("length", f"reply carries {n} data bytes, expected {data_len}", bytes(received))
        if pending and not bad_before and bytes(received[-pending:]).startswith(b"\xff"):
            return ("truncated", f"truncated reply ({pending} bytes of an incomplete packet)",
                    bytes(received))
        if framer.bad:
            return ("checksum", "corrupted reply (checksum mismatch)", bytes(received))
        if len(received) > state["explained"]:
            return ("garbage", "unreadable bytes instead of a reply (wrong baud rate?)", bytes(received))
        return ("none", "echo only" if copies else "", bytes(received))

    @staticmethod
    def _reply(p, rtt, copy=False):
        if copy:
            return Reply(p[3], 0, b"", p, rtt)
        return Reply(p[3], p[5], p[6:-1], p, rtt)

    def _fail(self, pkt, problems, limit, tries, optional):
        ident = pkt[3]
        kinds = [p[0] for p in problems]
        if all(k == "none" for k in kinds):
            if optional:
                return None
            ms = limit * 1000
            echo = any(p[1] == "echo only" for p in problems)
            note = " (only our own bytes came back: the adapter echoes)" if echo else ""
            ins = zap.INSTRUCTION_BY_CODE.get(pkt[5])
            raise NoReply(f"no reply from ID {ident} at {self.baud} baud within {ms:.1f} ms "
                          f"({tries} {'try' if tries == 1 else 'tries'}){note}",
                          ident=ident, baud=self.baud, timeout=limit, tries=tries, echo_only=echo,
                          mode_dependent=ins is not None and ins.reply != "always", protocol="zap")
        bad = [p for p in problems if p[0] != "none"][-1]
        seen = bad[2].hex(" ").upper() if bad[2] else "nothing"
        if len(seen) > 120:
            seen = seen[:117] + "..."
        raise BadReply(f"ID {ident}: {bad[1]} after {tries} {'try' if tries == 1 else 'tries'}; received {seen}",
                       kind=bad[0], ident=ident, baud=self.baud, timeout=limit, tries=tries, received=bad[2],
                       protocol="zap")

    # -- instructions -------------------------------------------------------------------------

    def command(self, pkt: bytes, *, check=True, optional=None):
        """Send any command packet and wait for what it gets (inferred from the packet): Load
        Data's data length, an ID change answered by the new ID, an unknown instruction's
        optional reply."""
        pkt = bytes(pkt)
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
            old = self.return_mode
            kw["reply"] = self.expects_reply(pkt, old) or self.expects_reply(pkt, new)
            kw["optional"] = self.expects_reply(pkt, old) != self.expects_reply(pkt, new)
            try:
                return self.transact(pkt, check=check, **kw)
            finally:
                self.return_mode = new
        ins = zap.INSTRUCTION_BY_CODE.get(code)
        if (ins is None or not ins.documented) and pkt[3] != zap.BROADCAST:
            kw["reply"] = True
            kw["optional"] = True
        if optional is not None:
            kw["optional"] = optional
        return self.transact(pkt, check=check, **kw)

    def echo(self, ident: int, **kw) -> Reply:
        return self.transact(zap.echo(ident), reply=True, **kw)

    def load(self, ident: int, address: int, length: int, **kw) -> Reply:
        """Load Data: ``length`` bytes from ``address``."""
        if self.return_mode == 0:
            raise UsageError("load: in feedback-return-mode 0 Load Data is never answered",
                             ident=ident, return_mode=0, assumed_mode=True)
        return self.transact(zap.load(ident, address, length), reply=True, data_len=length, **kw)

    def read(self, ident: int, reg, **kw) -> int:
        reg = zap.register(reg)
        return self.load(ident, reg.address, reg.size, **kw).value

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

    def symmetric_store(self, reg, targets) -> None:
        for pkt in zap.symmetric_store(reg, targets):
            self.command(pkt)

    def ping(self, ident: int, *, timeout=None, retries=0, quick=False, extra=0.0):
        """Echo that returns None when nothing answers (for scans); a corrupted reply is
        retried ``retries`` times and then raised as BadReply. ``quick``: wait only the quick
        probe's time (a slower reply is recognised as late later: see :attr:`events`);
        ``extra``: seconds added to the wait (see :meth:`patience`)."""
        return self.transact(zap.echo(ident), reply=True, timeout=timeout, retries=retries, optional=True,
                             check=False, quick=quick, extra=extra)

    def patience(self) -> float:
        """What to add to the wait when asking again where replies came late: 1.5x how far past
        the full allowance the slowest late reply came (:attr:`lateness`), at most :data:`LATE_WINDOW`;
        0.0 when every reply so far came in time. An actuator slower than the allowance (or one
        held up, like a simulator on a loaded machine) is then heard instead of colliding with
        the next request. An explicit ``timeout`` is never widened."""
        return min(LATE_WINDOW, 1.5 * self.lateness)

    def answers(self, ident: int, *, tries: int = 3) -> bool:
        """Whether any actuator answers to ``ident``: Echo with the full allowance up to
        ``tries`` times; a reply with error bits, a garbled reply or a late reply from
        ``ident`` all count as an answer. Only ``tries`` silences in a row say it is free."""
        self.take_events()
        for _ in range(tries):
            try:
                if self.ping(ident) is not None:
                    return True
            except BadReply:
                return True
            if any(kind == "late" and who == ident for kind, who, _ in self.events):
                return True
        self._settle()
        end = time.monotonic() + self.turnaround + self.margin + self.patience()
        while time.monotonic() < end:               # a reply slower than every wait above
            time.sleep(min(0.005, max(0.0, end - time.monotonic())))
        self._drain()
        return any(kind == "late" and who == ident for kind, who, _ in self.take_events())

    def detect_return_mode(self, ident: int) -> int:
        """Ask the actuator: Load feedback-return-mode (answered in modes 1 and 2); no answer
        but an Echo reply means mode 0. Sets and returns :attr:`return_mode`."""
        reg = zap.REGISTER_BY_NAME["feedback-return-mode"]
        r = self.transact(zap.load(ident, reg.address, 1), reply=True, data_len=1, optional=True, check=False)
        if r is not None and r.value in (0, 1, 2):
            self.return_mode = r.value
            return r.value
        self.echo(ident, check=False)
        self.return_mode = 0
        return 0

    def wait_ready(self, ident: int, within: float = 2.0, check=False) -> Reply:
        """Echo ``ident`` until it answers (after a restart or a baud change) or ``within``
        seconds pass (NoReply)."""
        end = time.monotonic() + within
        while True:
            self._settle()
            r = self.ping(ident, retries=1)
            if r is not None:
                if check and r.error:
                    raise device_error(r)
                return r
            if time.monotonic() >= end:
                raise NoReply(f"no reply from ID {ident} at {self.baud} baud within {within:g} s",
                              ident=ident, baud=self.baud, timeout=within, protocol="zap")
            time.sleep(0.005)


def open_bus(port=None, baud=57600, *, sim=False, sim_ids=None, timeout=None, return_mode=1,
             retries=RETRIES, sim_options=None, stop_bits=1) -> ZapBus:
    """Open ``port`` (any pyserial URL or device, or the in-process simulator with ``sim``;
    ``sim_ids`` are the simulated bus's actuator IDs) and return a :class:`ZapBus`."""
    from .port import open_port, sim_url

    if sim:
        opts = dict(sim_options or {})
        opts.setdefault("ids", sim_ids or "0")
        if baud in zap.BAUD_TO_CODE:
            opts.setdefault("baud", str(baud))
        url = sim_url("zap", **opts)
    else:
        if not port:
            raise UsageError("no port", no_port="zap")
        url = port
    p = open_port(url, baud, timeout=0.1, stop_bits=stop_bits)
    return ZapBus(p, return_mode=return_mode, timeout=timeout, retries=retries, url=url)
