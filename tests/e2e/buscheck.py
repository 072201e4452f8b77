"""Checking a mightyZAP capture against the half-duplex discipline (for the end-to-end tests and
benchmarks/bus_matrix.py).

:func:`check_capture` reads what a command recorded with ``--capture`` and checks, on the
host's own clock (the capture's timestamps): no request went out while the reply of an earlier
one was still due (it had neither come nor had its window closed), every reply answers the
request before it, and retries happened only after a window closed unanswered. It returns
the request/reply pairs with their latencies, so a test can hold the ``rtt_ms`` a command
printed against them.
"""

from __future__ import annotations

from zkzap.codec import zap
from zkzap.link.capture import CaptureFrames
from zkzap.link.pcapng import INBOUND
from zkzap.link.zap_timing import LATE_WINDOW, MARGIN


#: The zap commands on a bus of actuators 1 and 2, as batch or shell lines ({tmp}: a directory
#: of the run's), and whether return mode 0 (Echo only) can run them.
LINES = {
    "echo": ("echo --id 1 --count 3 -f jsonl", True),
    "load": ("load present-position --id 2 -f jsonl", False),
    "store": ("store goal-speed 600 --id 1", True),
    "dump": ("dump --id 2 -f jsonl", False),
    "backup": ("backup --ids 1,2 -o {tmp}/fleet.json", False),
    "apply": ("apply {tmp}/fleet.json --yes", False),
    "diff": ("diff {tmp}/fleet.json bus --ids 1,2 -f jsonl", False),
    "watch": ("watch present-position moving --ids 1,2 --count 2", False),
    "move": ("move 600 --id 2 --speed 1023 --wait", False),
    "move-nowait": ("move 500 --id 1", True),
    "sync-move": ("sync-move 1:300 2:400 --verify", False),
    "sync-nowait": ("sync-move 1:300 2:400", True),
    "check": ("check --ids 1 --yes", False),
    "check-still": ("check --ids 2 --no-move", False),
}


class Pair:
    """A request that expected a reply: ``sent``, ``answered`` (capture times), ``reply`` and
    ``next`` (when the next request went out: a round trip measured by the host cannot be
    longer)."""

    __slots__ = ("request", "reply", "sent", "answered", "next")

    def __init__(self, request, sent):
        self.request, self.sent, self.reply, self.answered, self.next = request, sent, None, None, None

    @property
    def latency_ms(self):
        return None if self.answered is None else (self.answered - self.sent) * 1000.0


def frames(path):
    """(ts, inbound, packet) of a mightyZAP capture, the adapter's echoes of our own packets left out."""
    out = []
    for ts, direction, pkt in CaptureFrames(str(path), "zap"):
        inbound = direction == INBOUND
        if inbound and zap.is_command(pkt[5]):
            continue                      # a half-duplex adapter's echo of what we sent
        out.append((ts, inbound, bytes(pkt)))
    return out


def check_capture(path, mode, *, window=LATE_WINDOW, baud=57600):
    """Check the half-duplex discipline in the capture at ``path`` of commands run in return mode
    ``mode``; returns ``(pairs, retries)``: every request that expected a reply with its reply
    (or None), and how many requests repeated one whose window had closed unanswered. Raises
    AssertionError naming the first violation."""
    pairs = []
    due = None                            # the Pair whose reply may still come
    retries = 0
    missed = {}                           # ID -> requests whose window closed unanswered
    for ts, inbound, pkt in frames(path):
        if not inbound:
            if pairs and pairs[-1].next is None:
                pairs[-1].next = ts
            if due is not None:           # unanswered: the next request waits for its window
                closes = due.sent + _span(due.request, window, baud)
                assert ts >= closes, (f"request {pkt.hex(' ')} sent {1000 * (ts - due.sent):.1f} ms after "
                                      f"{due.request.hex(' ')}, whose reply was still due (its window closes "
                                      f"after {1000 * (closes - due.sent):.1f} ms)")
                missed[due.request[3]] = missed.get(due.request[3], 0) + 1
                retries += pkt == due.request
                due = None
            ins = zap.INSTRUCTION_BY_CODE.get(pkt[5])
            if ins is not None and ins.answered(mode, pkt[3]):
                due = Pair(pkt, ts)
                pairs.append(due)
            continue
        if due is not None and pkt[3] in _answerers(due.request):
            due.reply, due.answered = pkt, ts
            due = None
        elif missed.get(pkt[3]):
            missed[pkt[3]] -= 1           # the late reply of a request whose window had closed
        else:
            raise AssertionError(f"reply {pkt.hex(' ')} at {ts:.6f} answers no request in hand")
    return pairs, retries


def check_rtts(pairs, shown, ident, latency):
    """The round trips a command printed (``shown``, ms, in order) are those of its requests to
    ``ident`` in the capture: at least the capture's (the host measures from just before its
    write to the read of the last byte), shorter than the time until its next request, and at
    least the bus's ``latency``: never a late reply credited to another request."""
    echoes = [p for p in pairs if p.request[5] == 0xF1 and p.request[3] == ident]
    assert len(echoes) >= len(shown), (shown, [p.latency_ms for p in echoes])
    for rtt, p in zip(shown, echoes):
        assert p.reply is not None and rtt >= latency, (rtt, p.latency_ms)
        assert p.latency_ms - 0.05 <= rtt, (rtt, p.latency_ms)
        assert p.next is None or rtt <= (p.next - p.sent) * 1000.0, (rtt, (p.next - p.sent) * 1000.0)


def _answerers(request):
    ids = {request[3]}
    if request[5] == zap.STORE_DATA and len(request) >= 9 and request[6] == zap.REGISTER_BY_NAME["id"].address:
        ids.add(request[7])               # an ID change is answered by the new ID
    return ids


def _span(request, window, baud):
    data = request[7] if request[5] == zap.LOAD_DATA else 0
    wire = (len(request) + 7 + data) * 10 / baud
    return wire + window + MARGIN
