"""Steady-state reduction of a test-stand run: one averaged row per schedule step.

A step is a schedule row in state ``run`` that holds for some time; standby, stop and pwm rows
are not steps, nor is the start-up: the row during which the engine passes through a starting
state. For each step the first ``settle`` seconds are let
pass and the next ``average`` seconds (cut at the step's end; None: up to the step's end) are
averaged: mean, min and max of each quantity in :data:`QUANTITIES`, over the status frames that carry it in that window.
Derived per step: thrust-specific fuel consumption, fuel mass flow over thrust, from the mean
fuel flow (L/min), the fuel density (kg/L) and the mean thrust (kgf):

- ``tsfc_g_kn_s``   g/(kN*s)   = (flow * density / 60 * 1000) / (thrust * 9.80665 / 1000)
- ``tsfc_kg_kgf_h`` kg/(kgf*h) = flow * density * 60 / thrust

(None where the mean thrust is not above zero.) Fuel densities at 15 °C: Jet A-1 0.8 kg/L (the
default; 0.775..0.840 by specification), kerosene 0.80, diesel 0.83..0.85.

With ``--ambient-temp`` each step also gets the standard-day corrected rpm, thrust, fuel flow
and TSFC (:mod:`zkzap.api.ambient`); with ``--thrust-from``/``--fuel-flow-from`` TSFC and the
corrections use an external sensor's means instead of the ECU's coarse values.

A step *never settled* when its RPM was still moving during the window: the means of the first
and the second half of the window differ by more than :data:`SETTLED_FRACTION` (1 %) of the
step's mean RPM. A window cut short by the step's end, or one without frames, is noted too.
"""

from __future__ import annotations

import math

from .logbook import STARTING_STATES

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


