"""Standard-day corrections and the quantities a test stand measures beside the ECU.

Gas-turbine performance is compared at standard sea-level conditions (ISA: 1013.25 hPa,
15 °C) through the quasi-dimensionless ("referred" or "corrected") parameter groups of
gas-turbine practice (Walsh & Fletcher, *Gas Turbine Performance*, chapter 4; the same δ, θ and
corrected net thrust Fn/δ are defined in ECAC Doc 29 and Directive (EU) 2015/996, Annex,
Appendix B):

- delta ``δ = p / 1013.25 hPa`` (ambient pressure ratio), theta ``θ = T / 288.15 K``
  (ambient temperature ratio, T in kelvin);
- corrected thrust ``F / δ``, corrected speed ``N / √θ``, corrected fuel flow
  ``Wf / (δ·√θ)``; the corrected TSFC follows from the corrected flow and thrust, which is
  ``TSFC / √θ``.

The ambient temperature is never reported by the ECU (its status ID 9 is the board's own
temperature): it is a number the user gives, or a field of an external sensor. The pressure is a
number, a sensor field, or by default the ECU's own air pressure (status ID 3).

:class:`Quantity` is one such input: a constant (``15``) or a field of an external sensor with
its unit (``baro_pa:Pa``, ``load:N``), converted to the unit zkzap works in (kgf, L/min, hPa,
°C).
"""

from __future__ import annotations

import math
import re

from ..errors import UsageError

#: ISA sea-level pressure (hPa) and temperature (K).
P0_HPA = 1013.25
T0_K = 288.15
KELVIN = 273.15
G0 = 9.80665

#: Units by quantity: name -> (factor to the working unit, offset added after); mass flows
#: (``kg/h``, ``g/min``, ``g/s``) need the fuel density (handled by :meth:`Quantity.convert`).
UNITS = {
    "thrust": ("kgf", {"kgf": 1.0, "kg": 1.0, "n": 1.0 / G0, "dan": 10.0 / G0, "lbf": 0.45359237, "g": 0.001}),
    "fuel_flow": ("L/min", {"l/min": 1.0, "ml/min": 0.001, "cc/min": 0.001, "l/h": 1.0 / 60.0,
                            "kg/h": None, "g/min": None, "g/s": None}),
    "pressure": ("hPa", {"hpa": 1.0, "mbar": 1.0, "pa": 0.01, "kpa": 10.0, "bar": 1000.0, "psi": 68.9475729,
                         "inhg": 33.8638866}),
    "temperature": ("°C", {"c": 1.0, "degc": 1.0, "°c": 1.0, "k": 1.0, "f": 5.0 / 9.0}),
}
#: Mass-flow units: kg per minute per unit.
_MASS_FLOW = {"kg/h": 1.0 / 60.0, "g/min": 0.001, "g/s": 0.06}
#: Units implied by a field name's ending, when ``FIELD`` is given without ``:UNIT``.
_BY_SUFFIX = {
    "thrust": (("_kgf", "kgf"), ("_kg", "kg"), ("_n", "n"), ("_lbf", "lbf"), ("_dan", "dan"), ("_g", "g")),
    "fuel_flow": (("_l_min", "l/min"), ("_ml_min", "ml/min"), ("_l_h", "l/h"), ("_kg_h", "kg/h"),
                  ("_g_min", "g/min"), ("_g_s", "g/s")),
    "pressure": (("_hpa", "hpa"), ("_mbar", "mbar"), ("_kpa", "kpa"), ("_pa", "pa"), ("_psi", "psi")),
    "temperature": (("_c", "c"), ("_k", "k"), ("_f", "f")),
}
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")


def delta(p_hpa):
    """δ = p / 1013.25 hPa."""
    return p_hpa / P0_HPA


def theta(t_c):
    """θ = T / 288.15 K, T in kelvin (t_c in °C)."""
    return (t_c + KELVIN) / T0_K


def corrected(p_hpa, t_c, *, thrust=None, rpm=None, flow=None) -> dict:
    """The corrected values of whatever is given (None where a value or an ambient input is
    missing): ``thrust`` (F/δ), ``rpm`` (N/√θ), ``flow`` (Wf/(δ·√θ))."""
    d = delta(p_hpa) if p_hpa is not None and p_hpa > 0 else None
    s = math.sqrt(theta(t_c)) if t_c is not None and theta(t_c) > 0 else None
    return {
        "thrust": thrust / d if thrust is not None and d else None,
        "rpm": rpm / s if rpm is not None and s else None,
        "flow": flow / (d * s) if flow is not None and d and s else None,
    }


