"""Find the actuators on a mightyZAP bus: every ID at every baud rate, fast and complete.

:func:`scan` is the procedure behind ``zap scan`` (click-free: it yields what it finds and the
command renders it):

1. **Quick pass.** Echo to each ID with the quick probe's wait (:meth:`ZapBus.ping` with
   ``quick=True``: our packet and one reply byte on the wire plus the bus's typical
   turnaround), so a bus of 2 ms actuators is scanned at about wire speed.
2. **Late and garbled replies.** A reply that comes after its probe's wait is recognised by
   its ID while later IDs are probed (the bus counts it as late). Its ID is probed again with
   the full allowance, and so are the IDs probed while that reply was on its way (on a real
   half-duplex line their probes may have collided with it). Bytes that make no packet
   (a collision) put every ID probed within one full allowance (plus :data:`GARBLED_WINDOW`)
   before them up for another probe. After the last ID the scan waits one full allowance for stragglers.
   Where replies came late, the second probes (and what follows them) wait that much longer
   (:meth:`ZapBus.patience`): a bus slower than the allowance is heard, not collided with.
   Records come out in ID order: one is held while a lower ID may still turn out to be there.
3. **Identify.** Each actuator found is asked for model number .. feedback-return-mode in one
   Load Data (full allowance, retries). No reply at all, with the full derived wait, and an
   Echo answered: return mode 0 (Echo only). A read that fails otherwise leaves ``model``,
   ``firmware`` and ``return_mode`` null with status ``unidentified`` -- never a guess.
4. **Duplicates.** Two actuators with one ID answer together and garble each other's
   replies, except where their bytes happen to be equal (an Echo, the same settings). The
   scan reads the live registers (present-position .. present-voltage), which differ between
   two units; replies that stay garbled give status ``duplicate`` (or ``garbled`` when even
   the Echo is) and a warning.

An ID whose replies only ever come late (a ``--timeout`` shorter than its turnaround) is
reported with status ``unidentified`` and the reason, not left out.

Records: ``id``, ``baud``, ``model``, ``firmware``, ``return_mode``, ``status`` (``ok``,
``error``, ``garbled``, ``duplicate``, ``unidentified``) and ``errors``.
"""

from __future__ import annotations

import time

from ..codec import zap
from ..errors import BadReply, NoReply

#: The order ``--baud all`` tries: the factory default first, then the others fastest first.
ALL_BAUDS = (57600, 115200, 38400, 19200, 9600)
#: The block read to identify an actuator: model-number .. feedback-return-mode.
INFO_FIRST = zap.REGISTER_BY_NAME["model-number"]
INFO_LAST = zap.REGISTER_BY_NAME["feedback-return-mode"]
#: Live registers read to reveal two actuators sharing an ID: present-position .. present-voltage.
LIVE_FIRST = zap.REGISTER_BY_NAME["present-position"]
LIVE_LAST = zap.REGISTER_BY_NAME["present-voltage"]
#: How far back (beyond one full allowance) bytes that make no packet put IDs up for another probe.
GARBLED_WINDOW = 0.03
#: ... and at least this many of the probes before them.
GARBLED_PROBES = 8
STATUSES = ("ok", "error", "garbled", "duplicate", "unidentified")


def duplicate_warning(ident: int, baud: int) -> str:
    return (f"ID {ident} at {baud} baud: replies collide: two actuators probably answer to this ID; "
            "connect them one at a time and give one a free ID ('zap set-id')")


def garbled_warning(ident: int, baud: int) -> str:
    return (f"ID {ident} at {baud} baud: every reply was garbled: two actuators may answer to this ID, "
            "or the line is noisy")


def scan(bus, ids, bauds, *, retries: int = 2):
    """Probe ``ids`` at each of ``bauds`` on ``bus`` (a :class:`~zkzap.link.zap_bus.ZapBus`).

    Yields ``("probe", baud, ident, found_so_far, first)`` before each probe (for progress;
    ``first`` is False for the second probes of step 2),
    ``("record", rec)`` for every actuator found (as found) and ``("warning", text)``.
    """
    found = 0
    for baud in bauds:
        bus.set_baud(baud)
        bus.take_events()
        wanted = set(ids)
        done = set()                          # IDs with a record at this baud
        sent_at = []                          # (time, ID) of every quick probe, in order
        recheck = set()
        late_seen = set()

        def account(now_events):
            for kind, who, t in now_events:
                if kind == "late" and who in wanted and who not in done:
                    late_seen.add(who)
                    recheck.add(who)
                    since = next((ts for ts, i in reversed(sent_at) if i == who), None)
                    if since is not None:
                        recheck.update(i for ts, i in sent_at if since <= ts <= t and i not in done)
                elif kind == "garbled":
                    # the colliding reply may have been asked for a full allowance earlier, and
                    # have trickled for a while before the probe that saw it ended
                    window = bus.turnaround + bus.margin + GARBLED_WINDOW
                    recheck.update(i for ts, i in sent_at if t - window <= ts <= t and i not in done)
                    # a host that was held up stretches time: the last few probes, whatever the clock
                    before = [i for ts, i in sent_at if ts <= t][-GARBLED_PROBES:]
                    recheck.update(i for i in before if i not in done)

        held = []                             # found, not yet released: (ID, time, events)

        def release(final=False):
            # in ID order: a record waits while a lower ID may still turn out to be there
            held.sort(key=lambda h: h[0])
            settle = bus.turnaround + bus.margin + 0.005
            now = time.monotonic()
            while held:
                ident, t, events = held[0]
                if not final and (now - t < settle or any(i < ident for i in recheck - done)):
                    break
                held.pop(0)
                yield from events

        def ask(ident, first):
            # one probe (quick on the first pass); what answers is identified and held
            nonlocal found
            if first:
                sent_at.append((time.monotonic(), ident))
            rec = _probe(bus, ident, baud, retries, quick=first)
            account(bus.take_events())
            if rec is not None:
                done.add(ident)
                found += 1
                held.append((ident, time.monotonic(), list(_finish(bus, rec, retries))))
                account(bus.take_events())

        def stragglers():
            # a reply to one of the last probes may still be on its way
            bus.linger(bus.turnaround + bus.margin + bus.patience())
            account(bus.take_events())

        for ident in ids:
            yield ("probe", baud, ident, found, True)
            ask(ident, True)
            yield from release()
        stragglers()
        rounds = 0
        while recheck - done and rounds < 3:
            rounds += 1
            todo = sorted(recheck - done)
            recheck.clear()
            for ident in todo:
                yield ("probe", baud, ident, found, False)
                ask(ident, False)
            stragglers()
        for ident in sorted(late_seen - done):
            # it answers, but never within the wait (a --timeout shorter than its turnaround)
            rec = _record(ident, baud)
            rec["status"] = "unidentified"
            wait = bus.reply_timeout(7, 7, bus.patience()) * 1000
            rec["errors"] = [f"ID {ident} answers only after the wait ({wait:.1f} ms): its replies came late; "
                             "give a longer --timeout"]
            found += 1
            held.append((ident, 0.0, [("record", rec)]))
        yield from release(final=True)


