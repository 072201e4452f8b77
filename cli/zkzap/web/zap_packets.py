"""The mightyZAP console's packet panel and register plot (a part of :class:`~.zap_console.ZapConsole`).

- **Plot**: one register of the table, chosen by the controlling page, polled with the live
  view (the same Load Data where it is near, one more otherwise) and sent in every sample as
  ``reg``; every page plots it.
- **Packets**: ``compose`` builds the packet of any instruction (by its name or code, to any ID,
  with a register and value or raw parameter bytes) and says what the library's permission table
  asks for it (:meth:`zkzap.codec.zap.Command.needs`) and whether a reply comes; ``packet``
  sends it through the bus, which refuses it until the page granted those permissions (the
  consent of every other request). Nothing about permissions is decided here or on the page.
  On a Modbus RTU bus the same for any request frame (Read Holding Registers, Write Single
  Register, Write Multiple Registers by a register of the bus's map or an address, or any
  function with raw data bytes; the CRC appended by :mod:`zkzap.codec.modbus`), its permissions
  those of :meth:`zkzap.codec.modbus.Request.needs` against the bus's map.
- **Traffic**: every byte the console writes and reads on the bus (the bus's ``monitor``),
  cut into frames by the bus's own framer (its protocol family's) and decoded (a reply named by
  the request it answers; a Modbus exception reply by its code and meaning); bytes that make no
  frame (a bad checksum or CRC, a frame cut short) are shown as such, never as values. To every
  page in batches, as live data; the live view's polls only while a page asks for them.
"""

from __future__ import annotations

import time

from ..codec import zap
from ..codec.fields import FieldValueError
from ..codec.framing import ZapFramer
from ..codec.hexfmt import HexError, parse_hex
from ..errors import UsageError
from .console import number

TRAFFIC_MAX_BYTES = 64
"""The longest packet shown whole in the traffic log (a longer one is cut, its length said)."""


def instruction_code(value, protocol: str = "ir") -> int:
    """An instruction by its command-line name (``load``, ``sync-move``, the vendor codes'
    names) or its code (0..255, or text like ``0xF2``/``F2``); on Modbus RTU (``protocol``
    "modbus") a function by its name (``read``, ``write``, ``write-multiple``) or code 0x01..0x7F."""
    modbus_ = protocol == "modbus"
    names = ({name: code for code, (name, _) in _modbus().FUNCTIONS.items()} if modbus_ else
             {ins.cli: ins.code for ins in zap.INSTRUCTIONS + zap.VENDOR_INSTRUCTIONS})
    what = "function" if modbus_ else "instruction"
    if isinstance(value, str):
        text = value.strip().lower()
        if text in names:
            return names[text]
        try:
            code = int(text, 16) if text.startswith("0x") or any(c in "abcdef" for c in text) else int(text)
        except ValueError:
            raise UsageError(f"{what}: {value!r} is not {'a function' if modbus_ else 'an instruction'}'s name or "
                             f"code; allowed {', '.join(names)} or a code") from None
    elif isinstance(value, int) and not isinstance(value, bool):
        code = value
    else:
        raise UsageError(f"{what}: {value!r} is not {'a function' if modbus_ else 'an instruction'}'s name or code")
    lo, hi = (1, 0x7F) if modbus_ else (0, 255)
    if not lo <= code <= hi:
        raise UsageError(f"{what}: {code} is out of range; allowed {lo}..{hi}"
                         + (" (0x80 and up mark exception replies)" if modbus_ else ""))
    return code


def _modbus():
    from ..codec import modbus

    return modbus


