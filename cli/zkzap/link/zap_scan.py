"""Find the actuators on a mightyZAP bus: every ID at every baud rate, fast and complete.

:func:`scan` is the procedure behind ``zap scan`` (click-free: it yields what it finds and the
command renders it). It keeps the bus's timing policy (:mod:`zkzap.link.zap_timing`) with the
one exception the policy allows:

1. **First pass.** Echo to each ID, waiting only for the first byte of a reply from an ID
   never measured at the latency floor (:meth:`ZapBus.quick_timeout`: about 4.4 ms at 57600),
   an actuator measured before for its own timeout, then moving on: the first pass does not
   wait for the late window of an ID that stays silent, but the bus keeps listening through
   every window it cut short, and the scan judges what it hears. A reply that comes after its
   probe's wait is recognised by its ID: that actuator is found. Bytes that make no packet (a
   late reply that met a later probe on the line, replies of two actuators at once) are kept
   with the time they arrived. The actuators found are identified at once (step 3); after the
   last ID the scan listens until the last window has closed.
2. **Quick rounds**, then **asking again**. The IDs in doubt are those whose window the first
   pass cut short while something unexplained was on the line:

   - every ID whose probe may have met bytes on the line (its echo came back broken, or it
     went out while they were arriving: a late reply can come through clean and still have
     broken the probe, since the probe's header of FF bytes leaves it as it was): its actuator
     may not have heard it;
   - for garbled bytes, every ID whose window they fell in: one of them may have sent them
     (a late reply that met a probe, or replies of two actuators that met each other).

   They are probed again in a quick round (when there are at least :data:`REPLAY_MIN`), in
   first-pass order, with no probe where the garbled bytes would come again: if one of these
   IDs sent them, its reply comes as long after its new probe as they came after its first, on
   a free line, and is recognised by its ID. Each ID is judged by its new window like a
   first-pass probe. A second round spaces its probes (each waits until a reply at the
   bus-typical latency would have ended), so that two late replies that met each other meet
   no more. What is
   still in doubt after :data:`REPLAYS` rounds is asked again with the whole late window and
   the retries of an ordinary transaction (nothing else is sent until its window has closed),
   judged the same way, until nothing is in doubt (every ID is asked so at most once). Records
   come out in ID order: one is held while a lower ID may still turn out to be there. A quiet
   line is never asked again: an ID whose whole window passed with nothing unexplained on the
   line has no actuator.
3. **Identify.** Each actuator found is asked for model number .. feedback-return-mode in one
   Load Data (retries). No reply at all, with the whole window, and an Echo answered: return
   mode 0 (Echo only). A read that fails otherwise leaves ``model``, ``firmware`` and
   ``return_mode`` null with status ``unidentified`` -- never a guess. What the first pass
   identified while other windows were open is identified again, on a quiet line, when it
   failed or something garbled came meanwhile.
4. **Duplicates.** Two actuators with one ID answer together and garble each other's
   replies, except where their bytes happen to be equal (an Echo, the same settings). The
   scan reads the live registers (present-position .. present-voltage), which differ between
   two units; replies that stay garbled give status ``duplicate`` (or ``garbled`` when even
   the Echo is) and a warning.

An ID whose replies only ever come after the window (a ``--timeout`` shorter than its
latency) is reported with status ``unidentified`` and the reason, not left out.

Records: ``id``, ``baud``, ``model``, ``firmware``, ``return_mode``, ``status`` (``ok``,
``error``, ``garbled``, ``duplicate``, ``unidentified``) and ``errors``.
"""

from __future__ import annotations


from ..codec import zap
from ..errors import BadReply, NoReply
from .zap_timing import QUICK_FACTOR, RETRY_GRACE, horizon_for

#: The order ``--baud all`` tries: the factory default first, then the others fastest first.
ALL_BAUDS = (57600, 115200, 38400, 19200, 9600)
#: How far before garbled bytes arrived (beyond the adapter's timer) a probe may have met them.
GARBLED_SLACK = 0.01
#: Quick rounds over the IDs in doubt before they are asked again one by one with the whole window
#: (each costs about one probe per ID and one window; asking costs one window per ID).
REPLAYS = 2
#: The fewest IDs in doubt for which a quick round is cheaper than asking them one by one.
REPLAY_MIN = 3
STATUSES = ("ok", "error", "garbled", "duplicate", "unidentified")


