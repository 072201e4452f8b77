"""The mightyZAP console's packet panel and register plot (a part of :class:`~.zap_console.ZapConsole`).

- **Plot**: one register of the table, chosen by the controlling page, polled with the live
  view (the same Load Data where it is near, one more otherwise) and sent in every sample as
  ``reg``; every page plots it.
- **Packets**: ``compose`` builds the packet of any instruction (by its name or code, to any ID,
  with a register and value or raw parameter bytes) and says what the library's permission table
  asks for it (:meth:`zkzap.codec.zap.Command.needs`) and whether a reply comes; ``packet``
  sends it through the bus, which refuses it until the page granted those permissions (the
  consent of every other request). Nothing about permissions is decided here or on the page.
- **Traffic**: every byte the console writes and reads on the bus (the bus's ``monitor``),
  framed into packets and decoded (a feedback named by the Load Data it answers), to every page
  in batches, as live data; the live view's polls only while a page asks for them.
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


def instruction_code(value) -> int:
    """An instruction by its command-line name (``load``, ``sync-move``, the vendor codes'
    names) or its code (0..255, or text like ``0xF2``/``F2``)."""
    if isinstance(value, str):
        text = value.strip().lower()
        for ins in zap.INSTRUCTIONS + zap.VENDOR_INSTRUCTIONS:
            if text == ins.cli:
                return ins.code
        try:
            code = int(text, 16) if text.startswith("0x") or any(c in "abcdef" for c in text) else int(text)
        except ValueError:
            raise UsageError(f"instruction: {value!r} is not an instruction's name or code") from None
    elif isinstance(value, int) and not isinstance(value, bool):
        code = value
    else:
        raise UsageError(f"instruction: {value!r} is not an instruction's name or code")
    if not 0 <= code <= 255:
        raise UsageError(f"instruction: {code} is out of range; allowed 0..255")
    return code


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
        text = msg.get("params") or ""
        if not isinstance(text, str) or len(text) > 2000:
            raise UsageError("params: expected hex bytes (like 8C 02)")
        try:
            params = parse_hex(text, what="params") if text.strip() else b""
        except HexError as e:
            raise UsageError(str(e)) from None
    if len(params) > 250:
        raise UsageError(f"params: {len(params)} bytes; a packet carries at most 250")
    return zap.packet(ident, code, params)


def describe_needs(cmd) -> list:
    """``[{"permission": name, "reason": text}]``: what the library's table asks of ``cmd``."""
    return [{"permission": (p.name or str(p)).lower().replace("_", "-"), "reason": why}
            for p, why in cmd.needs().items()]


