"""mightyZAP transactions: send a packet, wait for exactly the feedback the actuator will give.

Which commands are answered depends on the actuator's feedback-return mode (register 0x10):
0 answers Echo only; 1 (the default) Load Data and Echo; 2 every command; a broadcast (ID 254)
never. :class:`ZapBus` is told the mode (``return_mode``, default 1, or :meth:`detect_return_mode`)
and waits only when a reply will come.

Timeouts are derived from the baud rate: the bytes on the wire both ways at 10 bits per byte,
plus the actuator's turnaround (:data:`TURNAROUND`), plus a host margin (:data:`MARGIN`, plus
the USB adapter's latency timer when the port is a ``/dev/ttyUSB*`` with one, plus
:data:`NETWORK_MARGIN` for a ``socket://``/``rfc2217://`` port on another host), plus the
memory pause after a write to stored registers. ``timeout=`` overrides the whole figure.

Every reply is checked: checksum (through :class:`~zkzap.codec.framing.ZapFramer`), ID, data
length. A half-duplex adapter that echoes our own bytes is recognised (a copy of what we sent)
and the copy skipped. A failed attempt is retried ``retries`` times; then the failure is raised
as :class:`~zkzap.errors.NoReply` (exit 3), :class:`~zkzap.errors.BadReply` (exit 6); error bits
in a reply as :class:`~zkzap.errors.DeviceError` (exit 5, the reply attached as ``.reply``); a
port that fails or vanishes as :class:`~zkzap.errors.PortError` (exit 4).
"""

from __future__ import annotations

import os
import time
from collections import deque
from urllib.parse import urlsplit

from ..codec import zap
from ..codec.framing import ZapFramer
from ..errors import BadReply, DeviceError, NoReply, PortError, UsageError
from .port import close_port, wire_time

#: Allowance for the actuator's processing before it answers (seconds).
TURNAROUND = 0.002
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

    def __init__(self, ident, error, data, packet, rtt=0.0):
        self.ident, self.error, self.data, self.packet, self.rtt = ident, error, data, packet, rtt

    @property
    def errors(self) -> list:
        return zap.error_names(self.error)

    @property
    def value(self) -> int:
        return int.from_bytes(self.data, "little")

    def __repr__(self):
        return f"Reply(id={self.ident}, error=0x{self.error:02x}, data={self.data.hex(' ')})"


def error_message(reply: Reply) -> str:
    texts = [zap.ERROR_TEXT.get(n, n) for n in reply.errors]
    return f"ID {reply.ident} reports error 0x{reply.error:02X}: " + "; ".join(texts)


def device_error(reply: Reply) -> DeviceError:
    e = DeviceError(error_message(reply))
    e.reply = reply
    return e


def stored_writes(pkt: bytes) -> list:
    """Names of the stored (NV) settings a command packet writes (for consent and pauses)."""
    code, params = pkt[5], pkt[6:-1]
    if code in (0xF3, 0xF4) and len(params) >= 2:
        return _stored_in(params[0], len(params) - 1)
    if code == 0x73 and len(params) >= 2:
        return _stored_in(params[0], params[1])
    if code == 0xF6:
        return ["every stored setting (factory reset)"]
    return []


def _stored_in(address: int, length: int) -> list:
    names = []
    for addr in range(address, min(address + length, 256)):
        reg = zap.REGISTER_BY_ADDRESS.get(addr)
        if reg is not None and reg.stored and reg.name not in names:
            names.append(reg.name)
    return names


def leaves_protocol(pkt: bytes) -> bool:
    """True when the packet writes 0 (Modbus RTU) to protocol-type: the actuator would leave
    this protocol and no longer answer it."""
    code, params = pkt[5], bytes(pkt[6:-1])
    addr = zap.REGISTER_BY_NAME["protocol-type"].address
    if code in (0xF3, 0xF4) and len(params) >= 2 and params[0] <= addr < params[0] + len(params) - 1:
        return params[1 + addr - params[0]] == 0
    if code == 0x73 and len(params) >= 2 and params[1]:
        start, length = params[0], params[1]
        if start <= addr < start + length:
            body = params[2:]
            step = 1 + length
            return any(body[j + 1 + addr - start] == 0 for j in range(0, len(body) - step + 1, step))
    return False


