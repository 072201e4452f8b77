"""The one timing policy of a mightyZAP bus: when a reply may still come, and how long each
actuator takes.

A mightyZAP bus is half-duplex: the host and every actuator share one pair of wires, and a
host that transmits while an actuator is replying garbles both. Every transaction of every
command and API call (:class:`zkzap.link.zap_bus.ZapBus`), and the passive pairing of the
sniffer and of capture decoding (:class:`Pairing`), follow the rules here:

1. **The late window.** A reply may begin up to :data:`LATE_WINDOW` (150 ms, what IR Robot's own
   libraries allow; ``--timeout`` sets another) after the request's last byte has left. Until
   the windows of every request sent so far have closed, nothing is transmitted: after a
   missed reply the host keeps listening until the window closes before a retry or the next
   request, so a late reply is always the answer to the request it answers, with its true
   latency, and never meets a retry on the wire. The only exception is the first pass of a
   scan (:mod:`zkzap.link.zap_scan`), which moves on early (in quick rounds) and then asks
   again with the whole window every ID whose window it cut short while something it could
   not explain was on the line.
2. **Learned latency.** Every answered transaction gives a latency sample: the round trip
   minus both packets' time on the wire (the actuator's turnaround, the USB adapter's
   buffering, the host's scheduling). Each actuator has an :class:`Estimator` (a smoothed
   latency and its variation, as TCP's retransmission timer, RFC 6298); its timeout
   (:meth:`Estimator.timeout`) is bounded by :data:`FLOOR` and the late window. A reply after
   its actuator's timeout is counted late. A scan's first pass waits a measured actuator's
   own timeout, and for an ID never measured only :data:`FLOOR` (plus the adapter's timer, or
   the ``--latency`` hint): most IDs are free, and a slower reply is heard anyway. The
   estimators of a port are shared by every
   transaction in one process (:func:`policy_for`: ``zap batch``, ``zkzap shell``, every
   :class:`zkzap.Bus` on that port). ``--latency MS`` (``ZKZAP_ZAP_LATENCY``) gives the latency
   of a known slow setup before any sample, and widens the window when it needs more.
3. **The line's own time.** Deadlines add the packets' wire time at the line's baud rate and
   stop bits, :data:`MARGIN` for the host, the USB adapter's latency timer where the system
   tells it, and :data:`NETWORK_MARGIN` for a port on another host. While reply bytes trickle
   in the wait extends to :data:`INTER_BYTE` after the latest byte.

Nothing here imports pyserial.
"""

from __future__ import annotations

import os
from urllib.parse import urlsplit

#: How long after a request's last byte a reply may still begin (seconds).
LATE_WINDOW = 0.150
#: The shortest latency any wait assumes: a 12Lf's own turnaround (about 2 ms).
FLOOR = 0.002
#: Host allowance on every deadline: scheduling, the pty or USB transfer.
MARGIN = 0.0025
#: Extra allowance for a socket:// or rfc2217:// port on another host.
NETWORK_MARGIN = 0.02
#: Allowance between two reply bytes (on top of one byte time and the margin).
INTER_BYTE = 0.010
#: What a scan's first pass adds to its wait for the reply's first byte.
QUICK_MARGIN = 0.0005
#: Allowance for the memory pause after a write to stored (NV) registers.
NV_PAUSE = 0.008
#: Quiet time after Restart / Factory Reset before the next command in the same run.
RESTART_PAUSE = 0.1
#: How long after its request a reply is still recognised as possibly that request's, and so
#: never taken for another's answer (seconds; three times an attempt's whole wait when longer):
#: the slowest reply the bus is built to attribute. A reply later still is a device the bus
#: cannot vouch for at that window: give a longer ``--timeout``.
HORIZON = 1.5
#: How long past an unanswered attempt's window the bus listens on before a retry, as a share of
#: the attempt's whole wait (a reply a little late is then the request's own, its latency known,
#: and no retry meets it on the line); a scan that heard something late listens as long past
#: its last window.
RETRY_GRACE = 0.5
#: Default number of retries after a failed attempt.
RETRIES = 2
#: The smoothing of the estimators (RFC 6298: alpha 1/8, beta 1/4, K 4).
ALPHA, BETA, K = 0.125, 0.25, 4
#: How much a scan's first pass stretches the latency it allows an unknown ID (and a write's
#: courtesy wait the bus-typical latency).
QUICK_FACTOR = 1.25
#: An FTDI adapter's latency timer is shown in the measured latency when the bus-typical latency
#: reaches this share of it.
TIMER_SHARE = 0.75

_LOOPBACK = ("localhost", "127.0.0.1", "::1", "")