class PacketTools:
    """The plot, packet and traffic requests of the zap console (mixed into ZapConsole)."""

    def tools_init(self):
        self.plotted = None              # the register every page plots (a Register), or None
        self.traffic_polls = False       # whether the live view's polls go to the traffic log
        self._polling = False            # the watcher has the bus now
        self._framer = ZapFramer()
        self._decoder = zap.ZapDecoder()
        if self.protocol == "modbus":            # a reply's bytes until they make a frame
            from ..codec import modbus

            self._rtu, self._rtu_decoder = bytearray(), modbus.ModbusDecoder(self.map)
        self.bus.link.monitor = self._monitor

    def tools_hello(self) -> dict:
        ins = [{"name": i.cli, "code": i.code, "title": i.name, "help": i.help, "params": i.params_help,
                "documented": i.documented} for i in zap.INSTRUCTIONS + zap.VENDOR_INSTRUCTIONS]
        return {"instructions": ins, "plotted": self.plotted.name if self.plotted else None,
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

    def _ir_only(self):
        if self.protocol != "ir":
            raise UsageError("the packet panel composes mightyZAP IR packets, and this bus speaks Modbus RTU; "
                             "send a Modbus frame with 'zap raw --protocol modbus'")

    def op_compose(self, ctx, msg):
        self._ir_only()
        pkt = compose(msg)
        cmd = zap.Command(pkt)
        mode = self.bus.link.mode_of(pkt[3]) if pkt[3] != zap.BROADCAST else None
        self.reply(ctx, frame=pkt.hex(" ").upper(), describe=cmd.describe(), needs=describe_needs(cmd),
                   asks=self._asks(cmd), reply=cmd.expects_reply(mode) if mode is not None else False, record=zap.decode_packet(pkt))

    def _asks(self, cmd):
        """What the page will be asked before this packet goes out on this port (the consent
        adapter's question for the library's refusal), or None."""
        from ..codec import permissions as P
        from ..errors import PermissionNeeded

        try:
            P.require(cmd.needs(), P.Permission.NONE, simulated=self.policy.simulated, what=cmd.describe(),
                      frame=cmd.packet)
        except PermissionNeeded as e:
            return self.policy.needed(e).permission
        return None

    def op_packet(self, ctx, msg):
        self._ir_only()
        pkt = compose(msg)
        cmd = zap.Command(pkt)
        reply = self.bus.link.command(pkt, check=False)         # the bus asks for what the table says
        out = {"frame": pkt.hex(" ").upper(), "describe": cmd.describe()}
        if reply is not None:
            out.update(reply=reply.packet.hex(" ").upper(), rtt_ms=round(reply.rtt * 1000, 2),
                       decoded=zap.decode_packet(reply.packet, pkt), errors=reply.errors)
        else:
            out["note"] = ("a broadcast is never answered" if cmd.broadcast else
                           f"no reply expected (feedback-return-mode {self.bus.link.mode_of(pkt[3])})")
        self.log(f"{ctx.label}: sent {cmd.describe()}" + (f"; reply in {out['rtt_ms']} ms" if reply is not None else ""),
                 "warn" if cmd.needs() else "info")
        if cmd.blocks() and any(a in (zap.REGISTER_BY_NAME[n].address for n in ("id", "baud-rate", "protocol-type",
                                                                                  "feedback-return-mode"))
                                for _, a, _ in cmd.blocks()):
            self.log("the packet changes how an actuator is reached or answers: scan again to see the bus as it "
                     "is now", "warn")
        self.reply(ctx, **out)

    def op_traffic(self, ctx, msg):
        self.traffic_polls = bool(msg.get("polls"))
        self.broadcast({"type": "traffic-polls", "polls": self.traffic_polls})
        self.reply(ctx, polls=self.traffic_polls)

    # -- traffic ------------------------------------------------------------------------------

    def _monitor(self, direction, data):
        """Every write and read on the bus (the worker's thread)."""
        if self.protocol != "ir":
            self._monitor_modbus(direction, data)
            return
        if self._polling and not self.traffic_polls:
            if direction == "rx":
                self._framer.feed(data)          # kept in step, not shown
            return
        now = round(time.time() * 1000, 1)
        packets = [data] if direction == "tx" else self._framer.feed(data)
        if direction == "rx" and not packets:
            return
        for pkt in packets:
            item = {"w": now, "dir": direction, "hex": pkt[:TRAFFIC_MAX_BYTES].hex(" ").upper(), "n": len(pkt),
                    "poll": self._polling}
            try:
                zap.check_packet(pkt)
                rec = self._decoder.decode(pkt)
                item["text"] = _words(rec, pkt)
            except (zap.PacketError, ValueError, IndexError) as e:
                item["text"] = f"not a packet: {e}"
                item["bad"] = True
            if self.hub is not None:
                self.hub.traffic(item)


    def _monitor_modbus(self, direction, data):
        """The same log for a Modbus RTU bus: a request as written, a reply once its bytes make a
        CRC-valid frame (what is left when the next request goes out is shown as not a frame)."""
        from ..codec import modbus

        frames = []
        if direction == "tx":
            if self._rtu:
                frames.append(("rx", bytes(self._rtu)))
                self._rtu.clear()
            frames.append(("tx", bytes(data)))
        else:
            self._rtu += data
            if (len(self._rtu) >= 4 and modbus.crc_ok(self._rtu)) or len(self._rtu) > 256:
                frames.append(("rx", bytes(self._rtu)))
                self._rtu.clear()
        if self._polling and not self.traffic_polls:
            return
        now = round(time.time() * 1000, 1)
        for way, frame in frames:
            item = {"w": now, "dir": way, "hex": frame[:TRAFFIC_MAX_BYTES].hex(" ").upper(), "n": len(frame),
                    "poll": self._polling}
            try:
                modbus.check_frame(frame)
                rec = self._rtu_decoder.decode(frame, "h2d" if way == "tx" else "d2h")
                item["text"] = " ".join(f"{k}={rec[k]}" for k in modbus.MODBUS_KEYS if rec.get(k) not in (None, ""))
            except (modbus.ModbusFrameError, ValueError, IndexError) as e:
                item["text"] = f"not a frame: {e}"
                item["bad"] = True
            if self.hub is not None:
                self.hub.traffic(item)


def _words(rec, pkt) -> str:
    """One line for a decoded packet."""
    if rec["kind"] == "command":
        return zap.Command(pkt).describe()
    if rec["kind"] == "unknown":
        return f"ID {rec['id']}: code 0x{rec['code']:02X} {rec['params']}"
    text = f"reply of ID {rec['id']}"
    if "values" in rec:
        text += ": " + " ".join(f"{k}={v}" for k, v in rec["values"].items())
    elif "value" in rec:
        text += f": {rec['register']}={rec['value']}" if "register" in rec else f": {rec['value']}"
    elif rec.get("params"):
        text += f": {rec['params']}"
    if rec.get("errors"):
        text += " · errors: " + ", ".join(rec["errors"])
    return text
