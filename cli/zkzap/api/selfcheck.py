"""Actuator self-check: echo, identity, supply voltage, error bits, a full-stroke move, force
off/on, and the original goal restored.

:func:`check_actuator` yields one verdict row per check: ``id``, ``check``, ``verdict``
(``pass``, ``fail``, ``error`` — the actuator reports error bits —, ``skipped``), ``value``,
``limit`` and ``detail``, and last a row ``check="verdict"`` summing the actuator up. The
move goes to the short stroke limit, then the full stroke to the long one (timed), watching
position, ``moving`` and current: a rod that stops advancing while ``moving`` stays set is a
stall, named with the current it drew against the goal current. Whatever happens after the
move started, the original goal position is written back (and the force left on).

On Modbus RTU (the 17Lf, ``bus`` a :class:`~zkzap.link.modbus_bus.ModbusBus`) the same checks
run over its map: the error bits are its hardware-error register's, the echo is a read of its
model number, and the voltage check is skipped (its map gives no voltage limits, and the
present voltage's unit is not documented: the raw value is shown).

Nothing here imports click or rich.
"""

from __future__ import annotations

import time

from ..codec import zap
from ..errors import BadReply, NoReply

R = zap.REGISTER_BY_NAME
COLUMNS = ["id", "check", "verdict", "value", "limit", "detail"]
#: present-position .. moving in one Load Data while moving.
MOTION_FIRST = R["present-position"]
MOTION_LAST = R["moving"]
#: The rod must advance at least this much (position units) per :data:`STALL_WINDOW` seconds.
STALL_STEP = 2
STALL_WINDOW = 0.3


def _row(ident, check, verdict, value=None, limit=None, detail=""):
    return {"id": ident, "check": check, "verdict": verdict, "value": value, "limit": limit, "detail": detail}


class Motion:
    """The outcome of one move: reached, time, final position, peak current, stall."""

    __slots__ = ("reached", "seconds", "position", "peak_current", "stalled", "timed_out", "errors")

    def __init__(self):
        self.reached = False
        self.seconds = 0.0
        self.position = None
        self.peak_current = 0
        self.stalled = False
        self.timed_out = False
        self.errors = set()


def _modbus(bus) -> bool:
    m = getattr(bus, "regmap", None)
    return m is not None and m.protocol == "modbus"


def _reg(bus, name):
    return bus.regmap.by_name[name] if _modbus(bus) else R[name]


def _read(bus, ident, name) -> tuple:
    """``(raw, error names)`` of one register: a Load Data on IR (the reply's error bits), a read on
    Modbus RTU (an exception reply raises; the error bits are the hardware-error register's)."""
    reg = _reg(bus, name)
    if _modbus(bus):
        _, values = bus.read_registers(ident, reg.address, 1)
        return values[0][1], []
    rep = bus.load(ident, reg.address, reg.size, check=False)
    return rep.value, rep.errors


def _store(bus, ident, name, value):
    return bus.store(ident, _reg(bus, name), value, check=_modbus(bus))


def _motion(bus, ident) -> tuple:
    """``({present-position, moving, present-current}, error names)``: one Load Data on IR; on the
    17Lf, whose table has a gap between them, moving first and then position and current (a rod
    read "stopped" has stopped where the position read after it says)."""
    if _modbus(bus):
        m = bus.regmap.by_name
        moving = bus.read_registers(ident, m["moving"].address, 1)[1][0][1]
        _, values = bus.read_registers(ident, m["present-position"].address, 2)
        v = {reg.name: raw for reg, raw in values}
        v["moving"] = moving
        hw = bus.read_registers(ident, m["hardware-error"].address, 1)[1][0][1]
        return v, error_bits(bus, hw)
    length = MOTION_LAST.address + MOTION_LAST.size - MOTION_FIRST.address
    reply, values = bus.read_registers(ident, MOTION_FIRST.address, length, check=False)
    return {reg.name: raw for reg, raw in values}, reply.errors


def error_bits(bus, raw) -> list:
    """The names of the hardware-error register's bits (Modbus RTU)."""
    bits = bus.regmap.by_name["hardware-error"].bits or {}
    return [bits.get(b, f"bit {b}").replace(" ", "-") for b in range(16) if raw >> b & 1]


def move_and_wait(bus, ident, goal, *, margin, timeout, poll=0.005, clock=time.monotonic):
    """Write goal-position ``goal`` and follow the rod until it stops, stalls or ``timeout``."""
    m = Motion()
    _store(bus, ident, "goal-position", goal)
    t0 = clock()
    mark_t, mark_pos = t0, None
    while True:
        v, errs = _motion(bus, ident)
        now = clock()
        m.errors.update(errs)
        pos, moving, current = v["present-position"], v["moving"], v["present-current"]
        m.position = pos
        m.peak_current = max(m.peak_current, current)
        m.seconds = now - t0
        if not moving:
            m.reached = abs(pos - goal) <= max(margin, 1)
            return m
        if mark_pos is None or abs(pos - mark_pos) > STALL_STEP:
            mark_t, mark_pos = now, pos
        elif now - mark_t >= STALL_WINDOW:
            m.stalled = True
            return m
        if m.seconds >= timeout:
            m.timed_out = True
            return m
        if poll:
            time.sleep(poll)