def compose(msg) -> bytes:
    """The packet a page's compose request describes: ``instruction``, ``id`` (0..254), and
    ``register`` with ``value`` (Store/Send Data) or ``length`` (Load Data, default the
    register's size), or ``params`` (hex bytes, any notation)."""
    code = instruction_code(msg.get("instruction"))
    ident = number(msg, "id", int, 0, zap.BROADCAST, "id")
    name = msg.get("register")
    if name not in (None, ""):
        try:
            reg = zap.register(str(name))
        except FieldValueError as e:
            raise UsageError(str(e)) from None
        if code == zap.LOAD_DATA:
            length = reg.size if msg.get("length") in (None, "") else number(msg, "length", int, 1, 255, "length")
            params = bytes((reg.address, length))
        elif code in zap.WRITE_CODES:
            value = number(msg, "value", int, 0, 256 ** reg.size - 1, reg.name)
            params = bytes((reg.address,)) + value.to_bytes(reg.size, "little")
        else:
            raise UsageError("register: only for load, store and send; give params for this instruction")
    else:
        params = _raw_params(msg, "8C 02")
    if len(params) > 250:
        raise UsageError(f"params: {len(params)} bytes; a packet carries at most 250")
    return zap.packet(ident, code, params)


def _raw_params(msg, example) -> bytes:
    """A request's ``params``: hex bytes in any notation (empty: none)."""
    text = msg.get("params") or ""
    if not isinstance(text, str) or len(text) > 2000:
        raise UsageError(f"params: expected hex bytes (like {example})")
    try:
        return parse_hex(text, what="params") if text.strip() else b""
    except HexError as e:
        raise UsageError(str(e)) from None


def compose_modbus(msg, regmap) -> bytes:
    """The Modbus RTU request frame a page's compose request describes (the CRC appended by the
    codec): ``instruction`` (a function: read, write, write-multiple or a code), ``id`` (0..247,
    0 the broadcast), and ``register`` (a name of ``regmap`` or an address) with ``count``
    (read, default 1), ``value`` (write) or ``values`` (write-multiple: numbers, or text like
    ``1000 800``); or ``params``, the data bytes between function and CRC (hex, any notation)."""
    modbus = _modbus()
    code = instruction_code(msg.get("instruction"), "modbus")
    ident = number(msg, "id", int, 0, modbus.MAX_ID, "id")
    name = msg.get("register")
    try:
        if name in (None, ""):
            data = _raw_params(msg, "00 D2 00 01")
            if len(data) + 4 > modbus.MAX_FRAME:
                raise UsageError(f"params: {len(data)} bytes; a Modbus RTU frame carries at most "
                                 f"{modbus.MAX_FRAME - 4} between function and CRC")
            return modbus.frame(ident, bytes((code,)) + data)
        address = _modbus_address(name, regmap)
        label = regmap.by_address[address].name if address in regmap.by_address else f"register {address}"
        if code == modbus.READ_HOLDING:
            if ident == modbus.BROADCAST:
                raise UsageError("id: a read to the broadcast (0) is never answered; give an actuator's ID, or "
                                 "raw params")
            count = 1 if msg.get("count") in (None, "") else number(msg, "count", int, 1, modbus.MAX_READ, "count")
            return modbus.read_registers(ident, address, count)
        if code == modbus.WRITE_SINGLE:
            return modbus.write_register(ident, address, number(msg, "value", int, 0, 0xFFFF, label))
        if code == modbus.WRITE_MULTIPLE:
            return modbus.write_registers(ident, address, _values_given(msg, label))
    except FieldValueError as e:
        raise UsageError(str(e)) from None
    raise UsageError("register: only for read, write and write-multiple; give params for this function")


def _modbus_address(name, regmap) -> int:
    """A register of ``regmap`` by name, or any address 0..65535 (one the map lacks too: what
    writing it needs is the permission table's to say)."""
    text = str(name).strip()
    try:
        return regmap.register(text).address
    except FieldValueError:
        try:
            address = int(text, 0)
        except ValueError:
            raise UsageError(f"register: {text!r} is not a register of the {regmap.model} map or an address") \
                from None
        if not 0 <= address <= 0xFFFF:
            raise UsageError(f"register: address {address} is outside 0..65535") from None
        return address


