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

**Settling** is judged on rpm, EGT and thrust (the thrust TSFC uses: the ``--thrust-from``
sensor's, else the ECU's) by one criterion: the least-squares slope of the channel across the
averaging window, times the window's length, is the drift; a step whose drift exceeds the
channel's tolerance (:data:`SETTLING`: 1 % of the mean rpm; 10 °C; 2 % of the mean thrust, at
least 0.1 kgf) never settled. Standard deviations (of the samples, n - 1) stand beside the means.
An external sensor's channel that was stale for part of the window, or had values rejected in
it, leaves the step not settled too, with the reason; a window cut short by the step's end, or
one without frames, is noted.
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
#: The settling tolerance of each channel: the largest drift across the window (slope x window
#: length) of a settled step, as ``(fraction of the step's mean, floor in the channel's unit)``.
SETTLING = {"rpm": (0.01, 0.0), "egt_c": (0.0, 10.0), "thrust": (0.02, 0.1)}
#: RPM drift across the averaging window, as a fraction of the mean, above which a step has not
#: settled (:data:`SETTLING`'s rpm entry).
SETTLED_FRACTION = SETTLING["rpm"][0]
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
    """Count, mean, sample standard deviation (Welford), min, max and the least-squares slope
    over time of one quantity."""

    __slots__ = ("n", "_mean", "_m2", "min", "max", "t0", "st", "stt", "sv", "stv")

    def __init__(self):
        self.n, self._mean, self._m2, self.min, self.max = 0, 0.0, 0.0, math.inf, -math.inf
        self.t0 = None
        self.st = self.stt = self.sv = self.stv = 0.0

    def add(self, v, t=None):
        self.n += 1
        d = v - self._mean
        self._mean += d / self.n
        self._m2 += d * (v - self._mean)
        if v < self.min:
            self.min = v
        if v > self.max:
            self.max = v
        if t is not None:
            if self.t0 is None:
                self.t0 = t
            x = t - self.t0
            self.st += x
            self.stt += x * x
            self.sv += v
            self.stv += x * v

    def mean(self):
        return self._mean if self.n else None

    def std(self):
        return math.sqrt(self._m2 / (self.n - 1)) if self.n > 1 else None

    def slope(self):
        """Units per second (least squares over the times given), or None."""
        n = self.n
        den = n * self.stt - self.st * self.st
        if n < 3 or den <= 1e-12 * max(1.0, n * self.stt):
            return None
        return (n * self.stv - self.st * self.sv) / den


def _r(v, digits):
    return None if v is None else round(v, digits)


#: The standard-day columns of a step (with --ambient-temp): the ambient inputs, δ and θ, and the
#: corrected rpm N/√θ, thrust F/δ, fuel flow Wf/(δ·√θ) and TSFC from them (see api.ambient).
CORRECTED_COLUMNS = ["ambient_temp_c", "ambient_pressure_hpa", "delta", "theta", "rpm_corrected",
                     "thrust_corrected_kg", "fuel_flow_corrected_l_min", "tsfc_corrected_g_kn_s",
                     "tsfc_corrected_kg_kgf_h"]


def columns():
    """The steps CSV's columns, in order (without sensors, corrections or external channels)."""
    cols = ["step", "mode", "state", "target", "target_throttle_pct", "target_rpm", "step_start_s", "step_end_s",
            "window_start_s", "window_end_s", "frames"]
    for q in QUANTITIES:
        cols += [f"{q}_mean", f"{q}_std", f"{q}_min", f"{q}_max"]
    return cols + ["tsfc_g_kn_s", "tsfc_kg_kgf_h"] + DRIFT_COLUMNS + ["settled", "note"]


#: Each step's drift across its window (slope x length) of the channels settling is judged on.
DRIFT_COLUMNS = ["drift_rpm", "drift_egt_c", "drift_thrust_kg"]


