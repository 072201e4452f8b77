"""The mightyZAP console: scan, the actuators with their identity, errors and live position,
current and voltage; moves (one, or several at once by Symmetric Store), the register table,
a fleet file's backup, diff and apply, and each actuator's self-check.

The worker owns the :class:`~zkzap.api.zap.Bus` (a half-duplex line: one transaction at a
time). Between requests it polls the actuators found (:class:`~zkzap.api.watch.Watcher`:
goal and present position, current, voltage, moving, in one Load Data each); a request ends
the poll in between two polls and the poll resumes after it. Long jobs (scan, backup, apply,
check) report progress and stop at the next step when cancelled. Writes carry the library's
permissions, as the page granted them (:class:`~.consent.Policy`): the bus refuses a frame that
needs one more, and the page asks for it.
"""

from __future__ import annotations

import contextlib
import time

from ..api import fleet
from ..api.watch import Watcher
from ..codec import modbus, zap
from ..codec.fields import FieldValueError
from ..errors import BadReply, CheckFailed, NoReply, UsageError
from .consent import force_values, needs_force
from .console import Console, number
from .zap_motion import MotionTools
from .zap_packets import PacketTools

R = zap.REGISTER_BY_NAME
#: What the live view polls, in one Load Data per actuator (goal-position .. moving).
LIVE = [R[n] for n in ("goal-position", "goal-speed", "goal-current", "present-position", "present-current",
                       "present-voltage", "moving")]
#: Short keys of a live sample, by register.
SHORT = {"goal-position": "goal", "goal-speed": "gspeed", "goal-current": "gcur", "present-position": "pos",
         "present-current": "cur", "present-voltage": "volt", "moving": "moving"}
#: Requests that move actuators (refused while a job runs: it has the bus).
MOVES = ("move", "sync", "stop", "goals", "packet", "teach", "teach-take")
#: Progress messages per second, at most.
PROGRESS_HZ = 20


class Cancelled(Exception):
    """A job the page cancelled."""