def check_actuator(bus, ident, *, move=True, move_timeout=10.0, clock=time.monotonic):
    """Verdict rows for one actuator (see the module documentation)."""
    rows = []
    errors = set()

    def add(*a, **k):
        r = _row(ident, *a, **k)
        rows.append(r)
        return r

    # echo
    try:
        r = bus.echo(ident, check=False)
    except (NoReply, BadReply) as e:
        add("echo", "fail", detail=str(e))
        for name in ("identity", "voltage", "errors", "stroke", "force", "restore"):
            add(name, "skipped", detail="no echo")
        add("verdict", "fail", detail="does not answer")
        return rows
    modbus = _modbus(bus)
    if not modbus:
        errors.update(r.errors)
    add("echo", "pass", round(r.rtt * 1000, 2), detail="rtt ms")

    # identity and voltage: one read of model-number .. highest-limit-voltage and the present voltage
    def read(reg):
        value, errs = _read(bus, ident, reg.name)
        errors.update(errs)
        return value

    model, fw = read(_reg(bus, "model-number")), read(_reg(bus, "firmware-version"))
    add("identity", "pass", f"0x{model:04X}/{fw}", detail="model/firmware")
    if modbus:
        volts = read(_reg(bus, "present-voltage"))
        add("voltage", "skipped", volts, detail="raw: the 17Lf's map gives no voltage limits (nor the unit)")
        errors.update(error_bits(bus, read(_reg(bus, "hardware-error"))))
    else:
        lo, hi, volts = read(R["lowest-limit-voltage"]), read(R["highest-limit-voltage"]), read(R["present-voltage"])
        vr = R["present-voltage"]
        ok = lo <= volts <= hi
        add("voltage", "pass" if ok else "fail", vr.physical(volts), f"{vr.physical(lo):g}..{vr.physical(hi):g} V",
            detail="" if ok else "supply outside the actuator's voltage limits")
    bits = sorted(errors)
    add("errors", "error" if bits else "pass", ", ".join(bits) or "none",
        detail="; ".join(zap.ERROR_TEXT.get(b, b) for b in bits))

    # stroke and force
    if not move:
        add("stroke", "skipped", detail="--no-move")
        add("force", "skipped", detail="--no-move")
        add("restore", "skipped", detail="--no-move")
    else:
        original = read(_reg(bus, "goal-position"))
        short, long_ = read(_reg(bus, "short-stroke-limit")), read(_reg(bus, "long-stroke-limit"))
        short, long_ = min(short, long_), max(short, long_)
        margin = read(_reg(bus, "end-compliance-margin"))
        goal_current = read(_reg(bus, "goal-current"))
        try:
            first = move_and_wait(bus, ident, short, margin=margin, timeout=move_timeout, clock=clock)
            errors.update(first.errors)
            if not first.reached:
                add("stroke", "fail", first.position, f"{short}..{long_}",
                    detail=_why(first, short, goal_current, "to the short stroke limit"))
            else:
                full = move_and_wait(bus, ident, long_, margin=margin, timeout=move_timeout, clock=clock)
                errors.update(full.errors)
                if full.reached:
                    add("stroke", "pass", round(full.seconds, 3), f"{short}..{long_}",
                        detail=f"full stroke in {full.seconds:.2f} s, peak current {full.peak_current} mA")
                else:
                    add("stroke", "fail", full.position, f"{short}..{long_}",
                        detail=_why(full, long_, goal_current, "to the long stroke limit"))
            # force off, then on
            force = _reg(bus, "force-on-off")
            _store(bus, ident, force.name, 0)
            off = read(force)
            _store(bus, ident, force.name, 1)
            on = read(force)
            ok = off == 0 and on == 1
            add("force", "pass" if ok else "fail", f"{off}/{on}", "0/1",
                detail="force off then on" if ok else "force-on-off did not follow (an alarm holds it off?)")
        finally:
            back = move_and_wait(bus, ident, original, margin=margin, timeout=move_timeout, clock=clock)
        errors.update(back.errors)
        add("restore", "pass" if back.reached else "fail", back.position, original,
            detail="original goal restored" if back.reached else _why(back, original, goal_current,
                                                                      "back to the original goal"))
    bits = sorted(errors)
    err_row = next(r for r in rows if r["check"] == "errors")
    if bits and err_row["verdict"] == "pass":
        err_row.update(verdict="error", value=", ".join(bits), detail="; ".join(zap.ERROR_TEXT.get(b, b) for b in bits))
    verdicts = [r["verdict"] for r in rows]
    overall = "error" if "error" in verdicts else "fail" if "fail" in verdicts else "pass"
    failed = [r["check"] for r in rows if r["verdict"] in ("fail", "error")]
    add("verdict", overall, detail=", ".join(failed) if failed else "all checks passed")
    return rows


def _why(m, goal, goal_current, what):
    if m.stalled:
        at_limit = m.peak_current >= goal_current * 0.9 if goal_current else False
        return (f"stalled at {m.position} on the way {what} (goal {goal}), current {m.peak_current} mA"
                + (" at the goal current: blocked" if at_limit else ""))
    if m.timed_out:
        return f"still moving {what} after {m.seconds:.1f} s (position {m.position}, goal {goal})"
    return f"stopped at {m.position} on the way {what}, {abs(m.position - goal)} from the goal {goal}"