def duplicate_warning(ident: int, baud: int) -> str:
    return (f"ID {ident} at {baud} baud: replies collide: two actuators probably answer to this ID; "
            "connect them one at a time and give one a free ID ('zap set-id')")


def garbled_warning(ident: int, baud: int) -> str:
    return (f"ID {ident} at {baud} baud: every reply was garbled: two actuators may answer to this ID, "
            "or the line is noisy")


def scan(bus, ids, bauds, *, retries: int = 2):
    """Probe ``ids`` at each of ``bauds`` on ``bus`` (a :class:`~zkzap.link.zap_bus.ZapBus`).

    Yields ``("probe", baud, ident, found_so_far, phase)`` before each probe (for progress;
    ``phase`` is ``"first"``, ``"round"`` for the quick rounds of step 2, ``"ask"`` for asking
    again with the whole window),
    ``("record", rec)`` for every actuator found (as found), ``("warning", text)`` and
    ``("note", text)`` (what is worth knowing, where nothing went wrong).
    """
    found = [0]
    for baud in bauds:
        bus.set_baud(baud)
        bus.take_events()
        yield from _Scan(bus, baud, list(ids), retries, found).run()


class _Probe:
    __slots__ = ("ident", "t0", "tx_end", "span")

    def __init__(self, ident, t0, tx_end, span):
        self.ident, self.t0, self.tx_end, self.span = ident, t0, tx_end, span


