"""Steady-state reduction of a test-stand run: one averaged row per schedule step.

For each step (a schedule row that holds for some time), the first ``settle`` seconds are let
pass and the next ``average`` seconds (cut at the step's end; None: up to the step's end) are
averaged: mean, min and max of each quantity in :data:`QUANTITIES`, over the status frames that carry it in that window.
Derived per step: thrust-specific fuel consumption, fuel mass flow over thrust, from the mean
fuel flow (L/min), the fuel density (kg/L) and the mean thrust (kgf):

- ``tsfc_g_kn_s``   g/(kN*s)   = (flow * density / 60 * 1000) / (thrust * 9.80665 / 1000)
- ``tsfc_kg_kgf_h`` kg/(kgf*h) = flow * density * 60 / thrust

(None where the mean thrust is not above zero.) Fuel densities at 15 °C: Jet A-1 0.8 kg/L (the
default; 0.775..0.840 by specification), kerosene 0.80, diesel 0.83..0.85.

A step *never settled* when its RPM was still moving during the window: the means of the first
and the second half of the window differ by more than :data:`SETTLED_FRACTION` (1 %) of the
step's mean RPM. A window cut short by the step's end, or one without frames, is noted too.
"""

from __future__ import annotations

import math

#: Quantities averaged per step (status keys).
QUANTITIES = ("rpm", "egt_c", "thrust_kg", "fuel_flow_l_min", "pump_voltage_v", "throttle_pct")
#: Default fuel density (Jet A-1 at 15 °C), kg/L.
DEFAULT_DENSITY = 0.8
#: Documented densities (kg/L at 15 °C) for the help text and the manual.
DENSITIES = {"Jet A-1": 0.8, "kerosene": 0.80, "diesel": 0.84}
#: RPM change between the halves of the averaging window, as a fraction of the mean, above which
#: a step has not settled.
SETTLED_FRACTION = 0.01
G0 = 9.80665


def tsfc(flow_l_min, thrust_kg, density):
    """(g/(kN*s), kg/(kgf*h)) for a fuel flow in L/min and a thrust in kgf; (None, None) when the
    thrust is not positive or a value is missing."""
    if flow_l_min is None or thrust_kg is None or thrust_kg <= 0:
        return None, None
    mass_kg_s = flow_l_min * density / 60.0
    g_kn_s = mass_kg_s * 1000.0 / (thrust_kg * G0 / 1000.0)
    kg_kgf_h = mass_kg_s * 3600.0 / thrust_kg
    return round(g_kn_s, 2), round(kg_kgf_h, 4)


class _Acc:
    __slots__ = ("n", "sum", "min", "max")

    def __init__(self):
        self.n, self.sum, self.min, self.max = 0, 0.0, math.inf, -math.inf

    def add(self, v):
        self.n += 1
        self.sum += v
        if v < self.min:
            self.min = v
        if v > self.max:
            self.max = v

    def mean(self):
        return self.sum / self.n if self.n else None


def columns():
    """The steps CSV's columns, in order."""
    cols = ["step", "mode", "state", "target", "target_throttle_pct", "target_rpm", "step_start_s", "step_end_s",
            "window_start_s", "window_end_s", "frames"]
    for q in QUANTITIES:
        cols += [f"{q}_mean", f"{q}_min", f"{q}_max"]
    return cols + ["tsfc_g_kn_s", "tsfc_kg_kgf_h", "settled", "note"]


class StepAverager:
    """Feed (t, decoded status frame); :meth:`rows` gives one row per step.

    ``steps``: ``[(number, row, t_start, t_end)]`` as :meth:`zkzap.api.schedule.Schedule.steps`
    gives them; ``t`` is the session's time (the schedule's clock).
    """

    def __init__(self, steps, settle, average, density=DEFAULT_DENSITY):
        self.steps = list(steps)
        self.settle = settle
        self.average = average
        self.density = density
        self.windows = []
        for n, row, a, b in self.steps:
            w0 = min(a + settle, b)
            w1 = b if average is None else min(w0 + average, b)
            self.windows.append((w0, w1))
        self.acc = [{q: _Acc() for q in QUANTITIES} for _ in self.steps]
        self.halves = [(_Acc(), _Acc()) for _ in self.steps]
        self.frames = [0] * len(self.steps)
        self._i = 0

    def feed(self, t, rec):
        i = self._i
        while i < len(self.windows) and t >= self.windows[i][1]:
            i += 1
        self._i = i
        if i >= len(self.windows):
            return
        w0, w1 = self.windows[i]
        if not w0 <= t < w1:
            return
        acc = self.acc[i]
        seen = False
        for q in QUANTITIES:
            v = rec.get(q)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                acc[q].add(float(v))
                seen = True
                if q == "rpm":
                    self.halves[i][0 if t < (w0 + w1) / 2 else 1].add(float(v))
        if seen:
            self.frames[i] += 1

    def rows(self) -> list:
        out = []
        for i, (n, row, a, b) in enumerate(self.steps):
            w0, w1 = self.windows[i]
            acc = self.acc[i]
            r = {"step": n, "mode": row.mode, "state": row.state, "target": row.target_text(),
                 "target_throttle_pct": row.throttle, "target_rpm": row.rpm,
                 "step_start_s": round(a, 3), "step_end_s": round(b, 3),
                 "window_start_s": round(w0, 3), "window_end_s": round(w1, 3), "frames": self.frames[i]}
            for q in QUANTITIES:
                m = acc[q].mean()
                r[f"{q}_mean"] = None if m is None else round(m, 3)
                r[f"{q}_min"] = None if m is None else acc[q].min
                r[f"{q}_max"] = None if m is None else acc[q].max
            r["tsfc_g_kn_s"], r["tsfc_kg_kgf_h"] = tsfc(r["fuel_flow_l_min_mean"], r["thrust_kg_mean"],
                                                        self.density)
            notes = []
            settled = True
            if w1 <= w0:
                notes.append(f"step shorter than the settle time ({self.settle:g} s)")
            elif self.average is not None and w1 - w0 < self.average - 1e-9:
                notes.append(f"window cut to {w1 - w0:g} s by the step's end")
            if self.frames[i] == 0:
                settled = None
                if w1 > w0:
                    notes.append("no frames in the window")
            else:
                h1, h2 = self.halves[i]
                mean = acc["rpm"].mean()
                if h1.n and h2.n and mean:
                    drift = abs(h2.mean() - h1.mean()) / mean
                    if drift > SETTLED_FRACTION:
                        settled = False
                        notes.append(f"never settled: rpm changed {drift * 100:.1f} % across the window "
                                     f"(more than {SETTLED_FRACTION * 100:g} %)")
            r["settled"] = settled
            r["note"] = "; ".join(notes)
            out.append(r)
        return out