def _values_given(msg, label) -> list:
    """``values`` of a write-multiple: a list of numbers or text (``1000 800``, ``1000,800``)."""
    raw = msg.get("values")
    if isinstance(raw, str):
        raw = [v for v in raw.replace(",", " ").split() if v]
    elif isinstance(raw, (int, float)) and not isinstance(raw, bool):
        raw = [raw]
    if not isinstance(raw, list) or not raw:
        raise UsageError("values: give the registers' values (like 1000 800)")
    if len(raw) > _modbus().MAX_WRITE:
        raise UsageError(f"values: {len(raw)} registers; one write carries 1..{_modbus().MAX_WRITE}")
    return [number({"v": v}, "v", int, 0, 0xFFFF, f"{label} + {i}" if i else label) for i, v in enumerate(raw)]


def describe_needs(needs) -> list:
    """``[{"permission": name, "reason": text}]``: what the library's table asks (``needs``, a
    typed frame's ``{Permission: reason}``)."""
    return [{"permission": (p.name or str(p)).lower().replace("_", "-"), "reason": why}
            for p, why in needs.items()]


class PacketTools:
    """The plot, packet and traffic requests of the zap console (mixed into ZapConsole)."""

    def tools_init(self):
        self.plotted = None              # the register every page plots (a Register), or None
        self.traffic_polls = False       # whether the live view's polls go to the traffic log
        self._polling = False            # the watcher has the bus now
        self._rx = FrameCutter(self.bus.link.family.framer())     # the bytes read, cut as the bus cuts them
        self._last_tx = b""              # the last request written (a reply's bytes are judged against it)
        self._junk = b""                 # Modbus: bytes read since the last frame that made none (one run)
        self._junk_why = None
        if self.protocol == "modbus":
            self._decoder = _modbus().ModbusDecoder(self.map)
        else:
            self._decoder = zap.ZapDecoder()
        self.bus.link.monitor = self._monitor

    def tools_hello(self) -> dict:
        if self.protocol == "modbus":
            modbus = _modbus()
            takes = {modbus.READ_HOLDING: "count", modbus.WRITE_SINGLE: "value", modbus.WRITE_MULTIPLE: "values"}
            ins = [{"name": name, "code": code, "title": title, "help": f"{title} (0x{code:02X})",
                    "params": "", "documented": True, "takes": takes[code]}
                   for code, (name, title) in modbus.FUNCTIONS.items()]
            ids = {"lo": 0, "hi": modbus.MAX_ID, "broadcast": modbus.BROADCAST}
        else:
            takes = {zap.LOAD_DATA: "length", **{c: "value" for c in zap.WRITE_CODES}}
            ins = [{"name": i.cli, "code": i.code, "title": i.name, "help": i.help, "params": i.params_help,
                    "documented": i.documented, "takes": takes.get(i.code)}
                   for i in zap.INSTRUCTIONS + zap.VENDOR_INSTRUCTIONS]
            ids = {"lo": 0, "hi": zap.BROADCAST, "broadcast": zap.BROADCAST}
        return {"instructions": ins, "packet_ids": ids, "plotted": self.plotted.name if self.plotted else None,
                "traffic_polls": self.traffic_polls}

    # -- the plot -----------------------------------------------------------------------------

    def op_plot(self, ctx, msg):
        name = msg.get("register")
        if name in (None, ""):
            self.plotted = None
        else:
            self.plotted = self.reg(str(name))          # of the bus's map (IR table or Modbus map)
        self.broadcast({"type": "plot", "register": self.plotted.name if self.plotted else None})
        self.log(f"{ctx.label} plots {self.plotted.name}" if self.plotted else f"{ctx.label} ends the register plot")
        self.reply(ctx, register=self.plotted.name if self.plotted else None)

    # -- packets ------------------------------------------------------------------------------

    def _composed(self, msg):
        """``(frame, needs, describe, expects_reply, record)`` of the page's packet: what the
        protocol's typed frame answers (:class:`zkzap.codec.zap.Command`,
        :class:`zkzap.codec.modbus.Request` against the bus's map)."""
        if self.protocol == "modbus":
            modbus = _modbus()
            frame = compose_modbus(msg, self.map)
            req = modbus.Request(frame)
            return (frame, req.needs(self.map), req.describe(self.map), req.expects_reply(),
                    modbus.decode_frame(frame, regmap=self.map, direction="h2d"))
        pkt = compose(msg)
        cmd = zap.Command(pkt)
        mode = self.bus.link.mode_of(pkt[3]) if pkt[3] != zap.BROADCAST else None
        return (pkt, cmd.needs(), cmd.describe(), cmd.expects_reply(mode) if mode is not None else False,
                zap.decode_packet(pkt))

    def op_compose(self, ctx, msg):
        frame, needs, what, reply, record = self._composed(msg)
        self.reply(ctx, frame=frame.hex(" ").upper(), describe=what, needs=describe_needs(needs),
                   asks=self._asks(needs, what, frame), reply=reply, record=record)

    def _asks(self, needs, what, frame):
        """What the page will be asked before this packet goes out on this port (the consent
        adapter's question for the library's refusal), or None."""
        from ..codec import permissions as P
        from ..errors import PermissionNeeded

        try:
            P.require(needs, P.Permission.NONE, simulated=self.policy.simulated, what=what, frame=frame)
        except PermissionNeeded as e:
            return self.policy.needed(e).permission
        return None

    def op_packet(self, ctx, msg):
        frame, needs, what, _, _ = self._composed(msg)
        out = {"frame": frame.hex(" ").upper(), "describe": what}
        if self.protocol == "modbus":
            modbus = _modbus()
            req = modbus.Request(frame)
            # the bus asks for what the table says; a frame whose reply cannot be foretold may go unanswered
            reply = self.bus.link.command(frame, check=False, optional=True if req.reply_length() is None else None)
            if reply is not None:
                out.update(decoded=modbus.decode_frame(reply.packet, frame, self.map))
                if reply.exception:
                    out["exception"] = (f"exception {reply.error} ({modbus.exception_name(reply.error)}): "
                                        f"{modbus.exception_meaning(reply.error)}")
            else:
                out["note"] = ("a broadcast is never answered" if req.broadcast else
                               "no reply (a frame the actuator does not know may go unanswered)")
            moved = {self.map.owner[a].name for addr, values in req.blocks()
                     for a in range(addr, addr + len(values)) if a in self.map.owner}
        else:
            cmd = zap.Command(frame)
            reply = self.bus.link.command(frame, check=False)         # the bus asks for what the table says
            if reply is not None:
                out.update(decoded=zap.decode_packet(reply.packet, frame))
            else:
                out["note"] = ("a broadcast is never answered" if cmd.broadcast else
                               f"no reply expected (feedback-return-mode {self.bus.link.mode_of(frame[3])})")
            moved = {zap.REGISTER_BY_ADDRESS[a].name for _, a, _ in cmd.blocks() if a in zap.REGISTER_BY_ADDRESS}
        if reply is not None:
            out.update(reply=reply.packet.hex(" ").upper(), rtt_ms=round(reply.rtt * 1000, 2), errors=reply.errors)
        self.log(f"{ctx.label}: sent {what}" + (f"; reply in {out['rtt_ms']} ms" if reply is not None else "")
                 + (f"; {out['exception']}" if "exception" in out else ""), "warn" if needs else "info")
        if moved & REACHED_BY:
            self.log("the packet changes how an actuator is reached or answers: scan again to see the bus as it "
                     "is now", "warn")
        self.reply(ctx, **out)

    def op_traffic(self, ctx, msg):
        self.traffic_polls = bool(msg.get("polls"))
        self.broadcast({"type": "traffic-polls", "polls": self.traffic_polls})
        self.reply(ctx, polls=self.traffic_polls)

    # -- traffic ------------------------------------------------------------------------------

    def _monitor(self, direction, data):
        """Every write and read on the bus (the worker's thread): a request as written, the
        bytes read as the bus's framer cuts them (what it holds when the next request goes out,
        or once a Modbus reply's length is in, is judged then: no frame is lost or made up).

        On Modbus RTU the bytes between two frames that make none are one run, as the bus judges
        one attempt's bytes: a reply whose CRC fails is one line however many reads brought it
        (a USB adapter's or a socket's chunks; how long the host waited between two reads says
        nothing of the silence on the line), said once the reply's length is in."""
        show = self.hub is not None and (self.traffic_polls or not self._polling)
        if direction == "tx":
            said = self._pieces(self._rx.flush(), show, final=True)   # judged by the request they followed
            self._last_tx = bytes(data)
            said.append(self._said("tx", self._last_tx, None, show))
        else:
            said = self._pieces(self._rx.feed(data), show)
            if self.protocol == "modbus" and self._reply_in():
                said += self._pieces(self._rx.flush(), show, final=True)  # a reply's length in, no frame
        if not show:
            return
        now = round(time.time() * 1000, 1)
        for way, frame, text, bad in said:
            item = {"w": now, "dir": way, "hex": frame[:TRAFFIC_MAX_BYTES].hex(" ").upper(), "n": len(frame),
                    "poll": self._polling, "text": text}
            if bad:
                item["bad"] = True
            self.hub.traffic(item)

    def _pieces(self, pieces, show, final=False) -> list:
        """What the cutter's ``pieces`` say (see :meth:`_said`). On Modbus RTU the runs that make
        no frame are gathered into one, said before the next frame, or now when ``final``."""
        if self.protocol != "modbus":
            return [self._said("rx", p, why, show) for p, why in pieces]
        out = []
        for p, why in pieces:
            if why is None:
                out += self._junk_said(show)
                out.append(self._said("rx", p, None, show))
            else:
                self._junk += p
                if self._junk_why is None or why == "a failed check":
                    self._junk_why = why
        if final:
            out += self._junk_said(show)
        return out

    def _junk_said(self, show) -> list:
        junk, why = self._junk, self._junk_why
        self._junk, self._junk_why = b"", None
        return [self._said("rx", junk, why, show)] if junk else []

    def _said(self, way, frame, why, show=True):
        """``(way, frame, text, bad)``: a whole frame decoded (the decoder is kept in step with
        every frame, shown or not: a reply is named by its request), or bytes in no frame
        (``why``: the framer's reason)."""
        noun = "frame" if self.protocol == "modbus" else "packet"
        if why is not None:
            return (way, frame, f"not a {noun}: {self._bad(frame, why)}", True) if show else None
        try:
            return way, frame, self._decode(way, frame, show), False
        except (zap.PacketError, ValueError, IndexError) as e:
            return way, frame, f"not a {noun}: {e}", True

    def _reply_in(self) -> bool:
        """Whether the bytes read since the last request and in no frame yet (those the framer
        holds, after any that made none) are as many as a whole Modbus reply to it has: judged
        now, not at the next request. Bytes that begin as the request did are its echo coming (a
        half-duplex adapter's), still awaited; held bytes that begin as its reply does (its ID
        and function) after a run that made no frame are that reply coming, judged by their own
        length."""
        held, junk, sent = bytes(self._rx.raw), self._junk, self._last_tx
        if len(sent) < 4 or not (held or junk):
            return False
        if not junk and sent.startswith(held[:len(sent)]):
            return False
        if junk and held and held[0] == sent[0] and (len(held) < 2 or held[1] & 0x7F == sent[1]):
            junk = b""
        want = self._reply_len(junk + held)
        return want is not None and len(junk) + len(held) >= want

    def _reply_len(self, data):
        """The length of a whole Modbus reply to the last request that begins as ``data`` does
        (an exception reply 5), or None when it cannot be foretold."""
        modbus = _modbus()
        if len(data) >= 2 and data[1] & modbus.EXCEPTION_BIT:
            return 5
        return modbus.Request(self._last_tx).reply_length() if len(self._last_tx) >= 4 else None

    def _decode(self, way, frame, words=True) -> str:
        """One line for a whole frame, from the protocol's decoder (``words`` False: only the
        decoder kept in step)."""
        if self.protocol != "modbus":
            if way == "tx":
                zap.check_packet(frame)
            rec = self._decoder.decode(frame)
            return _words(rec, frame) if words else ""
        modbus = _modbus()
        if way == "rx" and frame == self._last_tx and frame[1] != modbus.WRITE_SINGLE:
            return "the request's echo (the adapter's)"
        rec = self._decoder.decode(frame, "h2d" if way == "tx" else "d2h")
        if not words:
            return ""
        if rec["kind"] == "request":
            return modbus.Request(frame).describe(self.map)
        if rec["kind"] == "exception":
            return (f"exception reply of ID {rec['id']} to {rec['function']}: {rec['exception']} {rec['name']} "
                    f"({rec['meaning']})")
        return _reply_words(rec)

    def _bad(self, data, why) -> str:
        """Why ``data`` is no frame: the protocol's own check where the bytes are as many as the
        frame they begin (a bad CRC or checksum, with the expected and found bytes), else their
        count and the framer's reason."""
        try:
            if self.protocol == "modbus":
                if len(data) == self._reply_len(data):
                    _modbus().check_frame(data)
            else:
                zap.check_packet(data)
        except (zap.PacketError, ValueError) as e:
            if "CRC" in str(e) or "checksum" in str(e):
                return str(e)
        return f"{len(data)} byte{'s' if len(data) != 1 else ''}, {why}"


