"""ZK telemetry as MAVLink (the optional ``mavlink`` extra: pymavlink), for QGroundControl,
Mission Planner and autopilots that show an engine through EFI_STATUS.

The bridge is a MAVLink component of its own (``--sysid``, default 1, the aircraft's system, so
a ground station shows the engine with the vehicle; ``--compid``, default 158
MAV_COMP_ID_PERIPHERAL). Its thread sends, on its own clock:

- HEARTBEAT at 1 Hz: type MAV_TYPE_GENERIC, autopilot MAV_AUTOPILOT_INVALID (a component, not
  a vehicle), system status ACTIVE while the engine runs, CRITICAL with an ECU error, STANDBY
  otherwise;
- EFI_STATUS at ``--mavlink-rate`` (default 10 Hz) with every ZK field MAVLink has a place for,
  in MAVLink's units (:data:`EFI_FIELDS`); fields the ZK protocol has no value for are 0, a ZK
  field not seen yet (or absent in the ECU's protocol version) is NaN;
- NAMED_VALUE_FLOAT for the other numeric fields (:func:`named_values`): thrust, engine state,
  pump voltage and ECU temperature at the EFI rate, the rest once a second;
- STATUSTEXT on engine state changes (INFO), a new ECU error (CRITICAL), an error cleared
  (NOTICE), and when status frames stop arriving for a second (WARNING) or come back (NOTICE).

Any pymavlink connection string is a destination: ``udpout:HOST:PORT``, ``udpin:HOST:PORT``
(sends to whoever sent to it), ``tcp:HOST:PORT``, ``tcpin:``, a serial device
(``/dev/ttyUSB1,57600``) for a telemetry radio. MAVLink 2 framing (EFI_STATUS's ignition
voltage is an extension field).
"""

from __future__ import annotations

import math
import os
import time

from ...codec import zk
from ...errors import PortError
from . import Bridge

EXTRA = "mavlink"
DEFAULT_RATE = 10.0
DEFAULT_SYSID = 1
DEFAULT_COMPID = 158          # MAV_COMP_ID_PERIPHERAL
#: Seconds without a status record before health goes to 0 and a warning is sent.
SILENT_S = 1.0

#: EFI_STATUS field <- (ZK key, factor to MAVLink's unit, MAVLink unit). ``health`` and
#: ``ecu_index`` are set apart (the ECU's error state, ``--ecu-index``).
EFI_FIELDS = {
    "rpm": ("rpm", 1, "rpm"),
    "fuel_consumed": ("fuel_used_l", 1000, "cm^3"),
    "fuel_flow": ("fuel_flow_l_min", 1000, "cm^3/min"),
    "throttle_position": ("throttle_pct", 1, "%"),
    "barometric_pressure": ("pressure_pa", 0.001, "kPa"),
    "exhaust_gas_temperature": ("egt_c", 1, "degC"),
    "ignition_voltage": ("ignition_pump_voltage_v", 1, "V"),
}
#: EFI_STATUS fields the ZK protocol has no value for (sent as 0).
EFI_UNUSED = ("engine_load", "spark_dwell_time", "intake_manifold_pressure", "intake_manifold_temperature",
              "cylinder_head_temperature", "ignition_timing", "injection_time", "throttle_out",
              "pt_compensation", "fuel_pressure")
#: NAMED_VALUE_FLOAT names (at most 10 characters) of the ZK keys not in EFI_STATUS; a key not
#: listed here uses its first 10 characters.
SHORT_NAMES = {
    "thrust_kg": "thrust_kg", "engine_state": "eng_state", "pump_voltage_v": "pump_v", "ecu_temp_c": "ecu_temp",
    "error_code": "ecu_error", "sw_state": "sw_state", "radio_voltage_v": "radio_v", "power_voltage_v": "power_v",
    "current_a": "current_a", "curve_inc": "curve_inc", "curve_dec": "curve_dec", "max_rpm": "max_rpm",
    "max_pump_voltage_v": "max_pump_v", "protocol_version": "proto_ver", "status_rate_hz": "rate_hz",
    "idle_rpm": "idle_rpm", "esr": "esr", "scl": "scl", "startup_time_s": "start_s", "prop_rpm": "prop_rpm",
    "fuel_pump_rpm": "fpump_rpm",
}
#: Sent with every EFI_STATUS; the other named values go once a second.
FAST_NAMED = ("thrust_kg", "engine_state", "pump_voltage_v", "ecu_temp_c")