class Quantity:
    """A constant or an external sensor's field, in the working unit of ``kind`` (thrust kgf,
    fuel_flow L/min, pressure hPa, temperature °C). ``field`` is None for a constant."""

    def __init__(self, kind, value=None, field=None, unit=None, option=""):
        self.kind, self.value, self.field, self.unit, self.option = kind, value, field, unit, option

    @classmethod
    def parse(cls, text, kind, option, *, constant=True, declared=None):
        """``NUMBER`` (in the working unit; when ``constant``) or ``FIELD[:UNIT]``: an external
        sensor's field (``--aux``), its unit given, declared with the sensor (``declared``: field ->
        unit) or implied by the name's ending (``load_n``: N)."""
        text = str(text).strip()
        work, units = UNITS[kind]
        try:
            number = float(text)
        except ValueError:
            number = None
        if number is not None:
            if not constant:
                raise UsageError(f"{option}: {text!r}: give the field of an --aux sensor (FIELD or FIELD:UNIT)")
            if not math.isfinite(number):
                raise UsageError(f"{option}: {text!r} is not a finite number")
            return cls(kind, value=number, unit=work.lower(), option=option)
        field, sep, unit = text.partition(":")
        field = field.strip()
        if not _NAME.match(field):
            what = "a number or " if constant else ""
            raise UsageError(f"{option}: {text!r}: expected {what}FIELD[:UNIT], FIELD a field of an --aux sensor")
        unit = unit.strip().lower()
        allowed = ", ".join(u for u in units if u)
        given = (declared or {}).get(field)
        if not sep and given:
            unit, sep = given.strip().lower(), ":"
            if unit not in units:
                raise UsageError(f"{option}: {field} is declared in {given}; a {kind.replace('_', ' ')} is in one "
                                 f"of {allowed}")
        if not sep:
            unit = next((u for tail, u in _BY_SUFFIX[kind] if field.lower().endswith(tail)), None)
            if unit is None:
                raise UsageError(f"{option}: {field}: which unit? write {field}:UNIT with UNIT one of {allowed} "
                                 f"(or name the field with its unit, like {field}{_BY_SUFFIX[kind][0][0]})")
        if unit not in units:
            raise UsageError(f"{option}: {text!r}: unit {unit!r}; allowed {allowed}")
        return cls(kind, field=field, unit=unit, option=option)

    def convert(self, raw, density=None):
        """A raw value (the constant's, or the field's as the sensor sent it) in the working unit."""
        if raw is None or isinstance(raw, bool) or not isinstance(raw, (int, float)) or not math.isfinite(raw):
            return None
        unit = self.unit
        if self.kind == "temperature":
            if unit == "k":
                return raw - KELVIN
            if unit == "f":
                return (raw - 32.0) * 5.0 / 9.0
            return float(raw)
        if unit in _MASS_FLOW:
            if not density:
                return None
            return raw * _MASS_FLOW[unit] / density
        return raw * UNITS[self.kind][1][unit]

    def describe(self) -> str:
        work = UNITS[self.kind][0]
        if self.field is None:
            return f"--{self.option}" if self.option else f"{self.value:g} {work}"
        return f"--aux field {self.field} ({self.unit})"


class RecordCorrections:
    """The corrected values a record carries (``--ambient-temp`` on a session): the latest rpm,
    thrust and fuel flow (the ECU's, or an ``--aux`` field's) over the latest ambient inputs."""

    KEYS = ("rpm_corrected", "thrust_corrected_kg", "fuel_flow_corrected_l_min")

    def __init__(self, temperature, pressure=None, thrust=None, flow=None, density=0.8):
        self.temperature, self.pressure, self.thrust, self.flow = temperature, pressure, thrust, flow
        self.density = density
        self.latest = {"rpm": None, "thrust": None, "flow": None, "p": None}

    def _input(self, q, aux, now):
        if q is None:
            return None
        if q.field is None:
            return q.value
        return q.convert(aux(q.field, now) if aux is not None else None, self.density)

    def record(self, t, rec, aux=None) -> dict:
        """The record's corrected fields after status frame ``rec`` at ``t``; ``aux(field, t)``
        gives an external sensor's fresh value."""
        latest = self.latest
        if isinstance(rec.get("rpm"), (int, float)):
            latest["rpm"] = rec["rpm"]
        if self.thrust is None and rec.get("id") == 4:
            latest["thrust"] = rec.get("thrust_kg")
        if self.flow is None and rec.get("id") == 7:
            latest["flow"] = rec.get("fuel_flow_l_min")
        if self.pressure is None and rec.get("id") == 3 and rec.get("pressure_pa"):
            latest["p"] = rec["pressure_pa"] / 100.0
        thrust = latest["thrust"] if self.thrust is None else self._input(self.thrust, aux, t)
        flow = latest["flow"] if self.flow is None else self._input(self.flow, aux, t)
        p = latest["p"] if self.pressure is None else self._input(self.pressure, aux, t)
        c = corrected(p, self._input(self.temperature, aux, t), thrust=thrust, rpm=latest["rpm"], flow=flow)
        return {"rpm_corrected": None if c["rpm"] is None else round(c["rpm"], 1),
                "thrust_corrected_kg": None if c["thrust"] is None else round(c["thrust"], 4),
                "fuel_flow_corrected_l_min": None if c["flow"] is None else round(c["flow"], 4)}