#: Registers whose write changes how an actuator is reached or answers (scan again after it).
REACHED_BY = {"id", "baud-rate", "protocol-type", "feedback-return-mode"}


class FrameCutter:
    """The bytes read on a bus cut by ``framer`` (the bus's family's: the same cut the bus makes)
    into whole frames and the runs of bytes that make none, each said with why (a failed check,
    a frame cut short, bytes in no frame); :meth:`flush` judges what the framer holds."""

    def __init__(self, framer):
        self.framer = framer
        self.raw = bytearray()           # bytes read and not yet given out as a frame or a run

    @property
    def held(self) -> int:
        return len(self.raw)

    def feed(self, data) -> list:
        """``[(bytes, None)]`` for a frame, ``[(bytes, why)]`` for bytes in none, as ``data`` completes them."""
        return self._cut(lambda: self.framer.feed(data), data, final=False)

    def flush(self) -> list:
        return self._cut(self.framer.flush, b"", final=True) if self.raw else []

    def _cut(self, run, data, final) -> list:
        f = self.framer
        bad, truncated = f.bad, f.truncated
        self.raw += data
        frames = run()
        why = "a failed check" if f.bad != bad else "cut short" if f.truncated != truncated else "in no frame"
        out = []
        for frame in frames:
            i = self.raw.find(frame)
            if i < 0:                      # cannot be: a framer's frames are the bytes it was fed
                i = 0
            if i:
                out.append((bytes(self.raw[:i]), why))
            out.append((bytes(frame), None))
            del self.raw[:i + len(frame)]
        rest = len(self.raw) - (0 if final else f.pending)
        if rest > 0:
            out.append((bytes(self.raw[:rest]), why))
            del self.raw[:rest]
        return out


def _reply_words(rec) -> str:
    """The words for a decoded reply (either protocol's record)."""
    text = f"reply of ID {rec['id']}"
    if isinstance(rec.get("values"), dict):
        text += ": " + " ".join(f"{k}={v}" for k, v in rec["values"].items())
    elif rec.get("values") is not None:
        text += ": " + " ".join(map(str, rec["values"]))
    elif "value" in rec:
        text += f": {rec['register']}={rec['value']}" if "register" in rec else f": {rec['value']}"
    elif rec.get("count") is not None and rec.get("register"):
        text += f": wrote {rec['register']} ({rec['count']} register{'s' if rec['count'] != 1 else ''})"
    elif rec.get("params"):
        text += f": {rec['params']}"
    if rec.get("errors"):
        text += " · errors: " + ", ".join(rec["errors"])
    return text


def _words(rec, pkt) -> str:
    """One line for a decoded IR packet."""
    if rec["kind"] == "command":
        return zap.Command(pkt).describe()
    if rec["kind"] == "unknown":
        return f"ID {rec['id']}: code 0x{rec['code']:02X} {rec['params']}"
    return _reply_words(rec)