class ZapBus:
    """Transactions on one port. ``return_mode`` is the bus's feedback-return mode (0, 1, 2);
    ``timeout`` (seconds) overrides the derived reply timeout; ``retries`` after a failure."""

    def __init__(self, port, *, return_mode: int = 1, timeout=None, retries: int = RETRIES, margin=None,
                 url=None):
        self.port = port
        self.url = url if url is not None else getattr(port, "port", None) or getattr(port, "portstr", "")
        self.return_mode = return_mode
        self.timeout = timeout
        self.retries = retries
        self.margin = host_margin(self.url) if margin is None else margin
        self.adapter_echo = False          # learned: the adapter echoes what we send
        self._recent = deque(maxlen=8)     # packets we sent lately (their echoes are skipped)
        self._quiet_until = 0.0
        self._port_timeout = object()
        self.sent = 0
        self.replies = 0
        self.retried = 0

    # -- line -----------------------------------------------------------------------------------

    @property
    def baud(self) -> int:
        return self.port.baudrate

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

    def close(self) -> None:
        close_port(self.port)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def reply_timeout(self, tx_bytes: int, rx_bytes: int, extra: float = 0.0) -> float:
        """The derived timeout: both packets on the wire + turnaround + margin + ``extra``."""
        if self.timeout is not None:
            return self.timeout
        return wire_time(tx_bytes + rx_bytes, self.baud) + TURNAROUND + self.margin + extra

    def expects_reply(self, pkt: bytes, return_mode=None) -> bool:
        ins = zap.INSTRUCTION_BY_CODE.get(pkt[5])
        mode = self.return_mode if return_mode is None else return_mode
        return ins is not None and ins.answered(mode, pkt[3])

    def _port_error(self, e) -> PortError:
        from .port import port_failed

        return port_failed(self.url, e)

    def _write(self, pkt: bytes) -> None:
        try:
            self.port.reset_input_buffer()
            self.port.write(pkt)
        except Exception as e:  # serial.SerialException, OSError: the port failed or vanished
            if isinstance(e, (KeyboardInterrupt, PortError)):
                raise
            raise self._port_error(e) from None
        self.sent += 1
        self._recent.append(bytes(pkt))

    def _read(self, n: int, timeout: float) -> bytes:
        if timeout <= 0:
            return b""
        try:
            if self._port_timeout != timeout:
                self.port.timeout = timeout
                self._port_timeout = timeout
            return self.port.read(n)
        except Exception as e:
            if isinstance(e, KeyboardInterrupt):
                raise
            raise self._port_error(e) from None

    def _settle(self) -> None:
        wait = self._quiet_until - time.monotonic()
        if wait > 0:
            time.sleep(wait)

    # -- one transaction ----------------------------------------------------------------------

    def transact(self, pkt: bytes, *, reply=None, data_len=None, extra=0.0, timeout=None, retries=None,
                 accept_ids=None, check=True, optional=False):
        """Send ``pkt``; return its checked :class:`Reply`, or None when none is expected.

        ``reply``: whether a reply comes (default: from the instruction and ``return_mode``);
        ``data_len``: data bytes the reply must carry (None: any); ``extra``: seconds added to
        the derived timeout; ``accept_ids``: IDs a reply may carry (default: the packet's);
        ``check``: raise DeviceError for error bits; ``optional``: no reply is not an error
        (returns None at once, without a retry: the command may have been carried out).
        """
        pkt = bytes(pkt)
        ident = pkt[3]
        if reply is None:
            reply = self.expects_reply(pkt)
        stored = stored_writes(pkt)
        restart = pkt[5] in (0xF6, 0xF8)
        extra = extra + (NV_PAUSE if stored else 0.0)
        tries = 1 + (self.retries if retries is None else retries)
        if not reply:
            self._settle()
            self._write(pkt)
            gap = wire_time(len(pkt), self.baud)
            gap += RESTART_PAUSE if restart else (NV_PAUSE if stored else 0.0)
            self._quiet_until = time.monotonic() + gap
            return None
        rx_len = 7 + (data_len or 0)
        limit = timeout if timeout is not None else self.reply_timeout(len(pkt), rx_len, extra)
        accept = set(accept_ids) if accept_ids else {ident}
        problems = []
        for attempt in range(tries):
            if attempt:
                self.retried += 1
            self._settle()
            self._write(pkt)
            t0 = time.monotonic()
            got = self._await(pkt, accept, data_len, rx_len, t0 + limit, restart)
            if isinstance(got, Reply):
                got.rtt = time.monotonic() - t0
                self.replies += 1
                if restart:
                    self._quiet_until = time.monotonic() + RESTART_PAUSE
                elif stored:
                    self._quiet_until = time.monotonic() + NV_PAUSE
                if check and got.error:
                    raise device_error(got)
                return got
            problems.append(got)
            if optional and got[0] == "none":
                return None                # silence is a legitimate answer: do not repeat the command
        return self._fail(pkt, problems, limit, tries, optional)

    def _await(self, pkt, accept, data_len, rx_len, deadline, restart):
        """Read until a valid reply or the deadline. Returns a Reply or a problem tuple
        (kind, detail, received bytes)."""
        framer = ZapFramer()
        received = bytearray()
        echo_known = self.adapter_echo
        state = {"copies": 0, "want": rx_len + (len(pkt) if echo_known else 0)}
        wrong = []

        def examine(packets):
            for p in packets:
                p = bytes(p)
                if p == pkt:
                    state["copies"] += 1
                    self.adapter_echo = True
                    state["want"] = max(state["want"], len(received) + rx_len)
                    continue
                if p in self._recent:
                    continue                      # a late echo of an earlier packet
                if zap.is_command(p[5]) and p[3] not in accept:
                    continue                      # another master's command
                if p[3] not in accept:
                    wrong.append(p)
                    state["want"] = len(received) + rx_len
                    continue
                data = p[6:-1]
                if data_len is not None and len(data) != data_len:
                    return ("length", f"reply carries {len(data)} data bytes, expected {data_len}",
                            bytes(received))
                return Reply(p[3], p[5], data, p)
            return None

        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            chunk = self._read(max(1, state["want"] - len(received)), left)
            if not chunk:
                break
            received += chunk
            got = examine(framer.feed(chunk))
            if got is not None:
                return got
        pending, bad_before = framer.pending, framer.bad
        got = examine(framer.flush())               # a packet held back to rule out a rival
        if got is not None:
            return got
        copies = state["copies"]
        # The documented Restart feedback is a copy of the command itself: accept a copy that
        # is more than the adapter's known echo.
        if restart and not wrong and copies >= (2 if echo_known else 1):
            return Reply(pkt[3], 0, b"", pkt)
        if wrong:
            ids = ", ".join(str(p[3]) for p in wrong)
            return ("wrong-id", f"reply from ID {ids}, expected ID {min(accept)}", bytes(received))
        if pending and not bad_before and bytes(received).find(zap.HEADER) >= 0:
            return ("truncated", f"truncated reply ({pending} bytes of an incomplete packet)",
                    bytes(received))
        if framer.bad:
            return ("checksum", "corrupted reply (checksum mismatch)", bytes(received))
        if len(received) > copies * len(pkt):
            return ("garbage", "unreadable bytes instead of a reply (wrong baud rate?)", bytes(received))
        return ("none", "echo only" if copies else "", bytes(received))

    def _fail(self, pkt, problems, limit, tries, optional):
        ident = pkt[3]
        kinds = [p[0] for p in problems]
        if all(k == "none" for k in kinds):
            if optional:
                return None
            ms = limit * 1000
            echo = any(p[1] == "echo only" for p in problems)
            hint = " (only our own bytes came back: the adapter echoes)" if echo else ""
            ins = zap.INSTRUCTION_BY_CODE.get(pkt[5])
            mode_hint = ""
            if ins is not None and ins.reply != "always":
                mode_hint = "; or the actuator's feedback-return-mode does not answer this (try 'zap echo')"
            raise NoReply(f"no reply from ID {ident} at {self.baud} baud within {ms:.1f} ms "
                          f"({tries} {'try' if tries == 1 else 'tries'}){hint}; check the ID, the baud rate "
                          f"('zap scan --baud all'), power and wiring{mode_hint}")
        bad = [p for p in problems if p[0] != "none"][-1]
        seen = bad[2].hex(" ").upper() if bad[2] else "nothing"
        if len(seen) > 120:
            seen = seen[:117] + "..."
        e = BadReply(f"ID {ident}: {bad[1]} after {tries} {'try' if tries == 1 else 'tries'}; received {seen}")
        e.kind = bad[0]
        raise e

    # -- instructions -------------------------------------------------------------------------

    def command(self, pkt: bytes, *, check=True, optional=None):
        """Send any command packet and wait for what it gets (inferred from the packet): Load
        Data's data length, an ID change answered by the new ID, an unknown instruction's
        optional reply."""
        pkt = bytes(pkt)
        code, params = pkt[5], pkt[6:-1]
        kw = {}
        if code == 0xF2 and len(params) == 2:
            kw["data_len"] = params[1]
        if code == 0xF3 and len(params) == 2 and params[0] == zap.REGISTER_BY_NAME["id"].address:
            kw["accept_ids"] = {pkt[3], params[1]}
        if code == 0xF3 and len(params) == 2 and params[0] == zap.REGISTER_BY_NAME["feedback-return-mode"].address \
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
        if code not in zap.INSTRUCTION_BY_CODE and pkt[3] != zap.BROADCAST:
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
            raise UsageError("load: in feedback-return-mode 0 Load Data is never answered; "
                             "give --return-mode 1 or 2 if the actuator is set so")
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

    def ping(self, ident: int, *, timeout=None, retries=0):
        """Echo that returns None when nothing answers (for scans); a corrupted reply is
        retried ``retries`` times and then raised as BadReply."""
        pkt = zap.echo(ident)
        tries = 1 + retries
        limit = timeout if timeout is not None else self.reply_timeout(len(pkt), 7)
        problems = []
        for _ in range(tries):
            self._settle()
            self._write(pkt)
            t0 = time.monotonic()
            got = self._await(pkt, {ident}, None, 7, t0 + limit, False)
            if isinstance(got, Reply):
                got.rtt = time.monotonic() - t0
                self.replies += 1
                return got
            problems.append(got)
            if got[0] == "none":
                return None
        return self._fail(pkt, problems, limit, tries, True)

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
                raise NoReply(f"no reply from ID {ident} at {self.baud} baud within {within:g} s")
            time.sleep(0.005)


def open_bus(port=None, baud=57600, *, sim=False, sim_ids=None, timeout=None, return_mode=1,
             retries=RETRIES, sim_options=None) -> ZapBus:
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
            raise UsageError("no port: give -p PORT (or set ZKZAP_ZAP_PORT), --sim, or -n to print the packet")
        url = port
    p = open_port(url, baud, timeout=0.1)
    return ZapBus(p, return_mode=return_mode, timeout=timeout, retries=retries, url=url)