class Estimator:
    """The latency of one actuator: ``srtt`` (smoothed, seconds), ``rttvar`` (its variation)
    and ``samples`` (answered transactions measured)."""

    __slots__ = ("srtt", "rttvar", "samples", "late")

    def __init__(self):
        self.srtt = None
        self.rttvar = None
        self.samples = 0
        self.late = 0

    def sample(self, latency: float) -> None:
        latency = max(0.0, latency)
        if self.samples == 0:
            self.srtt, self.rttvar = latency, latency / 2
        else:
            self.rttvar = (1 - BETA) * self.rttvar + BETA * abs(self.srtt - latency)
            self.srtt = (1 - ALPHA) * self.srtt + ALPHA * latency
        self.samples += 1

    def timeout(self, floor: float, cap: float) -> float:
        """When a reply of this actuator is late: its latency plus 4x its variation (at least
        :data:`MARGIN` more), within ``floor`` .. ``cap``."""
        if self.srtt is None:
            return cap
        return max(floor, min(cap, self.srtt + max(MARGIN, K * self.rttvar)))

    def __repr__(self):
        if self.srtt is None:
            return "Estimator()"
        return f"Estimator(srtt={self.srtt * 1000:.2f} ms, rttvar={self.rttvar * 1000:.2f} ms, n={self.samples})"


def ms(seconds) -> str:
    return f"{seconds * 1000:.1f} ms"