class StepAverager:
    """Feed (t, decoded status frame); :meth:`rows` gives one row per step.

    ``steps``: ``[(number, row, t_start, t_end)]`` as :meth:`zkzap.api.schedule.Schedule.steps`
    gives them (rows in state run; ramps left out, repeated targets merged); ``t`` is the
    session's time (the schedule's clock). A row during which the engine passes through a
    starting state (ignition, preheat, fuel ramp...) is its start-up: no step (:attr:`skipped`),
    and the steps are numbered without it.

    ``thrust``/``flow`` (:class:`~zkzap.api.ambient.Quantity` of an ``--aux`` field) replace the
    ECU's coarse thrust and fuel flow in TSFC and the corrections (the ECU's columns stay);
    ``ambient`` = (temperature, pressure) Quantities (pressure None: the ECU's own air pressure,
    status ID 3) adds the standard-day corrected columns. :meth:`add_channels` adds the external
    sensors' channels (mean, std, min, max per step; staleness and rejections mark the step).
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
        self.frames = [0] * len(self.steps)
        self.startup = [False] * len(self.steps)
        self.skipped = []
        self.channels = []                 # external sensors' channels (api.sensors.Channel)
        self.chan = [{} for _ in self.steps]              # per step: name -> _Acc
        self.stale = [{} for _ in self.steps]             # per step: name -> stale seconds in the window
        self.rejected = [{} for _ in self.steps]          # per step: name -> {reason: n}
        self._last_ok = {}
        self._t_end = 0.0
        self._i = 0
        self._row = 0
        self._aux = [(k, q) for k, q in (("thrust", thrust), ("flow", flow)) if q is not None and q.field]
        if ambient is not None:
            self._aux += [(k, q) for k, q in zip(("temp", "pressure"), ambient) if q is not None and q.field]

    def add_channels(self, channels) -> None:
        """The external sensors' channels (known once the sensors sent their first readings)."""
        for c in channels:
            if all(c.name != k.name for k in self.channels):
                self.channels.append(c)

    def _window(self, t):
        i = self._i
        while i < len(self.windows) and t >= self.windows[i][1]:
            i += 1
        self._i = i
        if i < len(self.windows) and self.windows[i][0] <= t < self.windows[i][1]:
            return i
        return None

    def feed(self, t, rec):
        if t > self._t_end:
            self._t_end = t
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
        acc = self.acc[i]
        seen = False
        for q in QUANTITIES:
            v = rec.get(q)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                acc[q].add(float(v), t)
                seen = True
        if seen:
            self.frames[i] += 1
        if self.ambient is not None and self.ambient[1] is None:
            p = rec.get("pressure_pa")
            if isinstance(p, (int, float)) and not isinstance(p, bool) and p > 0:
                self.extra[i]["pressure"].add(p / 100.0, t)

    def _stale_span(self, a, b, name):
        for i, (w0, w1) in enumerate(self.windows):
            lo, hi = max(a, w0), min(b, w1)
            if hi > lo:
                self.stale[i][name] = self.stale[i].get(name, 0.0) + hi - lo

    def feed_aux(self, t, reading, rejected=None):
        """An external sensor's reading at ``t``: a :class:`~zkzap.api.aux.Reading`, or a dict of
        its valid values (with ``rejected``: ``[(channel, reason, text)]``)."""
        if isinstance(reading, dict):
            values, rejected = reading, rejected or ()
        else:
            values, rejected = reading.values, reading.rejected
        if self.channels:
            from .aux import stale_span

            stale_of = {c.name: c.stale_s for c in self.channels}
            for name in values:
                if name in stale_of:
                    span = stale_span(self._last_ok.get(name), t, stale_of[name])
                    if span is not None:
                        self._stale_span(*span, name)
                    self._last_ok[name] = max(t, self._last_ok.get(name, t))
        i = self._window(t)
        if i is None:
            return
        for name, v in values.items():
            if self.channels and isinstance(v, (int, float)) and not isinstance(v, bool):
                self.chan[i].setdefault(name, _Acc()).add(float(v), t)
        for name, why, _ in rejected:
            got = self.rejected[i].setdefault(name, {})
            got[why] = got.get(why, 0) + 1
        for key, q in self._aux:
            v = q.convert(values.get(q.field), self.density)
            if v is not None:
                self.extra[i][key].add(v, t)

    def columns(self) -> list:
        """The columns of :meth:`rows` (the steps CSV's header)."""
        cols = columns()
        k = cols.index("tsfc_g_kn_s")
        head, tsfc_cols, tail = cols[:k], cols[k:k + 2], cols[k + 2:]
        for c in self.channels:
            head += [f"{c.name}_mean", f"{c.name}_std", f"{c.name}_min", f"{c.name}_max"]
        if self.thrust is not None:
            head += ["thrust_from", "thrust_from_kg_mean", "thrust_from_kg_std", "thrust_from_kg_min",
                     "thrust_from_kg_max"]
        if self.flow is not None:
            head += ["fuel_flow_from", "fuel_flow_from_l_min_mean", "fuel_flow_from_l_min_std",
                     "fuel_flow_from_l_min_min", "fuel_flow_from_l_min_max"]
        head += tsfc_cols
        if self.ambient is not None:
            head += CORRECTED_COLUMNS
        return head + tail

    def rows(self) -> list:
        out = []
        self.skipped = []
        if self.channels:                  # stale up to the end of what was fed
            from .aux import stale_span

            for c in self.channels:
                span = stale_span(self._last_ok.get(c.name), self._t_end, c.stale_s)
                if span is not None:
                    self._stale_span(*span, c.name)
                    self._last_ok[c.name] = self._t_end + 1e9      # counted once
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
            _stats(r, q, acc[q], 3)
        for c in self.channels:
            _stats(r, c.name, self.chan[i].get(c.name) or _Acc(), 4)
        thrust, flow = r["thrust_kg_mean"], r["fuel_flow_l_min_mean"]
        thrust_acc = acc["thrust_kg"]
        for key, q, name, col in (("thrust", self.thrust, "thrust_from", "thrust_from_kg"),
                                  ("flow", self.flow, "fuel_flow_from", "fuel_flow_from_l_min")):
            if q is None:
                continue
            r[name] = q.field
            _stats(r, col, extra[key], 4)
            if key == "thrust":
                thrust, thrust_acc = r[f"{col}_mean"], extra[key]
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
        drifts = {"rpm": _drift(acc["rpm"], w1 - w0), "egt_c": _drift(acc["egt_c"], w1 - w0),
                  "thrust": _drift(thrust_acc, w1 - w0)}
        r["drift_rpm"], r["drift_egt_c"], r["drift_thrust_kg"] = (_r(drifts["rpm"], 1), _r(drifts["egt_c"], 2),
                                                                   _r(drifts["thrust"], 4))
        moving = []
        if self.frames[i] == 0:
            settled = None
            if w1 > w0:
                notes.insert(0, "no frames in the window")
        else:
            for name, label, unit, mean in (("rpm", "rpm", "rpm", acc["rpm"].mean()),
                                            ("egt_c", "EGT", "°C", acc["egt_c"].mean()),
                                            ("thrust", "thrust", "kgf", thrust_acc.mean())):
                d = drifts[name]
                if d is None or mean is None:
                    continue
                frac, floor = SETTLING[name]
                tol = max(frac * abs(mean), floor)
                if abs(d) > tol:
                    relative = frac and frac * abs(mean) >= floor        # the tolerance is the fraction
                    how = f"{abs(d) / abs(mean) * 100:.2f} %" if relative else f"{abs(d):.{2 if floor < 1 else 1}f} {unit}"
                    lim = f"{frac * 100:g} %" if relative else f"{tol:g} {unit}"
                    moving.append(f"{label} drifted {'+' if d > 0 else '-'}{how} across the window (more than {lim})")
        if moving:
            settled = False
            notes.insert(0, "never settled: " + ", ".join(moving))
        sensor_notes = []
        for c in self.channels:
            stale = self.stale[i].get(c.name, 0.0)
            if stale > 1e-6 and w1 > w0:
                sensor_notes.append(f"{c.name} stale {stale:.1f} s of the window (nothing valid for more than "
                                    f"{c.stale_s:g} s)")
            bad = self.rejected[i].get(c.name)
            if bad:
                sensor_notes.append(f"{c.name}: {sum(bad.values())} value{'s' if sum(bad.values()) > 1 else ''} "
                                    f"rejected in the window ({', '.join(sorted(bad))})")
        if sensor_notes:
            if settled is not None:
                settled = False
            notes += sensor_notes
        for key, q in (("thrust", self.thrust), ("flow", self.flow)):
            if q is not None and extra[key].n == 0 and w1 > w0:
                notes.append(f"no valid {q.field} in the window: no TSFC from it")
                if settled is not None:
                    settled = False
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


def _stats(r, name, acc, digits):
    m = acc.mean()
    r[f"{name}_mean"] = _r(m, digits)
    r[f"{name}_std"] = _r(acc.std(), digits)
    r[f"{name}_min"] = None if m is None else round(acc.min, digits)
    r[f"{name}_max"] = None if m is None else round(acc.max, digits)


def _drift(acc, length):
    """The change across a window of ``length`` s that the slope of ``acc`` gives, or None."""
    slope = acc.slope()
    return None if slope is None or length <= 0 else slope * length