class ZapConsole(PacketTools, MotionTools, Console):
    """The console over ``bus`` (an open :class:`~zkzap.api.zap.Bus`); ``rate``: polls per
    second at most (None: as fast as the line allows); ``scan_ids`` the IDs the first scan
    searches (None: no scan at the start)."""

    kind = "zap"

    def __init__(self, bus, *, rate=30.0, scan_ids=range(254), retries=2):
        super().__init__(bus.url, simulated=bus.link.simulated)
        self.bus = bus
        #: The bus's protocol family, and its register map on Modbus RTU (None: the 12Lf's IR table).
        self.protocol = getattr(bus, "protocol", "ir")
        self.map = bus.map if self.protocol == "modbus" else None
        self.rate = rate
        self.retries = retries
        self.actuators = {}           # ID -> record (identity, baud, status, errors)
        self.busy = None              # the running job's name
        self._cancel = False
        self._progress_t = 0.0
        self._first_scan = list(scan_ids) if scan_ids is not None else None
        self.polls = 0
        self.tools_init()
        self.motion_init()

    @contextlib.contextmanager
    def granting(self, allow):
        saved = self.bus.allow
        self.bus.allow = saved | allow
        try:
            yield
        finally:
            self.bus.allow = saved

    # -- the worker -----------------------------------------------------------------------------

    def run(self):
        if self._first_scan:
            self._job(None, "scan", lambda: self._scan(None, self._first_scan, [self.bus.baud]))
        while not self.closing_now:
            self.handle_requests()
            self.teach_tick()
            polled = [i for i, a in self.actuators.items() if a["baud"] == self.bus.baud and a["polled"]]
            if polled and not self.closing_now:
                self._watch(polled)
            else:
                self.wait(0.25)

    def _watch(self, ids):
        """Poll ``ids`` until a request comes (between two polls) or the console closes."""
        plotted = self.plotted
        w = Watcher(self.bus.link, ids, self.live() + ([plotted] if plotted is not None else []), rate=self.rate,
                    retries=0)
        self._polling = True
        try:
            for row in w.rows():
                self._polling = False
                self._sample(row, plotted)
                if row["id"] == ids[-1]:
                    self.polls += 1
                    if self.pending() or self.closing_now or self.teach_due() or plotted is not self.plotted:
                        break
                self._polling = True
        finally:
            self._polling = False

    def _sample(self, row, plotted=None):
        item = {"w": round(time.time() * 1000, 1), "id": row["id"], "status": row["status"],
                "errors": row["errors"], "rtt": row["rtt_ms"]}
        for reg in self.live():
            v = row.get(reg.name)
            item[SHORT[reg.name]] = reg.physical(v) if v is not None else None
        if plotted is not None:
            v = row.get(plotted.name)
            item["reg"] = plotted.physical(v) if v is not None else None
        a = self.actuators.get(row["id"])
        if a is not None:
            if row["status"] == "ok" and a["errors"] != row["errors"]:
                a["errors"] = row["errors"]
                self._table()
            a["link"] = row["status"]
        self.hub.sample(item)

    def closing(self):
        self._cancel = True
        with self._wake:
            self._wake.notify_all()

    def shutdown(self):
        self.bus.close()

    # -- requests -------------------------------------------------------------------------------

    def request(self, cid, label, msg):
        op = msg.get("op")
        if op == "cancel":                 # taken at once: the job stops at its next step
            if self.busy:
                self._cancel = True
                self.log(f"{label} cancels the {self.busy}", "warn")
            return
        if self.busy and op in MOVES:
            self.hub.send(cid, {"type": "error", "req": msg.get("req"), "text": f"busy: {self.busy} in progress"})
            return
        if op == "move":                    # a slider: only its latest position counts
            with self._wake:
                for r in self._requests:
                    if r.msg.get("op") == "move" and r.msg.get("id") == msg.get("id") and r.cid == cid:
                        r.msg = msg
                        r.req = msg.get("req")
                        return
        super().request(cid, label, msg)

    def handle(self, ctx):
        op = ctx.msg.get("op")
        if op in JOBS or op in MOTION_JOBS:
            self._job(ctx, op, lambda: Console.handle(self, ctx))
        else:
            super().handle(ctx)

    def _job(self, ctx, name, fn):
        """Run a long request: the pages know the bus is busy and see its progress."""
        self.busy = name
        self._cancel = False
        self.broadcast({"type": "busy", "job": name, "by": ctx.label if ctx else None})
        try:
            fn()
        except Cancelled:
            self.log(f"{name} cancelled", "warn")
            if ctx is not None:
                self.error(ctx, f"{name} cancelled")
        except Exception as e:  # noqa: BLE001 - reported, then the console goes on (a port failure too)
            from ..errors import PortError, ZkzapError

            if isinstance(e, PortError) or not isinstance(e, (ZkzapError, ValueError)):
                raise
            if ctx is not None:
                self.error(ctx, str(e))
            self.log(f"{name}: {e}", "error")
        finally:
            self.busy = None
            self._cancel = False
            self.broadcast({"type": "busy", "job": None})

    def _progress(self, job, done, total, text=""):
        if self._cancel:
            raise Cancelled()
        now = time.monotonic()
        if done < total and now - self._progress_t < 1.0 / PROGRESS_HZ:
            return
        self._progress_t = now
        self.broadcast({"type": "progress", "job": job, "done": done, "total": total, "text": text})

    # the protocol's table: the 12Lf's IR registers, or the Modbus map's ------------------------

    def reg(self, name):
        """A register by name or address, of the bus's map."""
        try:
            return self.map.register(name) if self.map is not None else zap.register(name)
        except FieldValueError as e:
            raise UsageError(str(e)) from None

    def live(self) -> list:
        """What the live view polls: LIVE's registers that the map has."""
        if self.map is None:
            return LIVE
        return [self.map.by_name[r.name] for r in LIVE if r.name in self.map.by_name]

    @property
    def max_id(self) -> int:
        return modbus.MAX_ID if self.map is not None else zap.MAX_ID

    @property
    def bauds(self) -> list:
        return sorted(self.map.baud_codes.values(), reverse=True) if self.map is not None else list(zap.BAUD_TO_CODE)

    def hello(self):
        out = super().hello()
        registers = self.map.registers if self.map is not None else zap.REGISTERS
        out.update({"baud": self.bus.baud, "bauds": self.bauds, "rate": self.rate,
                    "protocol": self.protocol, "model": self.map.model if self.map is not None else "12Lf",
                    "return_mode": self.bus.return_mode,
                    "registers": [_register_info(r, self.map) for r in registers],
                    "protected": list(fleet.PROTECTED), "formats": list(fleet.SUFFIXES.values())})
        out.update(self.tools_hello())
        return out

    def snapshot(self):
        return super().snapshot() + [self._table_message(), {"type": "busy", "job": self.busy}] + self.motion_snapshot()

    def _table_message(self):
        return {"type": "actuators", "baud": self.bus.baud, "items": list(self.actuators.values())}

    def _table(self):
        self.broadcast(self._table_message())

    def _known(self, msg, key="id"):
        ident = number(msg, key, int, 0, self.max_id, "id")
        if ident not in self.actuators:
            raise UsageError(f"id: no actuator {ident} was found; scan first")
        return ident

    # scan -------------------------------------------------------------------------------------

    def op_scan(self, ctx, msg):
        try:
            ids = zap.parse_id_list(str(msg.get("ids") or ("1-247" if self.map is not None else "0-253")), "ids")
        except FieldValueError as e:
            raise UsageError(str(e)) from None
        if self.map is not None:
            for i in ids:
                modbus.check_id(i, allow_broadcast=False)
        bauds = msg.get("bauds") or [self.bus.baud]
        if not isinstance(bauds, list) or not all(isinstance(b, int) and b in self.bauds for b in bauds):
            raise UsageError(f"bauds: {bauds!r}; allowed {', '.join(map(str, self.bauds))}")
        self._scan(ctx, ids, bauds)

    def _scan(self, ctx, ids, bauds):
        total = len(ids) * len(bauds)
        count = {"n": 0}
        was = self.bus.baud
        found = {}

        def probe(baud, ident, hit):
            count["n"] += 1
            self._progress("scan", count["n"], total, f"ID {ident} at {baud} baud")

        self.log(f"scan: IDs {_ranges(ids)} at {', '.join(map(str, bauds))} baud")
        try:
            for rec in self.bus.scan(ids, bauds, retries=self.retries, on_probe=probe,
                                     on_warning=lambda text: self.log(f"scan: {text}", "warn"),
                                     on_note=lambda text: self.log(f"scan: {text}")):
                rec = dict(rec)
                rec["polled"] = rec["status"] not in ("garbled", "duplicate") and rec.get("return_mode") != 0
                rec["link"] = None
                found[rec["id"]] = rec
        finally:
            self._progress("scan", total, total, "done")
        self._second_look(found)
        # poll at the baud rate most actuators answered at (the first scanned when tied)
        bauds_found = [r["baud"] for r in found.values()]
        best = max(bauds, key=lambda b: (bauds_found.count(b), -bauds.index(b))) if bauds_found else was
        if self.bus.baud != best:
            self.bus.baud = best
        self.actuators = dict(sorted(found.items()))
        self._table()
        others = sorted(i for i, r in found.items() if r["baud"] != best)
        text = (f"scan: {len(found)} actuator{'s' if len(found) != 1 else ''} found"
                + (f" (IDs {_ranges(sorted(found))})" if found else "")
                + (f"; IDs {_ranges(others)} answer at another baud rate and are not polled at {best}" if others
                   else ""))
        self.log(text, "info" if found else "warn")
        self.reply(ctx, found=sorted(found))

    def _second_look(self, found):
        """Actuators that answered Echo but gave no identity (Load Data unanswered: return mode
        0, or a reply too late on a busy line) are asked once more at their baud rate, so a late
        reply does not leave an actuator unpolled."""
        for ident, rec in found.items():
            if rec["model"] is not None or rec["status"] in ("garbled", "duplicate"):
                continue
            if self.bus.baud != rec["baud"]:
                self.bus.baud = rec["baud"]
            again = self.bus.identify(ident)
            if again["model"] is not None:
                rec.update(again, polled=True)
                self.log(f"scan: ID {ident} identified on a second look (model 0x{again['model']:04X})")

    # moves ------------------------------------------------------------------------------------

    def op_move(self, ctx, msg):
        ident = self._known(msg)
        pos = number(msg, "position", int, 0, self.reg("goal-position").hi, "goal-position")
        self.bus.move(ident, pos, wait=False)
        self.reply(ctx, id=ident, position=pos)

    def op_goals(self, ctx, msg):
        """goal-speed and/or goal-current of one actuator (volatile: no consent)."""
        ident = self._known(msg)
        wrote = {}
        for key, name in (("speed", "goal-speed"), ("current", "goal-current")):
            if msg.get(key) is not None:
                wrote[name] = number(msg, key, int, self.reg(name).lo, self.reg(name).hi, name)
        if not wrote:
            raise UsageError("goals: give speed or current")
        for name, value in wrote.items():
            self.bus.store(ident, name, value)
        self.log(f"{ctx.label}: ID {ident} " + ", ".join(f"{n} {v}" for n, v in wrote.items()))
        self.reply(ctx, id=ident, **{n.replace("goal-", ""): v for n, v in wrote.items()})

    def op_sync(self, ctx, msg):
        targets = msg.get("targets")
        if not isinstance(targets, dict) or not targets:
            raise UsageError("sync: no targets; give {id: position, ...}")
        out = {}
        for key, value in targets.items():
            ident = self._known({"id": key})
            out[ident] = number({"p": value}, "p", int, 0, self.reg("goal-position").hi,
                                f"goal-position of ID {ident}")
        self.bus.sync_move(out)
        self.log(f"{ctx.label}: sync-move " + ", ".join(f"ID {i} to {p}" for i, p in out.items()))
        self.reply(ctx, targets=out)

    def op_stop(self, ctx, msg):
        ids = [self._known(msg)] if msg.get("id") is not None else [i for i, a in self.actuators.items()
                                                                       if a["polled"] and a["baud"] == self.bus.baud]
        where = {}
        for ident in ids:
            try:
                where[ident] = self.bus.stop(ident)
            except NoReply as e:
                self.log(f"stop: {e}", "warn")
        if where:
            self.log(f"{ctx.label}: stopped " + ", ".join(f"ID {i} at {p}" for i, p in where.items()))
        self.reply(ctx, stopped=where)

    # registers --------------------------------------------------------------------------------

    def op_registers(self, ctx, msg):
        ident = self._known(msg)
        records, worst = self.bus.dump_records(ident)
        self.reply(ctx, id=ident, records=records, errors=worst.errors if worst is not None else [])

    def op_write(self, ctx, msg):
        ident = self._known(msg)
        reg = self.reg(str(msg.get("register")))
        if not reg.writable:
            raise UsageError(f"{reg.name} is read-only")
        value = number(msg, "value", int, what=reg.name)
        reg.check(value)
        if reg.name == "id":
            new = self.bus.set_id(ident, value, force=False)     # the checked way: a stored write
            rec = self.actuators.pop(ident)
            rec["id"] = new
            self.actuators[new] = rec
            self.actuators = dict(sorted(self.actuators.items()))
            self.log(f"{ctx.label}: ID {ident} is now ID {new} (read back from ID {new})", "warn")
            self._table()
            self.reply(ctx, id=new, register=reg.name, value=new)
            return
        if reg.name == "baud-rate":
            baud = self.map.baud_codes[value] if self.map is not None else zap.BAUD_CODES[value]
            was = self.bus.baud
            try:
                self.bus.set_baud(ident, baud)
            except (NoReply, BadReply, CheckFailed) as e:
                self._baud_failed(ctx, ident, was, baud, e)      # logged, settled, then the page's error
            self.actuators[ident]["baud"] = baud
            if any(a["baud"] == was for i, a in self.actuators.items() if i != ident):
                self.bus.baud = was          # the others are still at the old rate
            self.log(f"{ctx.label}: ID {ident} now talks at {baud} baud (verified)", "warn")
            self._table()
            self.reply(ctx, id=ident, register=reg.name, value=value)
            return
        self.bus.store(ident, reg, value)          # with what the page granted (see granting)
        if reg.name == "feedback-return-mode":
            self.actuators[ident]["return_mode"] = value
            self.actuators[ident]["polled"] = value != 0
            self._table()
        back = self.bus.load(ident, reg) if reg.name != "feedback-return-mode" or value else None
        where = "stored" if reg.stored else "volatile"
        self.log(f"{ctx.label}: ID {ident} {reg.name} = {value} ({where}" +
                 (f", reads back {back})" if back is not None else ")"), "warn" if reg.stored else "info")
        if back is not None and back != value:
            raise UsageError(f"ID {ident}: {reg.name} reads back {back}, not the {value} written")
        self.reply(ctx, id=ident, register=reg.name, value=value, read_back=back)

    def _baud_failed(self, ctx, ident, was, baud, e):
        """A baud change that failed (the library rolls back what it can: ``e.rolled_back``): said
        in the log, then the actuator's true state read back (:meth:`~zkzap.api.zap.Bus.baud_state`)
        and said in the log and the page's error; the table shows the rate it answers at."""
        self.log(f"{ctx.label}: ID {ident} baud change {was} -> {baud} failed: {e}", "error")
        try:
            st = self.bus.baud_state(ident, (was, baud))
        except (NoReply, BadReply, CheckFailed, UsageError) as again:
            st = {"answers_at": None, "code": None, "stored_baud": None, "why": str(again)}
        rate, code, stored = st["answers_at"], st["code"], st["stored_baud"]
        holds = "its stored baud-rate is unread" if code is None else f"it stores baud-rate code {code} ({stored})"
        if rate is None:
            text = (f"ID {ident} answers at neither {was} nor {baud} baud: its state is unknown; scan at every baud "
                    "rate")
        elif rate == was and stored not in (None, was):
            text = (f"ID {ident} answers at {was} baud, but {holds}: it will answer at {stored} only after its "
                    "next power-up")
        elif rate == was:
            text = f"ID {ident} answers at {was} baud and {holds}: unchanged" + \
                (" (rolled back)" if getattr(e, "rolled_back", False) else "")
        else:
            text = f"ID {ident} answers at {baud} baud now and {holds}: the change took effect, its read-back failed"
        if rate is not None:
            self.actuators[ident]["baud"] = rate
        self.actuators[ident]["polled"] = rate is not None and self.actuators[ident].get("return_mode") != 0
        if any(a["baud"] == was for i, a in self.actuators.items() if i != ident) and self.bus.baud != was:
            self.bus.baud = was              # the others are still at the old rate
        self.log(text, "warn" if rate is not None and stored in (None, rate) else "error")
        self._table()
        raise CheckFailed(f"baud change of ID {ident} to {baud} failed ({e}); {text}", ident=ident) from None

    # check ------------------------------------------------------------------------------------

    def op_check(self, ctx, msg):
        from ..api.selfcheck import check_actuator

        ident = self._known(msg)
        move = bool(msg.get("move", True))
        self.policy.zap_check([ident], move, ctx.granted)
        self._progress("check", 0, 1, f"checking ID {ident}")
        rows = check_actuator(self.bus.link, ident, move=move)
        self._progress("check", 1, 1, "done")
        verdict = rows[-1]
        self.log(f"check ID {ident}: {verdict['verdict']} ({verdict['detail']})",
                 "info" if verdict["verdict"] == "pass" else "error")
        self.reply(ctx, id=ident, rows=rows)

    # fleet ------------------------------------------------------------------------------------

    def _fleet_ids(self):
        ids = [i for i, a in self.actuators.items() if a["baud"] == self.bus.baud and a.get("return_mode") != 0]
        if not ids:
            raise UsageError("no actuator to read at this baud rate; scan first")
        return ids

    def op_backup(self, ctx, msg):
        fmt = str(msg.get("format") or "json")
        if fmt not in fleet.SUFFIXES.values():
            raise UsageError(f"format: {fmt!r}; allowed json, toml, yaml")
        ids = self._fleet_ids()
        n = {"done": 0}

        def said(ident, entry):
            n["done"] += 1
            self._progress("backup", n["done"], len(ids), f"ID {ident} read")

        self._progress("backup", 0, len(ids), "reading")
        doc = fleet.read_bus(self.bus.link, ids, on_actuator=said)
        doc["port"] = self.url
        stamp = time.strftime("%Y%m%d-%H%M%S")
        self.log(f"backup: {len(ids)} actuator{'s' if len(ids) != 1 else ''} ({_ranges(ids)}) read")
        self.reply(ctx, text=fleet.dumps(doc, fmt), filename=f"fleet-{stamp}.{fmt}")

    def _document(self, msg):
        name = str(msg.get("name") or "fleet.json")
        text = msg.get("text")
        if not isinstance(text, str):
            raise UsageError("file: no text")
        entries = fleet.check_document(fleet.loads(text, fleet.format_of(name), name), name)
        return name, entries

    def op_diff(self, ctx, msg):
        name, entries = self._document(msg)
        compare = msg.get("compare") or "stored"
        if compare not in fleet.COMPARE:
            raise UsageError(f"compare: {compare!r}; allowed {', '.join(fleet.COMPARE)}")
        self._progress("diff", 0, 1, "reading the bus")
        # every actuator that answers at this baud rate, as zap diff finds them: one only on the bus is a row too
        live = fleet.bus_entries(self.bus.link, None, [self.bus.baud], retries=self.retries)
        self._progress("diff", 1, 1, "done")
        rows = fleet.diff(entries, live, compare=compare)
        self.log(f"diff {name} with the bus: {len(rows)} difference{'s' if len(rows) != 1 else ''}")
        self.reply(ctx, rows=rows, name=name)

    def op_apply(self, ctx, msg):
        name, entries = self._document(msg)
        force = "force" in ctx.granted
        pairs = fleet.assignments(entries)
        writes, unchanged, _ = fleet.plan_bus(self.bus.link, entries, pairs, name=name, force=force,
                                              on_mismatch=lambda t: self.log(t, "warn"))
        if msg.get("plan") or not writes:
            self.reply(ctx, plan=[w.record() for w in writes], unchanged=unchanged, applied=False)
            return
        done = []
        count = {"n": 0}

        def wrote(w):
            count["n"] += 1
            self._progress("apply", count["n"], len(writes), f"ID {w.target} {w.register.name}")

        try:
            fleet.execute(self.bus.link, writes, done, on_write=wrote)
        finally:
            made = len(done)
            self.log(f"apply {name}: {made} of {len(writes)} writes made", "warn" if made < len(writes) else "info")
        bad = [w for w in writes if w.status not in ("verified", "unverifiable")]
        self.reply(ctx, plan=[w.record() for w in writes], unchanged=unchanged, applied=True, failed=len(bad))


#: Requests that take the bus for a while (the pages show them as busy).
JOBS = ("scan", "backup", "diff", "apply", "check")
#: The motion requests that are jobs too (see :mod:`.zap_motion`).
MOTION_JOBS = ("play", "cycle")


def _register_info(reg, regmap=None) -> dict:
    return {"name": reg.name, "address": reg.address, "size": reg.size, "access": reg.access,
            "memory": reg.memory, "lo": reg.lo, "hi": reg.hi, "unit": reg.unit, "scale": reg.scale,
            "choices": {str(k): v for k, v in reg.choices.items()} if reg.choices else None,
            "range": reg.describe_range(), "help": reg.help, "default": reg.default,
            "protected": needs_force(reg, regmap=regmap), "force_values": force_values(reg, regmap)}


def _ranges(ids) -> str:
    return zap.id_ranges(ids)