_EFI_KEYS = {zk_key for zk_key, _, _ in EFI_FIELDS.values()}


def named_values() -> dict:
    """ZK key -> NAMED_VALUE_FLOAT name, for every numeric status field EFI_STATUS lacks (from the
    protocol table, so a new field is never left out)."""
    out = {}
    for s in zk.STATUS:
        name_keys = {f.name_key for f in s.layout.fields if f.name_key}
        for key in s.layout.keys():
            if key in _EFI_KEYS or key in name_keys or key in out:
                continue
            out[key] = SHORT_NAMES.get(key, key[:10])
    return out


def _num(v):
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


class MavlinkBridge(Bridge):
    name = "mavlink"

    def __init__(self, url, *, rate=DEFAULT_RATE, sysid=DEFAULT_SYSID, compid=DEFAULT_COMPID, ecu_index=0,
                 clock=time.monotonic):
        super().__init__()
        self.url = url
        self.rate = rate
        self.sysid = sysid
        self.compid = compid
        self.ecu_index = ecu_index
        self.clock = clock
        self.conn = None
        self.latest = {}
        self.sent = {"HEARTBEAT": 0, "EFI_STATUS": 0, "NAMED_VALUE_FLOAT": 0, "STATUSTEXT": 0}
        self.send_errors = 0
        self._named = named_values()
        self._state = None
        self._error = None
        self._last_rec = None
        self._arrived = None          # when the last status record was submitted (the session's side)
        self._silent = False
        self._due = None              # when the next HEARTBEAT, EFI_STATUS and slow named values are due
        self._t0 = clock()

    def connect(self):
        os.environ.setdefault("MAVLINK20", "1")
        # only the common dialect (EFI_STATUS is there): mavutil loads every dialect by default
        os.environ.setdefault("MAVLINK_DIALECT", "common")
        from pymavlink import mavutil

        try:
            self.conn = mavutil.mavlink_connection(self.url, source_system=self.sysid, source_component=self.compid,
                                                   dialect="common", autoreconnect=True, retries=0)
        except (OSError, ValueError) as e:
            raise PortError(f"mavlink: cannot open {self.url}: {getattr(e, 'strerror', None) or e}") from None
        self.mav = self.conn.mav
        self.m = mavutil.mavlink

    def disconnect(self):
        if self.conn is not None:
            try:
                self.conn.close()
            except OSError:
                pass
            self.conn = None

    # records in
    def submit(self, rec) -> None:
        if rec.get("kind", "status") == "status":
            self._arrived = self.clock()   # silence counts from here, not from when the thread took it
        super().submit(rec)

    def absorb(self, rec):
        """Take a record's values; changes of engine state and ECU error become STATUSTEXT."""
        if rec.get("kind", "status") != "status":
            return
        self._last_rec = self.clock()
        if self._silent:
            self._silent = False
            self._text(self.m.MAV_SEVERITY_NOTICE, "ZK ECU: status frames again")
        latest = self.latest
        for k, v in rec.items():
            latest[k] = v
        name = rec.get("engine_state_name")
        if name is not None and name != self._state:
            self._state = name
            self._text(self.m.MAV_SEVERITY_INFO, f"ZK engine: {name}")
        code = rec.get("error_code")
        if code is not None and code != self._error:
            first = self._error is None
            self._error = code
            if code:
                self._text(self.m.MAV_SEVERITY_CRITICAL, f"ZK ECU error {code}: {rec.get('error_name') or ''}")
            elif not first:
                self._text(self.m.MAV_SEVERITY_NOTICE, "ZK ECU error cleared")

    # messages out
    def _send(self, what, fn, *args):
        try:
            fn(*args)
            self.sent[what] += 1
        except OSError:
            self.send_errors += 1

    def _text(self, severity, text):
        self._send("STATUSTEXT", self.mav.statustext_send, severity, text.encode("utf-8")[:50])

    def healthy(self) -> bool:
        return bool(self.latest) and not self._silent and not self.latest.get("error_code")

    def heartbeat(self):
        m = self.m
        if self.latest.get("error_code"):
            status = m.MAV_STATE_CRITICAL
        elif self._state == "running":
            status = m.MAV_STATE_ACTIVE
        else:
            status = m.MAV_STATE_STANDBY
        self._send("HEARTBEAT", self.mav.heartbeat_send, m.MAV_TYPE_GENERIC, m.MAV_AUTOPILOT_INVALID, 0, 0, status)

    def efi_values(self) -> dict:
        """The EFI_STATUS fields from the latest values, in MAVLink's units."""
        latest = self.latest
        out = {"health": 1 if self.healthy() else 0, "ecu_index": float(self.ecu_index)}
        for field, (key, factor, _) in EFI_FIELDS.items():
            out[field] = _num(latest.get(key)) * factor
        for field in EFI_UNUSED:
            out[field] = 0.0
        return out

    def efi_status(self):
        self._send("EFI_STATUS", lambda: self.mav.efi_status_send(**self.efi_values()))

    def named(self, keys):
        boot_ms = int((self.clock() - self._t0) * 1000) & 0xFFFFFFFF
        for key in keys:
            v = self.latest.get(key)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                self._send("NAMED_VALUE_FLOAT", self.mav.named_value_float_send, boot_ms,
                           self._named[key].encode("ascii"), float(v))

    def _pump_input(self):
        """Read what the peer sent (a udpin connection learns its destination so)."""
        for _ in range(50):
            try:
                if self.conn.recv_msg() is None:
                    break
            except (OSError, ValueError):
                break

    def run(self, q, stop):
        fast = [k for k in FAST_NAMED if k in self._named]
        slow = [k for k in self._named if k not in FAST_NAMED]
        self._due = None
        wake = self.clock()
        while True:
            # wake for the next message due (or the moment the frames count as stopped), not
            # for every record: they wait in the queue
            self._closing.wait(max(0.0, wake - self.clock()))
            recs, stopped = self.drain(q, stop)
            for rec in recs:
                self.absorb(rec)
            if stopped:
                return
            wake = self.step(self.clock(), fast, slow)

    def step(self, now, fast=(), slow=()) -> float:
        """Send what is due at ``now`` — the "no status frames" warning the moment the last
        status record is :data:`SILENT_S` old (whatever the ECU's error state), HEARTBEAT at
        1 Hz, EFI_STATUS and the named values at the EFI rate — and return when the next is due."""
        due = self._due
        if due is None:
            due = self._due = {"hb": now, "efi": now, "slow": now + 1.0}
        last = self._arrived if self._arrived is not None else self._last_rec
        if last is not None and not self._silent and self._last_rec is not None and now - last >= SILENT_S:
            self._silent = True
            self._text(self.m.MAV_SEVERITY_WARNING, "ZK ECU: no status frames")
        if now >= due["hb"]:
            self._pump_input()
            self.heartbeat()
            due["hb"] = due["hb"] + 1.0 if due["hb"] + 1.0 > now else now + 1.0
        if now >= due["efi"]:
            period = 1.0 / self.rate
            if self.latest:
                self.efi_status()
                self.named(fast)
                if now >= due["slow"]:
                    self.named(slow)
                    due["slow"] = now + 1.0
            due["efi"] = due["efi"] + period if due["efi"] + period > now else now + period
        wake = min(due["hb"], due["efi"])
        if last is not None and not self._silent:
            wake = min(wake, last + SILENT_S)
        return wake

    def stats(self) -> dict:
        s = super().stats()
        s.update({"sent": dict(self.sent), "send_errors": self.send_errors})
        return s

    def describe(self) -> str:
        s = self.stats()
        return (f"{s['submitted']} records, {s['dropped']} dropped; sent {s['sent']['EFI_STATUS']} EFI_STATUS, "
                f"{s['sent']['HEARTBEAT']} HEARTBEAT, {s['sent']['NAMED_VALUE_FLOAT']} NAMED_VALUE_FLOAT, "
                f"{s['sent']['STATUSTEXT']} STATUSTEXT to {self.url}"
                + (f" ({s['send_errors']} send errors)" if s["send_errors"] else ""))