class _Scan:
    """One baud rate of a scan."""

    def __init__(self, bus, baud, ids, retries, found):
        self.bus, self.baud, self.ids, self.retries, self.found = bus, baud, ids, retries, found
        self.records = {}              # ID -> record (found)
        self.identified = set()        # IDs whose identification is final
        self.provisional = set()       # identified while windows were open: to be done again
        self.late_seen = set()         # IDs heard only after a window
        self.probes = {}               # ID -> its first-pass _Probe (the windows the events fall in)
        self.doubt = set()             # IDs to ask again with the whole window
        self.asked = set()             # IDs asked again with the whole window
        self.held = []                 # (ID, [events]) found, not yet released
        self.echo_errors = {}          # ID -> the error bits of the Echo that found it
        self.bursts = []               # (lo, hi) of the garbled bytes heard since the last round
        self.all_bursts = []           # (lo, hi) of every burst of garbled bytes heard
        self.prompt = set()            # IDs that answered their first-pass probe in its wait
        self.tried = {}                # ID -> every _Probe of it (first pass and rounds)
        self.twice = set()             # IDs found whose replies came where none was due
        self.bursts_heard = 0          # bursts of garbled bytes heard (for the warning)
        self.start = bus.now()         # a late reply to an attempt before it finds nobody
        self.late_rtt = {}             # ID -> the round trip of its latest late reply (for the note)

    # -- steps ------------------------------------------------------------------------------

    def run(self):
        bus = self.bus
        for ident in self.ids:
            yield ("probe", self.baud, ident, self.found[0], "first")
            r = self._probe(ident)
            if r is not None:
                self._found(ident, r)
                self.prompt.add(ident)
            self._judge()
            yield from self._release()
        self._identify_found()
        for round_ in range(REPLAYS):
            todo = sorted(self.doubt - set(self.records) - self.asked)
            if len(todo) < REPLAY_MIN:
                break
            yield from self._replay(todo, spaced=round_ > 0)
            self._identify_found()
        far = self._far_doubt()
        if far:
            # garbled bytes no actuator found explains: one later than the window may have sent
            # them (a reply is recognised up to its horizon): a spaced round over every ID
            # probed within that reach, with the line free where they would come again
            self.bursts = list(self.all_bursts)
            yield from self._replay(far, spaced=True, reach=self._reach())
            self._identify_found()
        if self.bursts_heard or self.late_seen:
            # something late was on the line: a reply a little later than the last probes'
            # windows is still heard (half a window more, as before any retry), not taken for
            # an absent ID's silence
            bus.linger(bus.window * RETRY_GRACE)
            self._judge()
        while True:                    # every ID is asked again at most once: this ends
            todo = sorted(self.doubt - set(self.records) - self.asked)
            redo = sorted(i for i in self.records if i not in self.identified or i in self.provisional)
            if not todo and not redo:
                break
            for ident in todo:
                yield ("probe", self.baud, ident, self.found[0], "ask")
                self._ask(ident)
                self._judge()
            for ident in sorted(i for i in self.records if i not in self.identified or i in self.provisional):
                self.provisional.discard(ident)
                self._identify(ident, early=False)
            bus.quiet()
            self._judge()
            yield from self._release()
        for ident in sorted(self.late_seen - set(self.records)):
            # it answers, but never within the window (a --timeout shorter than its latency)
            rec = _record(ident, self.baud)
            rec["status"] = "unidentified"
            rec["errors"] = [_late_text(bus, ident)]
            self._final(ident, [("record", rec)])
        yield from self._release(final=True)
        yield from self._collision_warnings()

    def _collision_warnings(self):
        """What the scan talked over, said once per baud rate: an actuator found by a reply that
        came after its probe's quick wait (the probes sent meanwhile met or may have met it; the
        same on every scan of that bus), else bursts of garbled bytes heard. Where every such
        actuator was identified all the same, that is a note with the latency learned of them
        (a bus of slow actuators or a USB adapter's timer: nothing went wrong), said once per
        bus and rate; else a warning."""
        late = sorted(self.late_seen & set(self.records))
        if late:
            ids = ", ".join(str(i) for i in late)
            them = "it" if len(late) == 1 else "them"
            found = f"{'ID' if len(late) == 1 else 'IDs'} {ids} at {self.baud} baud"
            if all(self.records[i]["status"] in ("ok", "error") and self.records[i]["model"] is not None
                   for i in late):
                key = (self.baud, tuple(late))
                if key not in self.bus.noted:
                    self.bus.noted.add(key)
                    yield ("note", f"{found} answered after the scan's quick wait "
                                   f"({_latencies(self.bus, late, self.late_rtt)}): "
                                   f"found and identified; the IDs near {them} were probed again")
            else:
                yield ("warning", f"{found} answered after the scan's quick wait: its probes talk over such "
                                  f"replies, so the IDs near {them} were probed again")
        elif self.bursts_heard:
            yield ("warning", f"{self.bursts_heard} burst{'s' if self.bursts_heard > 1 else ''} of garbled bytes at "
                              f"{self.baud} baud during the scan (replies that met a probe or each other, or a line "
                              "fault): the IDs they may have come from were probed again")

    def _probe(self, ident):
        """A first-pass Echo: the reply, or None (garbled bytes are an event like the others)."""
        bus = self.bus
        try:
            return bus.ping(ident, quick=True, early=True)
        except BadReply:
            return None
        finally:
            t0 = bus.last_sent
            tx = bus.wire(bus.family.PROBE_LEN)
            self.probes[ident] = probe = _Probe(ident, t0, t0 + tx, tx + bus.window + bus.wire(bus.family.PROBE_LEN) + bus.margin)
            self.tried.setdefault(ident, []).append(probe)

    def _identify_found(self):
        """Identify the actuators found and not identified yet while the last windows close (one
        identified while windows were open is done again later, on a quiet line); then listen
        until no reply may still come and judge what came."""
        for ident in sorted(self.records):
            if ident not in self.identified and ident not in self.provisional:
                self._identify(ident, early=True)
        self.bus.quiet()
        self._judge()

    def _reach(self) -> float:
        """How many first-pass windows back a reply may still come: to its horizon."""
        bus = self.bus
        span = bus.wire(bus.family.PROBE_LEN) + bus.window + bus.wire(bus.family.PROBE_LEN) + bus.margin
        return horizon_for(span) / span

    def _far_doubt(self) -> list:
        """The IDs not found that may have sent a burst of garbled bytes no actuator found
        explains (no actuator found late, one that did not answer its probe at once, was probed
        a window before): every ID probed up to its reach before."""
        found = [p for i in self.records if i not in self.prompt for p in self.tried.get(i, ())]
        reach = self._reach()
        out = set()
        for lo, hi in self.all_bursts:
            if any(p.t0 <= hi and p.t0 + p.span >= lo for p in found):
                continue
            out |= {p.ident for p in self.probes.values()
                    if p.ident not in self.records and p.t0 <= hi and p.t0 + p.span * reach >= lo}
        self.all_bursts = []
        return sorted(out - self.asked)

    def _replay(self, todo, spaced, reach=1.0):
        """A quick round over ``todo`` (the IDs in doubt), in first-pass order, keeping the line
        free where the bytes that raised the doubt would come again: if one of these IDs sent
        them, its reply comes as long after its new probe as they came after its first one, and
        meets no probe this time. Each ID is then judged by its new window like any first-pass
        probe. ``spaced`` (a later round): after each probe the line stays quiet until a reply at
        the bus-typical latency would have ended, so that late replies that met each other (or
        the probes between them) meet no more."""
        bus = self.bus
        guard = self._slack() + bus.wire(bus.family.PROBE_LEN)
        offsets = {}                    # ID -> [(from, to)] after its probe, where its reply would come
        for lo, hi in self.bursts:
            for ident in todo:
                p = self.probes.get(ident)
                if p is not None and p.t0 <= hi and p.t0 + p.span * reach >= lo:
                    offsets.setdefault(ident, []).append((lo - p.t0 - guard, hi - p.t0 + bus.margin))
        self.bursts = []
        free = []                       # (from, to): where a reply may come on the line: no probe then
        tx = bus.wire(bus.family.PROBE_LEN)
        for ident in sorted(todo, key=lambda i: self.probes[i].t0 if i in self.probes else 0.0):
            if ident in self.records:
                continue                # found meanwhile (its late reply came through)
            yield ("probe", self.baud, ident, self.found[0], "round")
            self.doubt.discard(ident)
            while True:
                now = bus.now()
                block = [b for a, b in free if a < now + tx + bus.margin and b > now]
                if not block:
                    break
                bus.linger(max(block) - now)
            r = self._probe(ident)
            if r is not None:
                self._found(ident, r)
            t0 = self.probes[ident].t0
            free.extend((t0 + a, t0 + b) for a, b in offsets.get(ident, ()))
            if spaced:
                # long enough for a reply at the bus-typical latency to end before the next probe
                # (one later than that, where the garbled bytes came, has its free slot above)
                typical = bus.policy.typical() or 0.0
                end = t0 + tx + max(typical * QUICK_FACTOR, bus.policy.quick(bus.latency, bus.window)) \
                    + bus.wire(bus.family.PROBE_LEN) * 2 + bus.margin
                left = end - bus.now()
                if left > 0:
                    bus.linger(left)
            self._judge()
            yield from self._release()

    def _ask(self, ident, again=False):
        """Ask again, with the whole window and the retries: a record, found, or absent."""
        self.asked.add(ident)
        self.doubt.discard(ident)
        try:
            r = self.bus.ping(ident, retries=self.retries)
        except BadReply as e:
            if e.kind == "wrong-id":
                return                 # only another ID's reply came (named: an event): none here
            if not again and self.bus.owes():
                # a late reply of another ID may have met the probes: ask once more when no
                # reply owed to any can come, so that garbled bytes are this ID's own
                self.bus.settle()
                self._judge()
                return self._ask(ident, again=True)
            rec = _record(ident, self.baud)
            rec["status"] = "garbled"
            rec["errors"] = [str(e)]
            self.records[ident] = rec
            self._final(ident, [("record", rec), ("warning", garbled_warning(ident, self.baud))])
            return
        if r is not None:
            self._found(ident, r)

    def _found(self, ident, reply):
        if ident in self.records:
            return
        rec = _record(ident, self.baud)
        rec["errors"] = list(reply.errors)
        self.echo_errors[ident] = list(reply.errors)
        if reply.error:
            rec["status"] = "error"
        self.records[ident] = rec
        self.doubt.discard(ident)

    def _final(self, ident, events):
        """A record is final: held for release in ID order (one whose ID sent replies where
        none was due is a duplicate: two actuators answering one request, whose replies did not
        meet, or a line fault)."""
        if ident in self.twice:
            for ev in events:
                rec = ev[1] if ev[0] == "record" else None
                if rec is not None and rec["status"] in ("ok", "error"):
                    rec["status"] = "duplicate"
                    rec["errors"] = rec["errors"] + [f"ID {ident}: two replies came where one was due"]
                    events = events + [("warning", duplicate_warning(ident, self.baud))]
                    break
        self.identified.add(ident)
        self.found[0] += 1
        self.held.append((ident, events))

    def _identify(self, ident, *, early):
        bus = self.bus
        rec = self.records[ident]
        garbled_before = bus.garbled
        events = list(_finish(bus, rec, self.retries, early=early))
        self._judge()
        if rec["status"] == "unidentified" and ident in self.late_seen:
            rec["errors"] = [_late_text(bus, ident)]
        if early and (rec["status"] in ("unidentified", "duplicate") or bus.garbled != garbled_before):
            # identified while other windows were open: say nothing yet, ask again on a quiet line
            fresh = _record(ident, self.baud)
            fresh["errors"] = list(self.echo_errors.get(ident, []))
            if fresh["errors"]:
                fresh["status"] = "error"
            self.records[ident] = fresh
            self.provisional.add(ident)
            return
        self.provisional.discard(ident)
        self._final(ident, events)

    # -- judging what was heard --------------------------------------------------------------

    def _slack(self):
        return GARBLED_SLACK + (self.bus.policy.adapter or 0.0) + self.bus.margin

    def _collided(self, lo, hi, skip=None):
        """Put up the probes that may have met bytes on the line between ``lo`` and ``hi`` (their
        echo came back broken, or they went out meanwhile): their actuators may not have heard
        them."""
        bus = self.bus
        for p in self.probes.values():
            if p.ident in self.records or p.ident == skip:
                continue
            clean = bus.echo_clean(p.t0)
            if clean is False or (clean is None and p.tx_end >= lo and p.t0 <= hi):
                self.doubt.add(p.ident)

    def _judge(self):
        """Account for the bus's events: late replies are actuators found; a probe that may have
        met them on the line is asked again; garbled bytes are kept to be explained."""
        bus = self.bus
        slack = self._slack()
        for ev in bus.take_events():
            if ev.kind in ("late", "stray") and ev.packet is not None:
                ident = ev.ident
                if ev.kind == "stray" and ident in self.records:
                    self.twice.add(ident)     # two replies where one was due
                # (the late answer of a request made before the scan, a Store that changed the
                # ID, says nothing of who answers to that ID now)
                ours = ev.kind == "late" and (ev.t0 is None or ev.t0 >= self.start)
                if ours and ev.t0 is not None:
                    self.late_rtt[ident] = ev.hi - ev.t0
                if ident not in self.records and (ours or (ev.kind == "stray" and ident in self.probes)):
                    if ev.packet[4] == 2:             # an Echo reply (no data): the actuator is there
                        self._found(ident, bus.family.reply(ev.packet, 0.0, None))
                    self.late_seen.add(ident)
                # a late reply can come through clean and still have broken a probe sent while
                # it was on the line (the probe's header of FF bytes leaves it as it was, while
                # its bytes garble the probe)
                self._collided(ev.lo - slack - bus.wire(len(ev.packet)), ev.hi, skip=ident)
                continue
            if ev.kind != "garbled":
                continue
            lo, hi = ev.lo - slack - bus.wire(bus.family.PROBE_LEN), ev.hi
            self.bursts.append((ev.lo, ev.hi))
            self.all_bursts.append((ev.lo, ev.hi))
            self.bursts_heard += 1
            self._collided(lo, hi)
            # whoever sent them may be any ID whose window they fell in
            self.doubt |= {p.ident for p in self.probes.values()
                           if p.ident not in self.records and p.t0 <= hi and p.t0 + p.span >= ev.lo}

    def _release(self, final=False):
        # in ID order: a record waits while a lower ID may still turn out to be there
        self.held.sort(key=lambda h: h[0])
        now = self.bus.now()
        while self.held:
            ident, events = self.held[0]
            if not final and any(self._open(i, now) for i in self.ids if i < ident):
                break
            self.held.pop(0)
            yield from events

    def _open(self, i, now) -> bool:
        """Whether ID ``i`` may still turn out to be there (or its record is not out yet)."""
        if i in self.records:
            return i not in self.identified or i in self.provisional
        if i in self.doubt:
            return True
        p = self.probes.get(i)
        return p is None or p.t0 + p.span > now