def _record(ident, baud):
    return {"id": ident, "baud": baud, "model": None, "firmware": None, "return_mode": None,
            "status": "ok", "errors": []}


def _probe(bus, ident, baud, retries, quick):
    """An Echo probe: a record when something answered (garbled included), else None."""
    rec = _record(ident, baud)
    try:
        # asked again: as long as the replies seen late need
        r = bus.ping(ident, retries=retries, quick=quick, extra=0.0 if quick else bus.patience())
    except BadReply as e:
        rec["status"] = "garbled"
        rec["errors"] = [str(e)]
        return rec
    if r is None:
        return None
    rec["errors"] = list(r.errors)
    if r.error:
        rec["status"] = "error"
    return rec


def _finish(bus, rec, retries):
    """Identify a found actuator and check for a duplicate; yields the record and warnings."""
    ident, baud = rec["id"], rec["baud"]
    if rec["status"] == "garbled":
        yield ("record", rec)
        yield ("warning", garbled_warning(ident, baud))
        return
    identify(bus, rec, retries)
    if rec["status"] in ("ok", "error") and rec["return_mode"] != 0:
        length = LIVE_LAST.address + LIVE_LAST.size - LIVE_FIRST.address
        try:
            bus.transact(zap.load(ident, LIVE_FIRST.address, length), reply=True, data_len=length,
                         retries=retries, check=False, extra=bus.patience())
        except BadReply as e:
            rec["status"] = "duplicate"
            rec["errors"] = rec["errors"] + [str(e)]
        except NoReply:
            pass
    yield ("record", rec)
    if rec["status"] == "duplicate":
        yield ("warning", duplicate_warning(ident, baud))


def collides(bus, ident: int, retries: int = 2) -> bool:
    """Whether two actuators seem to answer to ``ident``: its live registers (which differ
    between two units) come back garbled on every try."""
    length = LIVE_LAST.address + LIVE_LAST.size - LIVE_FIRST.address
    try:
        bus.transact(zap.load(ident, LIVE_FIRST.address, length), reply=True, data_len=length,
                     retries=retries, check=False, extra=bus.patience())
    except BadReply:
        return True
    except NoReply:
        pass
    return False


def identify(bus, rec, retries=2) -> None:
    """Fill ``model``, ``firmware`` and ``return_mode`` of ``rec`` from one Load Data, or leave
    them null with status ``unidentified`` (or ``duplicate`` when the reply is garbled) and the
    reason in ``errors``."""
    ident = rec["id"]
    length = INFO_LAST.address + INFO_LAST.size - INFO_FIRST.address
    pkt = zap.load(ident, INFO_FIRST.address, length)
    try:
        r = bus.transact(pkt, reply=True, data_len=length, retries=retries, check=False, extra=bus.patience())
    except BadReply as e:
        rec["status"] = "duplicate"
        rec["errors"] = rec["errors"] + [str(e)]
        return
    except NoReply as e:
        full = bus.timeout is None or bus.timeout >= bus.reply_timeout_derived(len(pkt), 7 + length)
        if full and _echo_answers(bus, ident, retries):
            rec["return_mode"] = 0                 # answers Echo, never Load Data: Echo only
            return
        rec["status"] = "unidentified"
        rec["errors"] = rec["errors"] + [f"identify: {e}"]
        return
    values = {reg.name: raw for reg, raw in zap._register_values(INFO_FIRST.address, r.data)}
    rec["model"] = values.get("model-number")
    rec["firmware"] = values.get("firmware-version")
    rec["return_mode"] = values.get("feedback-return-mode")


def _echo_answers(bus, ident, retries) -> bool:
    try:
        return bus.ping(ident, retries=retries, extra=bus.patience()) is not None
    except BadReply:
        return False
