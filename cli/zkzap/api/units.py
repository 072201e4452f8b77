"""Physical units of a mightyZAP rod: positions in millimetres, speeds in mm/s.

An actuator reports its position in counts (0..4095 over the potentiometer's travel). How many
millimetres a count is depends on the actuator's stroke, which the register map does not
hold (every 12Lf reports model number 41234, whatever its stroke): it comes from the fleet
file, per actuator, in its ``motion`` entry::

    "actuators": {"1": {"motion": {"part": "12Lf-20PT-27"}, ...}}            # the stroke from the part
    "actuators": {"2": {"motion": {"stroke_mm": 27}, ...}}                    # or given
    "actuators": {"3": {"motion": {"stroke_mm": 27, "calibration":            # or taught: zap calibrate
                                   {"retracted": 12, "extended": 3671, "travel_mm": 26.9}}}}

:data:`PARTS` is the model table: the part numbers whose stroke IR Robot's datasheets give.
The rated stroke ends at the factory long-stroke-limit, 3686 counts (:data:`RATED_COUNTS`):
the L12-xxF-3 datasheet gives "27 mm (extendable to 30 mm)", and 27/30 of 4096 counts is
3686.4 — the factory long-stroke-limit. So without a calibration a count is
``stroke_mm / 3686`` mm from the fully retracted rod (count 0). A calibration (``zap
calibrate``: the operator shows the two ends) replaces that with the two taught ends and the
travel measured between them.

A model's position range comes from its register map (:func:`position_range`): the 12Lf's
potentiometer counts 0..4095 with its rated stroke at the factory long-stroke-limit (3686, the
map's default); the 17Lf's control table takes positions 0..10000 over its whole stroke (its
long-stroke-limit default is per model, so the range's top is the rated stroke's end). No 17Lf
part number with its stroke from a datasheet is in hand: a 17Lf's motion entry gives
``stroke_mm`` or a calibration (a part is refused, never guessed).

Speeds: goal-speed is a raw 0..1023 of the motor's rate, not a velocity; its mm/s needs the
rod's speed at goal-speed 1023, ``max_speed_mm_s`` in the motion entry (``zap calibrate
--measure-speed`` times a full stroke). Without it a speed in mm/s is refused, never guessed.
Velocities measured from positions over time convert with the stroke alone.

Nothing here imports click or rich.
"""

from __future__ import annotations

import math
import re

from ..errors import UsageError

#: Counts at the end of the rated stroke: the factory long-stroke-limit (0.9 x 4096).
RATED_COUNTS = 3686
#: The highest count a rod reports.
MAX_COUNTS = 4095
#: Keys of a fleet file's ``motion`` entry.
MOTION_KEYS = ("part", "stroke_mm", "max_speed_mm_s", "calibration")
CALIBRATION_KEYS = ("retracted", "extended", "travel_mm", "time")
#: Units of ``--unit``.
UNITS = ("counts", "mm")

#: The model table: part number pattern (``xx`` is the rated force and gear option, any digits)
#: -> (stroke in mm, the datasheet it comes from).
PARTS = (
    (r"12Lf-\d+PT-27", 27.0, "12Lf-xxPT-27 datasheet"),
    (r"L12-\d+F-3", 27.0, "L12-xxF-3 datasheet (27 mm, extendable to 30 mm)"),
    (r"L12-\d+PT-3", 27.0, "L12-xxPT-3 datasheet"),
    (r"L12-\d+PT-6", 56.0, "L12-xxPT-6 datasheet"),
)


def position_range(regmap=None) -> tuple:
    """``(rated, top)`` counts of a model's map (None: the 12Lf's IR map): the count at the end
    of the rated stroke (the map's long-stroke-limit default, else the top of goal-position's
    range) and the highest position the map takes."""
    if regmap is None:
        return RATED_COUNTS, MAX_COUNTS
    goal = regmap.by_name.get("goal-position")
    if goal is None:
        raise UsageError(f"--unit mm: the {regmap.model} map has no goal-position", model=regmap.model)
    top = goal.hi
    limit = regmap.by_name.get("long-stroke-limit")
    rated = limit.default if limit is not None and limit.default is not None else top
    return rated, top


def stroke_of_part(part: str) -> float:
    """The rated stroke (mm) of a part number of :data:`PARTS`; UsageError for another."""
    text = str(part).strip()
    for pattern, stroke, _ in PARTS:
        if re.fullmatch(pattern, text, flags=re.IGNORECASE):
            return stroke
    known = ", ".join(p.replace(r"\d+", "xx") for p, _, _ in PARTS)
    raise UsageError(f"part {text!r}: its stroke is not in the model table ({known}); give stroke_mm in the "
                     "fleet file's motion entry", part=text)