class Policy:
    """The learned latencies of one bus (one port), shared by every transaction on it.

    ``adapter`` is the USB adapter's latency timer (seconds) when the system tells it,
    ``network`` whether the port is on another host; ``margin`` (default: derived from both)
    is added to every deadline."""

    def __init__(self, *, adapter=None, network=False, margin=None, device=None):
        self.adapter = adapter
        self.network = network
        self.device = device
        self.margin = (MARGIN + (adapter or 0.0) + (NETWORK_MARGIN if network else 0.0)) if margin is None \
            else margin
        self.estimators = {}               # ID -> Estimator, at the line speed the port is at
        self.baud = None                   # that line speed (None: not told yet)
        self._at = {}                      # baud -> the estimators of the other line speeds
        self.hinted = False                # the adapter hint was given (once per process)

    def switch(self, baud) -> None:
        """The port is at ``baud`` now: the latencies learned at that rate are the ones in use
        (an ID 7 at 115200 and another at 57600 are two actuators, each with its own)."""
        if baud == self.baud:
            return
        if self.baud is not None:
            self._at[self.baud] = self.estimators
        self.estimators = self._at.pop(baud, {})
        self.baud = baud

    def moved(self, old: int, new: int) -> None:
        """An ID change (verified): what was learned of ``old`` is that actuator's at ``new`` now,
        and nothing is known any more of ``old`` (another actuator given that ID later is not
        judged by it)."""
        est = self.estimators.pop(old, None)
        self.estimators.pop(new, None)
        if est is not None:
            self.estimators[new] = est

    def moved_to(self, ident: int, baud: int) -> None:
        """A baud change (verified) of ``ident`` from the line speed in use: what was learned of it
        goes along to ``baud`` (replacing what was learned there of that ID), and nothing is known
        any more of ``ident`` at this speed."""
        if baud == self.baud:
            return
        est = self.estimators.pop(ident, None)
        there = self._at.setdefault(baud, {})
        there.pop(ident, None)
        if est is not None:
            there[ident] = est

    def estimator(self, ident: int) -> Estimator:
        est = self.estimators.get(ident)
        if est is None:
            est = self.estimators[ident] = Estimator()
        return est

    def learn(self, ident: int, latency: float, window: float) -> bool:
        """Take one latency sample of ``ident``; True when it came after the actuator's timeout
        (a late reply: still the answer, counted)."""
        est = self.estimator(ident)
        late = est.samples > 0 and latency > est.timeout(FLOOR, window)
        est.sample(latency)
        if late:
            est.late += 1
        return late

    def latency(self, ident=None, hint=None):
        """The expected latency of ``ident`` (its smoothed one), else the bus-typical one, else
        ``hint``; None before anything is known."""
        if ident is not None:
            est = self.estimators.get(ident)
            if est is not None and est.srtt is not None:
                return est.srtt
        typical = self.typical()
        return typical if typical is not None else hint

    def typical(self):
        """The bus-typical latency: the median of the actuators' smoothed latencies, the lower
        of the two middle ones for an even count (None before any was measured): one slow
        actuator is not the bus, even among two. It keeps the line quiet after a write to an
        unmeasured ID (:meth:`courtesy`) and spaces a scan's last quick round."""
        values = sorted(e.srtt for e in self.estimators.values() if e.srtt is not None)
        if not values:
            return None
        return values[(len(values) - 1) // 2]

    def measured(self, ident, window: float):
        """The timeout of ``ident``'s estimator within :data:`FLOOR` .. ``window``, or None
        before its first sample."""
        est = self.estimators.get(ident)
        if est is not None and est.samples:
            return est.timeout(FLOOR, window)
        return None

    def timeout(self, ident: int, window: float, hint=None) -> float:
        """When a reply of ``ident`` counts as late (its estimator's timeout, the hint before
        any sample), within :data:`FLOOR` .. ``window``."""
        measured = self.measured(ident, window)
        if measured is not None:
            return measured
        if hint is not None:
            return max(FLOOR, min(window, hint * QUICK_FACTOR + MARGIN))
        return window

    def window_of(self, ident, window: float) -> float:
        """The late window for ``ident``: ``window``, or, for an actuator learned to answer later
        than that (its replies came after the window and were still known to be its answers),
        its latency stretched by :data:`QUICK_FACTOR` plus 4x its variation, at most a third
        of the horizon: a slow actuator is waited for as long as it takes, not asked again
        while its reply is on its way."""
        est = self.estimators.get(ident)
        if est is None or est.srtt is None or est.srtt + K * est.rttvar + MARGIN <= window:
            return window
        return min(max(window, HORIZON / 3), est.srtt * QUICK_FACTOR + K * est.rttvar + MARGIN)

    def inter_byte(self, ident, window=LATE_WINDOW) -> float:
        """How long a reply's bytes may pause before the rest counts as missing (a truncated
        reply): :data:`INTER_BYTE`, or 4x the variation of ``ident``'s latency when larger (an
        adapter or host that delivers in irregular bursts), at most the window."""
        est = self.estimators.get(ident)
        if est is None or not est.samples:
            return INTER_BYTE
        return min(window, max(INTER_BYTE, K * est.rttvar))

    def quick(self, hint=None, window=LATE_WINDOW) -> float:
        """The latency a scan's first pass allows an ID never measured: :data:`FLOOR` plus the
        adapter's timer (or the ``--latency`` hint when larger) stretched by
        :data:`QUICK_FACTOR`, within the window. Not the latency of the actuators already
        measured: most IDs probed are free, and a slower actuator's reply that comes after the
        wait is still heard (a scan judges it; see :mod:`zkzap.link.zap_scan`)."""
        floor = FLOOR + (self.adapter or 0.0)
        base = max(floor, hint) if hint is not None else floor
        return min(window, base * QUICK_FACTOR)

    def courtesy(self, hint=None, window=LATE_WINDOW) -> float:
        """How long the line stays quiet after a write that an unmeasured actuator in another
        return mode might acknowledge: the bus-typical latency (or the hint, or :data:`FLOOR`
        plus the adapter's timer) stretched by :data:`QUICK_FACTOR`, within the window."""
        floor = FLOOR + (self.adapter or 0.0)
        typical = self.typical()
        base = typical if typical is not None else (hint if hint is not None else floor)
        return min(window, max(floor, base * QUICK_FACTOR))

    def adapter_effect(self):
        """Facts when the measured latency shows an FTDI adapter's latency timer: ``(typical
        latency, timer, device)`` (seconds), else None."""
        if not self.adapter or self.adapter <= 0.001:
            return None
        typical = self.typical()
        if typical is None or typical < TIMER_SHARE * self.adapter:
            return None
        return typical, self.adapter, self.device

    def summary(self) -> dict:
        """{ID: {"latency_ms", "variation_ms", "samples", "late"}} of the actuators measured."""
        return {i: {"latency_ms": round(e.srtt * 1000, 3), "variation_ms": round(e.rttvar * 1000, 3),
                    "samples": e.samples, "late": e.late}
                for i, e in sorted(self.estimators.items()) if e.srtt is not None}


def horizon_for(span: float) -> float:
    """How long after an attempt its reply is still recognised as that attempt's (see
    :data:`HORIZON`), for an attempt that waits ``span`` seconds."""
    return max(HORIZON, 3 * span)


def window_for(timeout=None, hint=None) -> float:
    """The late window: ``timeout`` (``--timeout``) when given, else :data:`LATE_WINDOW`, widened
    to what a latency ``hint`` needs (1.25x it plus the margin)."""
    window = LATE_WINDOW if timeout is None else float(timeout)
    if hint is not None and timeout is None:
        window = max(window, hint * QUICK_FACTOR + MARGIN)
    return window


# -- the port --------------------------------------------------------------------------------

def usb_latency(device):
    """The latency timer (seconds) of a USB serial adapter (FTDI: 16 ms by default), or None."""
    from . import adapters

    try:
        name = os.path.basename(os.path.realpath(str(device)))
    except (OSError, ValueError):
        return None
    value = adapters.read_latency_timer(name, adapters.SYSFS_USB_SERIAL)
    return None if value is None else value / 1000.0


def port_facts(url) -> dict:
    """``adapter`` (a USB adapter's latency timer, seconds, or None), ``network`` (a port on
    another host) and ``device`` of a port URL or device path."""
    url = str(url or "")
    if "://" in url:
        parts = urlsplit(url)
        network = parts.scheme in ("socket", "rfc2217") and (parts.hostname or "") not in _LOOPBACK
        return {"adapter": None, "network": network, "device": None}
    if not url:
        return {"adapter": None, "network": False, "device": None}
    return {"adapter": usb_latency(url), "network": False, "device": url}


def host_margin(url) -> float:
    """The host margin for ``url``: :data:`MARGIN`, plus a USB adapter's latency timer, plus
    :data:`NETWORK_MARGIN` for a remote network port."""
    return Policy(**port_facts(url)).margin


#: The policies of the ports opened in this process, by URL (simulators excepted: each opening
#: of sim://zap?ids=... is a new bus; a simulator started from Python, sim://zap?instance=N, is
#: one).
_POLICIES: dict = {}


def policy_for(url, margin=None) -> Policy:
    """The policy of the port ``url``: the same object for every opening in this process (the
    latencies learned by one command serve the next), a new one for a simulator."""
    key = str(url or "")
    simulated = not key or key.startswith("loop://") or (key.startswith("sim://") and "instance=" not in key)
    if not simulated and margin is None and key in _POLICIES:
        return _POLICIES[key]
    policy = Policy(margin=margin, **port_facts(key))
    if not simulated and margin is None:
        _POLICIES[key] = policy
    return policy


# -- passive pairing -------------------------------------------------------------------------

class Pairing:
    """Pairs mightyZAP feedback with the request it answers, for observers that never send (the
    sniffer, capture decoding), under the same rule as the host: a reply answers the latest
    request to its ID that is still open, whatever was sent since; a request closes unanswered
    when its late window (``window`` after the request, plus ``margin``) has passed with the
    line idle (a reply that began in time may trickle in after it). :meth:`command` opens a
    request (its ``info`` is returned with the feedback), :meth:`feedback` closes it,
    :meth:`expired` gives the requests whose window closed unanswered. A request sent while
    another's reply was still due is counted in :attr:`overlaps` (on a half-duplex line it may
    have collided with that reply)."""

    def __init__(self, window=LATE_WINDOW, margin=MARGIN):
        self.window = window
        self.margin = margin
        self.pending = {}                  # ID -> (ts, info)
        self.overlaps = 0

    def due(self, now) -> bool:
        """Whether a reply to a pending request may still come at ``now``."""
        return any(now - ts <= self.window + self.margin for ts, _ in self.pending.values())

    def command(self, ident, ts, info=None) -> list:
        """A request to ``ident`` at ``ts``; returns ``[(ident, ts, info)]`` of the requests it
        supersedes (a new request to the same ID: the earlier one went unanswered)."""
        out = []
        if self.due(ts):
            self.overlaps += 1
        old = self.pending.pop(ident, None)
        if old is not None:
            out.append((ident, old[0], old[1]))
        self.pending[ident] = (ts, info)
        return out

    def feedback(self, ident, ts):
        """``(request ts, info, latency seconds)`` of the request a feedback from ``ident`` at
        ``ts`` answers, or None (no request to that ID is open). The latency is None when the
        request and the feedback carry one time stamp (they came in one read, a reader held up):
        the time between them is not known, and never taken for 0."""
        p = self.pending.pop(ident, None)
        if p is None:
            return None
        return p[0], p[1], (ts - p[0]) if ts > p[0] else None

    def expired(self, now, busy=False) -> list:
        """``[(ident, ts, info)]`` of the requests whose window closed by ``now``, unanswered
        (none while ``busy``: bytes of a packet are arriving)."""
        if busy:
            return []
        out = [(i, ts, info) for i, (ts, info) in self.pending.items() if now - ts > self.window + self.margin]
        for i, _, _ in out:
            del self.pending[i]
        return sorted(out, key=lambda r: r[1])

    def others(self, ident):
        """The IDs of the other requests still open (a reply from ``ident`` was not asked for,
        but these were)."""
        return sorted(i for i in self.pending if i != ident)