def _latencies(bus, ids, late_rtt) -> str:
    """The latency learned of ``ids``, as a note says it (``latency 20.4 ms``, or a range); for
    IDs whose every reply came late (never learned), the round trip of their last late reply."""
    got, rtt = [], []
    for i in ids:
        est = bus.policy.estimators.get(i)
        if est is not None and est.srtt is not None:
            got.append(est.srtt * 1000.0)
        elif i in late_rtt:
            rtt.append(late_rtt[i] * 1000.0)
    parts = []
    for what, xs in (("latency", sorted(got)), ("round trip", sorted(rtt))):
        if xs:
            parts.append(f"{what} {xs[0]:.1f} ms" if xs[-1] - xs[0] < 0.05 else f"{what} {xs[0]:.1f}-{xs[-1]:.1f} ms")
    return "; ".join(parts) or "latency not measured"


def _late_text(bus, ident) -> str:
    return (f"ID {ident} answers only after the window ({bus.window * 1000:.1f} ms): its replies came late; "
            "give a longer --timeout")


def _record(ident, baud):
    return {"id": ident, "baud": baud, "model": None, "firmware": None, "return_mode": None,
            "status": "ok", "errors": []}


def _finish(bus, rec, retries, early=False):
    """Identify a found actuator and check for a duplicate; yields the record and warnings."""
    ident, baud = rec["id"], rec["baud"]
    if rec["status"] == "garbled":
        yield ("record", rec)
        yield ("warning", garbled_warning(ident, baud))
        return
    identify(bus, rec, retries, early=early)
    if rec["status"] in ("ok", "error") and rec["return_mode"] != 0:
        if collides(bus, ident, retries, early=early):
            rec["status"] = "duplicate"
            rec["errors"] = rec["errors"] + [f"ID {ident}: the live registers come back garbled"]
    yield ("record", rec)
    if rec["status"] == "duplicate":
        yield ("warning", duplicate_warning(ident, baud))