class Scale:
    """Counts <-> millimetres for one actuator: ``mm = (counts - zero) * mm_per_count``.

    ``stroke_mm``: the rated stroke (counts 0 .. :data:`RATED_COUNTS`); ``calibration``:
    ``{"retracted": counts, "extended": counts, "travel_mm": mm}`` from ``zap calibrate``
    (replaces the rated mapping: the retracted end is 0 mm; without ``travel_mm`` the travel
    between the ends follows from the rated stroke); ``max_speed_mm_s``: the rod's
    speed at goal-speed 1023."""

    __slots__ = ("ident", "stroke_mm", "zero", "mm_per_count", "max_speed_mm_s", "source", "top")

    def __init__(self, stroke_mm=None, *, calibration=None, max_speed_mm_s=None, ident=None, source="",
                 regmap=None):
        self.ident = ident
        self.stroke_mm = stroke_mm
        self.max_speed_mm_s = max_speed_mm_s
        rated, self.top = position_range(regmap)
        if calibration:
            lo, hi = calibration["retracted"], calibration["extended"]
            travel = calibration.get("travel_mm")
            if travel is None:             # the ends taught, the travel from the rated stroke
                if not stroke_mm:
                    raise UsageError(f"ID {ident}: a calibration without travel_mm needs the stroke (part or "
                                     "stroke_mm)", ident=ident)
                travel = abs(hi - lo) * stroke_mm / rated
            for end in (lo, hi):
                if end > self.top:
                    raise UsageError(f"ID {ident}: calibration end {end} is beyond the model's positions "
                                     f"(0..{self.top})", ident=ident)
            self.zero = lo
            self.mm_per_count = travel / (hi - lo)
            self.source = source or "calibration"
        else:
            if not stroke_mm:
                raise UsageError("a scale needs a stroke or a calibration")
            self.zero = 0
            self.mm_per_count = stroke_mm / rated
            self.source = source or f"stroke {stroke_mm:g} mm"

    def __repr__(self) -> str:
        return f"Scale(id={self.ident}, {self.mm_per_count * 1000:.3f} um/count, zero {self.zero}, {self.source})"

    def mm(self, counts) -> float:
        """Millimetres of a position in counts (from the retracted end), to 0.001 mm."""
        return round((counts - self.zero) * self.mm_per_count, 3)

    def counts(self, mm: float, *, what: str = "position") -> int:
        """The count nearest ``mm``; UsageError when it falls outside the model's positions
        (0..4095 on the 12Lf, 0..10000 on the 17Lf)."""
        if not math.isfinite(mm):
            raise UsageError(f"{what}: {mm!r} mm is not a finite number")
        c = round(self.zero + mm / self.mm_per_count)
        if not 0 <= c <= self.top:
            lo, hi = self.mm(0), self.mm(self.top)
            raise UsageError(f"{what}: {mm:g} mm is outside the rod's travel ({min(lo, hi):g}..{max(lo, hi):g} mm"
                             f"{self._who()})", mm=mm)
        return c

    def mm_s(self, counts_per_s: float) -> float:
        """A velocity in counts per second as mm/s."""
        return round(counts_per_s * abs(self.mm_per_count), 3)

    def speed_raw(self, mm_s: float) -> int:
        """goal-speed (1..1023) for ``mm_s``; UsageError without ``max_speed_mm_s`` or beyond it."""
        if not self.max_speed_mm_s:
            raise UsageError(f"speed in mm/s{self._who()}: the rod's speed at goal-speed 1023 is not known; give "
                             "max_speed_mm_s in the fleet file's motion entry (zap calibrate --measure-speed "
                             "measures it) or the speed in counts")
        if not (math.isfinite(mm_s) and 0 < mm_s <= self.max_speed_mm_s):
            raise UsageError(f"speed: {mm_s:g} mm/s is outside 0..{self.max_speed_mm_s:g} mm/s{self._who()}")
        return max(1, min(1023, round(1023 * mm_s / self.max_speed_mm_s)))

    def speed_mm_s(self, raw: int):
        """The mm/s of goal-speed ``raw`` (None without ``max_speed_mm_s``)."""
        if not self.max_speed_mm_s:
            return None
        return round(raw * self.max_speed_mm_s / 1023, 3)

    def _who(self) -> str:
        return f" of ID {self.ident}" if self.ident is not None else ""


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def check_motion(entry, where: str, fail) -> dict:
    """Check a fleet file's ``motion`` entry (``fail(key, text)`` raises naming the key);
    returns it."""
    if not isinstance(entry, dict):
        fail(where, "expected an object with part, stroke_mm, max_speed_mm_s, calibration")
    for k in entry:
        if k not in MOTION_KEYS:
            fail(f"{where}.{k}", f"unknown key; allowed {', '.join(MOTION_KEYS)}")
    part = entry.get("part")
    if part is not None:
        if not isinstance(part, str):
            fail(f"{where}.part", f"{part!r} is not a part number")
    for k in ("stroke_mm", "max_speed_mm_s"):
        v = entry.get(k)
        if v is not None and not (_number(v) and 0 < v <= 1000):
            fail(f"{where}.{k}", f"{v!r} is not a length in mm (0..1000)" if k == "stroke_mm"
                 else f"{v!r} is not a speed in mm/s (0..1000)")
    cal = entry.get("calibration")
    if cal is not None:
        if not isinstance(cal, dict):
            fail(f"{where}.calibration", "expected an object with retracted, extended, travel_mm")
        for k in cal:
            if k not in CALIBRATION_KEYS:
                fail(f"{where}.calibration.{k}", f"unknown key; allowed {', '.join(CALIBRATION_KEYS)}")
        for k in ("retracted", "extended"):
            v = cal.get(k)
            if not (isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 0xFFFF):
                # (the model's own range is checked where its map is known: Scale)
                fail(f"{where}.calibration.{k}", f"{v!r} is not a position in counts (0..4095 on a 12Lf, "
                                                 "0..10000 on a 17Lf)")
        if cal["retracted"] == cal["extended"]:
            fail(f"{where}.calibration", "the two ends are the same position")
        t = cal.get("travel_mm")
        if t is not None and not (_number(t) and 0 < t <= 1000):
            fail(f"{where}.calibration.travel_mm", f"{t!r} is not a length in mm (0..1000)")
    return entry