#: The standard-day columns of a step (with --ambient-temp): the ambient inputs, δ and θ, and the
#: corrected rpm N/√θ, thrust F/δ, fuel flow Wf/(δ·√θ) and TSFC from them (see api.ambient).
CORRECTED_COLUMNS = ["ambient_temp_c", "ambient_pressure_hpa", "delta", "theta", "rpm_corrected",
                     "thrust_corrected_kg", "fuel_flow_corrected_l_min", "tsfc_corrected_g_kn_s",
                     "tsfc_corrected_kg_kgf_h"]


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
    gives them (rows in state run); ``t`` is the session's time (the schedule's clock). A row
    during which the engine passes through a starting state (ignition, preheat, fuel ramp...) is
    its start-up: no step (:attr:`skipped`), and the steps are numbered without it.

    ``thrust``/``flow`` (:class:`~zkzap.api.ambient.Quantity` of an ``--aux`` field) replace the
    ECU's coarse thrust and fuel flow in TSFC and the corrections (the ECU's columns stay);
    ``ambient`` = (temperature, pressure) Quantities (pressure None: the ECU's own air pressure,
    status ID 3) adds the standard-day corrected columns.
    """

    def __init__(self, steps, settle, average, density=DEFAULT_DENSITY, *, thrust=None, flow=None, ambient=None):
        self.steps = list(steps)
        self.settle = settle
        self.average = average
        self.density = density
        self.thrust, self.flow, self.ambient = thrust, flow, ambient
        self.windows = []
        for n, row, a, b in self.steps:
            w0 = min(a + settle, b)
            w1 = b if average is None else min(w0 + average, b)
            self.windows.append((w0, w1))
        self.acc = [{q: _Acc() for q in QUANTITIES} for _ in self.steps]
        self.extra = [{k: _Acc() for k in ("thrust", "flow", "temp", "pressure")} for _ in self.steps]
        self.halves = [(_Acc(), _Acc()) for _ in self.steps]
        self.frames = [0] * len(self.steps)
        self.startup = [False] * len(self.steps)
        self.skipped = []
        self._i = 0
        self._row = 0
        self._aux = [(k, q) for k, q in (("thrust", thrust), ("flow", flow)) if q is not None and q.field]
        if ambient is not None:
            self._aux += [(k, q) for k, q in zip(("temp", "pressure"), ambient) if q is not None and q.field]

    def _window(self, t):
        i = self._i
        while i < len(self.windows) and t >= self.windows[i][1]:
            i += 1
        self._i = i
        if i < len(self.windows) and self.windows[i][0] <= t < self.windows[i][1]:
            return i
        return None

    def feed(self, t, rec):
        if rec.get("id") == 1 and rec.get("engine_state_name") in STARTING_STATES:
            r = self._row
            while r < len(self.steps) and t >= self.steps[r][3]:
                r += 1
            self._row = r
            if r < len(self.steps) and self.steps[r][2] <= t:
                self.startup[r] = True
        i = self._window(t)
        if i is None:
            return
        w0, w1 = self.windows[i]
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
        if self.ambient is not None and self.ambient[1] is None:
            p = rec.get("pressure_pa")
            if isinstance(p, (int, float)) and not isinstance(p, bool) and p > 0:
                self.extra[i]["pressure"].add(p / 100.0)

    def feed_aux(self, t, reading):
        """An external sensor's reading (its fields as the sensor named them) at ``t``."""
        if not self._aux:
            return
        i = self._window(t)
        if i is None:
            return
        for key, q in self._aux:
            v = q.convert(reading.get(q.field), self.density)
            if v is not None:
                self.extra[i][key].add(v)

    def columns(self) -> list:
        """The columns of :meth:`rows` (the steps CSV's header)."""
        cols = columns()
        head, tsfc_cols, tail = cols[:-4], cols[-4:-2], cols[-2:]
        if self.thrust is not None:
            head += ["thrust_from", "thrust_from_kg_mean", "thrust_from_kg_min", "thrust_from_kg_max"]
        if self.flow is not None:
            head += ["fuel_flow_from", "fuel_flow_from_l_min_mean", "fuel_flow_from_l_min_min",
                     "fuel_flow_from_l_min_max"]
        head += tsfc_cols
        if self.ambient is not None:
            head += CORRECTED_COLUMNS
        return head + tail

    def rows(self) -> list:
        out = []
        self.skipped = []
        for i, (n, row, a, b) in enumerate(self.steps):
            if self.startup[i]:
                self.skipped.append((row, a, b, "start-up"))
                continue
            out.append(self._row_of(i, len(out) + 1, row, a, b))
        return out

    def _row_of(self, i, n, row, a, b):
        w0, w1 = self.windows[i]
        acc, extra = self.acc[i], self.extra[i]
        r = {"step": n, "mode": row.mode, "state": row.state, "target": row.target_text(),
             "target_throttle_pct": row.throttle, "target_rpm": row.rpm,
             "step_start_s": round(a, 3), "step_end_s": round(b, 3),
             "window_start_s": round(w0, 3), "window_end_s": round(w1, 3), "frames": self.frames[i]}
        for q in QUANTITIES:
            m = acc[q].mean()
            r[f"{q}_mean"] = None if m is None else round(m, 3)
            r[f"{q}_min"] = None if m is None else acc[q].min
            r[f"{q}_max"] = None if m is None else acc[q].max
        thrust, flow = r["thrust_kg_mean"], r["fuel_flow_l_min_mean"]
        for key, q, name, col in (("thrust", self.thrust, "thrust_from", "thrust_from_kg"),
                                  ("flow", self.flow, "fuel_flow_from", "fuel_flow_from_l_min")):
            if q is None:
                continue
            m = extra[key].mean()
            r[name] = q.field
            r[f"{col}_mean"] = None if m is None else round(m, 4)
            r[f"{col}_min"] = None if m is None else round(extra[key].min, 4)
            r[f"{col}_max"] = None if m is None else round(extra[key].max, 4)
            if key == "thrust":
                thrust = r[f"{col}_mean"]
            else:
                flow = r[f"{col}_mean"]
        r["tsfc_g_kn_s"], r["tsfc_kg_kgf_h"] = tsfc(flow, thrust, self.density)
        notes = []
        if self.ambient is not None:
            got = self._corrected(r, i, thrust, flow)
            if self.frames[i]:
                notes += got
        settled = True
        if w1 <= w0:
            notes.insert(0, f"step shorter than the settle time ({self.settle:g} s)")
        elif self.average is not None and w1 - w0 < self.average - 1e-9:
            notes.insert(0, f"window cut to {w1 - w0:g} s by the step's end")
        if self.frames[i] == 0:
            settled = None
            if w1 > w0:
                notes.insert(0, "no frames in the window")
        else:
            h1, h2 = self.halves[i]
            mean = acc["rpm"].mean()
            if h1.n and h2.n and mean:
                drift = abs(h2.mean() - h1.mean()) / mean
                if drift > SETTLED_FRACTION:
                    settled = False
                    notes.insert(0, f"never settled: rpm changed {drift * 100:.1f} % across the window "
                                    f"(more than {SETTLED_FRACTION * 100:g} %)")
        r["settled"] = settled
        r["note"] = "; ".join(notes)
        return r

    def _corrected(self, r, i, thrust, flow):
        from .ambient import corrected, delta, theta

        temp_q, press_q = self.ambient
        extra = self.extra[i]
        t_c = temp_q.value if temp_q.field is None else extra["temp"].mean()
        if press_q is not None and press_q.field is None:
            p = press_q.value
        else:
            p = extra["pressure"].mean()
        r["ambient_temp_c"] = None if t_c is None else round(t_c, 2)
        r["ambient_pressure_hpa"] = None if p is None else round(p, 2)
        r["delta"] = None if not p else round(delta(p), 5)
        r["theta"] = None if t_c is None else round(theta(t_c), 5)
        c = corrected(p, t_c, thrust=thrust, rpm=r["rpm_mean"], flow=flow)
        r["rpm_corrected"] = None if c["rpm"] is None else round(c["rpm"], 1)
        r["thrust_corrected_kg"] = None if c["thrust"] is None else round(c["thrust"], 4)
        r["fuel_flow_corrected_l_min"] = None if c["flow"] is None else round(c["flow"], 4)
        r["tsfc_corrected_g_kn_s"], r["tsfc_corrected_kg_kgf_h"] = tsfc(c["flow"], c["thrust"], self.density)
        notes = []
        if p is None:
            notes.append("no air pressure in the window: not corrected")
        if t_c is None:
            notes.append("no ambient temperature in the window: not corrected")
        return notes