def collides(bus, ident: int, retries: int = 2, early=False) -> bool:
    """Whether two actuators seem to answer to ``ident``: its live registers (which differ
    between two units) come back garbled on every try."""
    pkt, length = bus.family.live_request(ident)
    try:
        bus.transact(pkt, reply=True, data_len=length, retries=retries, check=False, early=early)
    except BadReply:
        return True
    except NoReply:
        pass
    return False


def identify(bus, rec, retries=2, early=False) -> None:
    """Fill ``model``, ``firmware`` and ``return_mode`` of ``rec`` from one Load Data, or leave
    them null with status ``unidentified`` (or ``duplicate`` when the reply is garbled) and the
    reason in ``errors``."""
    ident = rec["id"]
    pkt, length = bus.family.info_request(ident)
    mark = len(bus.events)
    try:
        r = bus.transact(pkt, reply=True, data_len=length, retries=retries, check=False, early=early)
    except BadReply as e:
        rec["status"] = "duplicate"
        rec["errors"] = rec["errors"] + [str(e)]
        return
    except NoReply as e:
        # an actuator answers in the order it is asked: once its Echo (asked after the Load) is
        # answered, a reply to the Load has come already, late, or never will (return mode 0)
        if _echo_answers(bus, ident, retries, early) and not _answered_late(bus, mark, ident, length):
            rec["return_mode"] = 0                 # answers Echo, never Load Data: Echo only
            bus.devices.learn_mode(ident, 0)       # that actuator's from now on
            return
        rec["status"] = "unidentified"
        late = any(ev.kind == "late" and ev.ident == ident for ev in bus.events)
        rec["errors"] = rec["errors"] + [_late_text(bus, ident) if late else f"identify: {e}"]
        return
    rec.update(bus.family.info_values(r))
    if rec["return_mode"] in (0, 1, 2):
        bus.devices.learn_mode(ident, rec["return_mode"])   # that actuator's from now on


def _answered_late(bus, mark, ident, length) -> bool:
    """Whether a reply of ``ident`` carrying ``length`` data bytes (a Load's) came after its
    window among the bus's events since ``mark``: the actuator answers Load Data, later than
    the window."""
    family = bus.family
    return any(ev.kind in ("late", "stray") and ev.ident == ident and ev.packet is not None
               and family.fits(ev.packet, length) for ev in bus.events[mark:])


def _echo_answers(bus, ident, retries, early=False) -> bool:
    """Whether ``ident`` answers an Echo now: its own reply (one that may answer an earlier
    request says nothing of this one: it does not make the actuator one in return mode 0)."""
    for _ in range(3):                      # each doubt settles one earlier unanswered Echo
        try:
            r = bus.ping(ident, retries=retries, early=early)
        except BadReply:
            return False
        if r is None or r.doubt is None:
            return r is not None
        bus.settle(ident)                   # until no reply to an earlier attempt can come
    return False
