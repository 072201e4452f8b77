"""Simulators that play recordings (``zkzap sim zk|zap --replay CAPTURE``).

- :class:`ZkReplay`: the ECU -> host status frames of a ZK capture, sent at their recorded
  times (model time: ``--speed`` scales it), once or looping; control frames the host sends
  meanwhile are decoded and handed to ``log`` as records.
- :class:`ZapReplay`: every request that was recorded is answered with the reply recorded for
  the same request (same ID, instruction and parameters: the same bytes), after the recorded
  latency; several recorded replies to one request are played in order, then the last again; a
  request recorded without a reply stays unanswered (a silent actuator is reproduced). Other
  requests go to the actuator-bus model (:class:`zkzap.sim.zap_actuators.ActuatorBus`).
"""

from __future__ import annotations

from ..codec import zap, zk
from ..errors import InvalidValue
from ..codec.framing import ZapFramer, ZkFramer
from ..link.capture import CaptureFrames
from ..link.pcapng import INBOUND, OUTBOUND
from .base import Device


class ZkReplay(Device):
    def __init__(self, path, loop=False, log=None):
        self.path = path
        self.loop = loop
        self.log = log
        self.framer = ZkFramer("control")
        self.decoder = zk.ZkDecoder()
        self._start(0.0)
        self.first = self._peek()
        if self.first is None:
            raise InvalidValue(f"{path}: no status frame to replay")
        self.received = 0
        self.sent = 0

    def _start(self, offset):
        self.frames = CaptureFrames(self.path, "zk", "status")
        self._it = iter(self.frames)
        self._next = None
        self._t0 = None
        self._offset = offset
        self._last = offset
        self._count = 0

    def _peek(self):
        """(model time, frame) of the next recorded status frame, or None at the end."""
        if self._next is None:
            item = next(self._it, None)
            if item is None:
                return None
            ts, _direction, frame = item
            if self._t0 is None:
                self._t0 = ts
            self._next = (self._offset + ts - self._t0, frame)
        return self._next

    def receive(self, data, now, baud=None):
        for frame in self.framer.feed(data):
            self.received += 1
            if self.log is not None:
                rec = {"t": round(now, 6), "dir": "h2d"}
                rec.update(self.decoder.decode(frame))
                rec["frame"] = frame.hex(" ").upper()
                self.log(rec)

    def poll(self, now):
        out = bytearray()
        while True:
            head = self._peek()
            if head is None:
                if not self.loop or not self._count:
                    break
                # the next round starts one mean frame period after the last frame
                period = (self._last - self._offset) / (self._count - 1) if self._count > 1 else 0.05
                self._start(self._last + period)
                head = self._peek()
                if head is None:
                    break
            if head[0] > now:
                break
            out += head[1]
            self._last = head[0]
            self._next = None
            self.sent += 1
            self._count += 1
        return bytes(out)

    def next_wakeup(self, now):
        head = self._peek()
        if head is None:
            return now + 0.05 if self.loop else None
        return head[0]

    def close(self):
        self.frames.reader.close()


def recorded_replies(path):
    """{request bytes: [(reply bytes or None, latency seconds)]} from a mightyZAP capture, in
    recorded order, and the IDs that answered."""
    table = {}
    ids = set()
    pending = None
    for ts, direction, pkt in CaptureFrames(path, "zap"):
        if zap.is_command(pkt[5]):
            if direction == INBOUND:
                continue                      # an adapter's echo of the host's own bytes
            if pending is not None:
                table.setdefault(pending[0], []).append((None, None))
            pending = (bytes(pkt), ts) if pkt[3] != zap.BROADCAST else None
        elif pending is not None and pkt[3] == pending[0][3]:
            table.setdefault(pending[0], []).append((bytes(pkt), max(0.0, ts - pending[1])))
            ids.add(pkt[3])
            pending = None
    if pending is not None:
        table.setdefault(pending[0], []).append((None, None))
    return table, ids


class ZapReplay(Device):
    def __init__(self, path, model, recorded=None):
        self.table, self.ids = recorded if recorded is not None else recorded_replies(path)
        self.model = model
        self.framer = ZapFramer()
        self._used = {}
        self._queue = []
        self.replayed = 0
        self.modelled = 0

    def receive(self, data, now, baud=None):
        for pkt in self.framer.feed(data):
            pkt = bytes(pkt)
            replies = self.table.get(pkt)
            if replies is None:
                self.modelled += 1
                self.model.receive(pkt, now, baud)
                continue
            n = self._used.get(pkt, 0)
            reply, latency = replies[min(n, len(replies) - 1)]
            self._used[pkt] = n + 1
            self.replayed += 1
            if reply is not None:
                self._queue.append((now + latency, reply))
                self._queue.sort(key=lambda x: x[0])

    def poll(self, now):
        out = bytearray(self.model.poll(now))
        while self._queue and self._queue[0][0] <= now:
            out += self._queue.pop(0)[1]
        return bytes(out)

    def next_wakeup(self, now):
        times = [t for t in (self.model.next_wakeup(now), self._queue[0][0] if self._queue else None)
                 if t is not None]
        return min(times) if times else None

    def close(self):
        self.model.close()


__all__ = ["ZkReplay", "ZapReplay", "recorded_replies", "OUTBOUND"]