def scale_of(motion, ident=None, regmap=None) -> Scale:
    """The :class:`Scale` of a checked ``motion`` entry on a model of ``regmap`` (None: the
    12Lf's); UsageError when it gives no stroke."""
    motion = motion or {}
    stroke = motion.get("stroke_mm")
    source = ""
    if stroke is None and motion.get("part"):
        if regmap is not None and regmap.protocol == "modbus":
            raise UsageError(f"ID {ident}: part {motion['part']!r}: no {regmap.model} part's stroke is in the model "
                             "table; give stroke_mm (or calibrate) in the fleet file's motion entry", ident=ident)
        stroke = stroke_of_part(motion["part"])
        source = f"part {motion['part']} ({stroke:g} mm)"
    if stroke is None and not motion.get("calibration"):
        raise UsageError(f"ID {ident}: the fleet file gives no stroke (motion.part, motion.stroke_mm or a "
                         "calibration from zap calibrate)", ident=ident)
    return Scale(stroke, calibration=motion.get("calibration"), max_speed_mm_s=motion.get("max_speed_mm_s"),
                 ident=ident, source=source, regmap=regmap)


def scales(path, ids, regmap=None) -> dict:
    """``{ID: Scale}`` for ``ids`` from the fleet file at ``path``, on a model of ``regmap``
    (None: the 12Lf's); UsageError naming an ID the file gives no stroke for."""
    from .fleet import read_document

    entries = read_document(path)
    out = {}
    for ident in ids:
        entry = entries.get(ident)
        if entry is None or entry.motion is None:
            raise UsageError(f"{path}: ID {ident} has no motion entry (its stroke): add "
                             f"actuators.{ident}.motion.part or .stroke_mm, or run zap calibrate", ident=ident)
        out[ident] = scale_of(entry.motion, ident, regmap)
    return out


def motion_entries(path) -> dict:
    """``{ID: motion entry}`` of the fleet file at ``path``; ``{}`` when there is none or it is
    not a readable fleet file (a backup about to replace it keeps them: :func:`keep_motion`)."""
    import os

    if not path or path == "-" or not os.path.isfile(path):
        return {}
    from .fleet import read_document

    try:
        return {i: e.motion for i, e in read_document(path).items() if e.motion}
    except UsageError:
        return {}


def keep_motion(doc: dict, entries: dict) -> list:
    """Put ``entries`` ({ID: motion}) into the backup document ``doc`` for the actuators it
    holds; returns those IDs."""
    kept = []
    for ident, motion in sorted(entries.items()):
        entry = doc["actuators"].get(str(ident))
        if entry is not None:
            entry["motion"] = motion
            kept.append(ident)
    return kept


def record_motion(path, ident: int, motion: dict) -> None:
    """Merge ``motion`` into actuator ``ident``'s motion entry of the fleet file at ``path``
    (created when missing), rewritten whole and atomically."""
    import os

    from . import documents
    from .fleet import FORMAT, check_document, dump_document, format_of, now_iso

    fmt = format_of(path)
    if os.path.exists(path):
        doc, name = documents.read(path, "fleet", fmt)
        check_document(doc, name)
    else:
        doc = {"format": FORMAT, "time": now_iso(), "actuators": {}}
    entry = doc["actuators"].setdefault(str(ident), {})
    merged = dict(entry.get("motion") or {})
    merged.update(motion)
    entry["motion"] = merged
    check_document(doc, path)
    dump_document(doc, path, fmt)
