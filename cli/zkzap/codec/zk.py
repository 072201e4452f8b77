"""ZK turbine ECU protocol V1.2 (with the V1.4 additions): the field tables and payload codec.

Everything about a field is declared once, in :data:`CONTROL` and :data:`STATUS`; encoders,
decoders, the CLI's sub-commands and options, JSON keys, CSV columns and help text are derived
from these tables. Frame boundaries and CRCs live in :mod:`zkzap.codec.framing`.

Control frame (host -> ECU), 4 bytes: ``FF b1 b2 CRC``; b1[7:4] is the command ID; the CRC
covers bytes 1..2. Status frame (ECU -> host), 7 bytes: ``F0|ID b1..b5 CRC``; the CRC covers
bytes 0..5. ``bN`` below is byte N of the frame.
"""

from __future__ import annotations

from ..errors import CHECK_FAILED, USAGE, CheckFailed, ZkzapError, close_names, did_you_mean, unknown_name

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Iterable, Mapping, Optional, Union

    from typing_extensions import Self, TypeAlias

    from .permissions import Permission

    #: Bytes of a frame: bytes, a bytearray, a memoryview or a list of ints.
    Bytes: TypeAlias = Union[bytes, bytearray, memoryview, "list[int]"]
    #: A decoded record: a dict of JSON-ready values.
    Record: TypeAlias = dict[str, Any]
from .crc import crc8_maxim
from .fields import OUT_OF_RANGE, ContextScale, Field, FieldValueError, Layout, VersionScale, quote_value

CONTROL_HEAD = 0xFF
STATUS_HEAD = 0xF0
CONTROL_LEN = 4
STATUS_LEN = 7

#: Protocol version assumed for version-dependent units until a status ID 6 frame reveals it.
#: Version 4 is the version of the document's own worked example, and every version >= 4
#: shares its 0.2 V voltage unit.
DEFAULT_PROTOCOL_VERSION = 4

# --- names from the appendix ---------------------------------------------------------------
ENGINE_STATES = {
    0: "stop", 1: "standby", 2: "ignition-min-throttle", 3: "ignition", 4: "preheat",
    5: "fuel-ramp", 6: "learn-max-throttle", 7: "learn-min-throttle", 8: "learn-idle",
    9: "running-min-throttle", 10: "running-pump-limit", 11: "running", 12: "cooling",
    13: "restart", 14: "test-glowplug", 15: "test-main-valve", 16: "test-ignition-valve",
    17: "test-pump", 18: "test-starter", 19: "fuel-exhaust-air",
}
ENGINE_STATE_TEXT = {
    0: "Stop", 1: "Standby/auto cooling", 2: "Ignition (requires minimum throttle)",
    3: "Ignition", 4: "Preheat", 5: "Fuel ramp", 6: "Running (learning mode, requires maximum throttle)",
    7: "Running (learning mode, requires minimum throttle)", 8: "Running (learning idle)",
    9: "Running (minimum throttle)", 10: "Running (warning, fuel pump at limit)", 11: "Running",
    12: "Cooling", 13: "Restart", 14: "Test glowplug", 15: "Test main valve",
    16: "Test ignition valve", 17: "Test pump", 18: "Test starter", 19: "Fuel exhaust air",
}
ERRORS = {
    0: "none", 1: "timeout", 2: "voltage-low", 3: "glowplug-failure", 4: "pump-failure",
    5: "starter-failure", 6: "rpm-low", 7: "rpm-instability", 8: "egt-high", 9: "egt-low",
    10: "egt-sensor-failure", 11: "ignition-valve-failure", 12: "main-valve-failure",
    13: "loss-of-control-signal", 14: "starter-controller-overheat",
    15: "pump-controller-overheat", 16: "clutch-failure", 17: "current-overload",
    18: "engine-offline",
}
ERROR_TEXT = {
    0: "No error", 1: "Time out", 2: "Voltage low", 3: "Glowplug failure", 4: "Pump failure",
    5: "Starter failure", 6: "RPM low", 7: "RPM instability", 8: "Exhaust temperature is high",
    9: "Exhaust temperature is low", 10: "Exhaust gas temperature sensor failure",
    11: "Ignition valve failure", 12: "Main valve failure", 13: "Loss of control signal",
    14: "Starter controller temperature is too high", 15: "Pump controller temperature is too high",
    16: "Clutch failure", 17: "Current overload", 18: "Engine offline",
}
#: Control ID 1 SW: who controls the engine and in which state.
CONTROL_SW = {0: "pwm", 1: "stop", 2: "standby", 3: "run"}
#: Control ID 6 SW: 0 leaves ID 1's SW in force.
MODE_SW = {0: "none", 1: "stop", 2: "standby", 3: "run"}
#: Status ID 1 SwSt.
SW_STATE = {0: "stop", 1: "standby", 2: "run"}
#: Control ID 2 params, 1..13 in document order.
ACTIONS = {
    1: "drain-oil", 2: "test-glowplug", 3: "test-main-valve", 4: "test-ignition-valve",
    5: "test-pump", 6: "test-starter", 7: "rate-20hz", 8: "rate-50hz", 9: "rate-100hz",
    10: "reset-fuel", 11: "zero-thrust", 12: "pump-on", 13: "pump-off",
}
ACTION_TEXT = {
    1: "Drain oil", 2: "Test the glowplug", 3: "Test the main valve", 4: "Test the ignition valve",
    5: "Test the fuel pump", 6: "Test the starter", 7: "Set the status update rate to 20 Hz",
    8: "Set the status update rate to 50 Hz", 9: "Set the status update rate to 100 Hz",
    10: "Reset fuel consumption statistics", 11: "Calibrate the thrust sensor to 0",
    12: "Open the fuel pump for a long time", 13: "Close the pump",
}
ACTION_SINCE = {10: 2, 11: 2, 12: 5, 13: 5}
STATUS_RATES = {0: 20, 1: 50, 2: 100}

#: Voltage unit of status IDs 2 and 6: 0.1 V up to protocol version 3, 0.2 V from 4.
VOLTAGE = VersionScale(((3, 0.1),), 0.2)


class ControlCommand:
    """One control command (host -> ECU)."""

    def __init__(self, id: int, name: str, help: str, fields: Iterable[Field] = (), since: int = 1,
                 params: Iterable[Param] = (), hazard: Optional[str] = None, needs_unlock: bool = False) -> None:
        self.id = id
        self.name = name
        self.help = help
        self.since = since
        self.params = tuple(params)   # context parameters the CLI asks for (not in the frame)
        self.hazard = hazard          # what it can do to an engine; None when harmless
        self.needs_unlock = needs_unlock
        self.layout = Layout(fields, CONTROL_LEN, covered={0: 0xFF, 1: 0xF0, 3: 0xFF})

    @property
    def fields(self) -> tuple[Field, ...]:
        """The command's fields, in frame order."""
        return self.layout.fields


class Param:
    """A context parameter a command needs to convert physical values (not sent in the frame)."""

    def __init__(self, key: str, lo: int, hi: int, cli: str, help: str) -> None:
        self.key, self.lo, self.hi, self.cli, self.help = key, lo, hi, cli, help

    @property
    def label(self) -> str:
        """The parameter's name in messages (``rpm-factor``)."""
        return self.cli.lstrip("-")

    def check(self, value: int) -> int:
        """``value`` if it is within the parameter's range; FieldValueError otherwise."""
        if not isinstance(value, int) or not self.lo <= value <= self.hi:
            raise FieldValueError(f"{self.label}: {quote_value(value)} is out of range; allowed {self.lo}..{self.hi}")
        return value


RPM_FACTOR = Param("rpm_factor", 1, 6, "--rpm-factor",
                   "RPM factor RPM_X set with 'mode' (1..6): target rpm = value x 10 x RPM_X")

CONTROL = (
    ControlCommand(0, "keepalive", "Keep-alive (ID 0): no control, the ECU keeps reporting status."),
    ControlCommand(1, "control", "Engine state and throttle (ID 1).", fields=(
        Field("sw", "b1[3:2]", names=CONTROL_SW, name_key="state", cli="--state",
              help="pwm hands control back to the PWM input; stop, standby (cools when hot) or run"),
        Field("throttle_pct", "b1[1:0] b2", scale=0.1, unit="%", hi=1000, cli="--throttle",
              help="throttle, 0..100 % in 0.1 % steps"),
    ), hazard="can start the engine"),
    ControlCommand(2, "action", "ECU action or setting (ID 2).", fields=(
        Field("param", "b2", names=ACTIONS, name_key="action", lo=1, hi=13, cli="NAME", label="action",
              since_by_value=ACTION_SINCE, help="the action to run"),
    ), hazard="can run the starter or pump, fire the igniter or drain fuel"),
    ControlCommand(3, "unlock", "Unlock settings (ID 3): ignition-voltage and accel-curve need it first."),
    ControlCommand(4, "ignition-voltage", "Ignition pump voltage (ID 4); needs unlock first.", fields=(
        Field("ignition_voltage_v", "b2", scale=0.02, unit="V", cli="VOLTS", label="ignition-voltage",
              help="ignition pump voltage, 0..5.10 V in 0.02 V steps"),
    ), needs_unlock=True),
    ControlCommand(5, "accel-curve", "Acceleration curve (ID 5); needs unlock first.", fields=(
        Field("accel_curve", "b2", lo=10, hi=70, cli="N", label="accel-curve",
              help="acceleration curve 10..70; larger accelerates faster"),
    ), needs_unlock=True),
    ControlCommand(6, "mode", "Engine state and RPM factor (ID 6); a non-zero RPM factor selects RPM mode.", fields=(
        Field("rpm_factor", "b2[4:2]", hi=6, cli="--rpm-factor",
              help="RPM factor RPM_X 0..6 (0 = throttle mode); max target 40950 x RPM_X rpm"),
        Field("sw", "b2[1:0]", names=MODE_SW, name_key="state", cli="--state",
              help="none leaves ID 1's state in force; stop, standby or run override it"),
    ), since=4, hazard="can start the engine"),
    ControlCommand(7, "rpm", "Target engine speed in RPM mode (ID 7).", fields=(
        Field("target_rpm", "b1[3:0] b2", scale=ContextScale("rpm_factor", 10), hi=4095,
              raw_key="rpm_value", unit="rpm", cli="RPM", label="rpm",
              help="target engine speed; sent as RPM / (10 x RPM_X), 0..4095"),
    ), since=4, params=(RPM_FACTOR,)),
    ControlCommand(8, "pressure", "Atmospheric static pressure (ID 8).", fields=(
        Field("pressure_hpa", "b1[1:0] b2", unit="hPa", hi=1023, cli="HPA", label="pressure",
              note="10-bit field; the document's 1024 does not fit",
              help="air pressure, 0..1023 hPa"),
    )),
)
CONTROL_BY_ID = {c.id: c for c in CONTROL}
CONTROL_BY_NAME = {c.name: c for c in CONTROL}

RPM = Field("rpm", "b2 b1", scale=10, unit="rpm", help="engine speed")


class StatusFrame:
    """One status frame kind (ECU -> host)."""

    def __init__(self, id: int, name: str, fields: Iterable[Field], since: int = 1, help: str = "") -> None:
        self.id = id
        self.name = name
        self.since = since
        self.help = help
        self.layout = Layout((RPM,) + tuple(fields), STATUS_LEN, covered={0: 0xFF, 6: 0xFF})

    @property
    def fields(self) -> tuple[Field, ...]:
        """The frame's fields (``rpm`` first), in frame order."""
        return self.layout.fields


STATUS = (
    StatusFrame(1, "engine", (
        Field("engine_state", "b3[4:0]", names=ENGINE_STATES, name_key="engine_state_name",
              help="engine state (appendix table 0..19)"),
        Field("error_code", "b4[1:0] b3[7:5]", names=ERRORS, name_key="error_name",
              help="error code (appendix table 0..18)"),
        Field("egt_c", "b4[4:2] b5", offset=-50, unit="°C", help="exhaust gas temperature"),
        Field("sw_state", "b4[6:5]", names=SW_STATE, name_key="sw_state_name",
              help="host control state: stop, standby, run"),
    )),
    StatusFrame(2, "voltages", (
        Field("radio_voltage_v", "b3", scale=VOLTAGE, unit="V", help="receiver (radio) voltage"),
        Field("power_voltage_v", "b4", scale=VOLTAGE, unit="V", help="power (battery) voltage"),
        Field("pump_voltage_v", "b5", scale=VOLTAGE, unit="V", help="fuel pump voltage"),
    )),
    StatusFrame(3, "throttle", (
        Field("throttle_pct", "b3", unit="%", hi=100, help="throttle"),
        Field("pressure_pa", "b5 b4", scale=2, unit="Pa", help="air pressure"),
    )),
    StatusFrame(4, "load", (
        Field("current_a", "b4[0] b3", scale=0.1, unit="A", help="current"),
        Field("thrust_kg", "b4[7:1] b5", scale=0.1, unit="kg", since=2,
              help="thrust (0 without a thrust sensor)"),
    )),
    StatusFrame(5, "ignition", (
        Field("ignition_pump_voltage_v", "b3", scale=0.02, unit="V", help="ignition pump voltage"),
        Field("curve_inc", "b4", lo=10, hi=70, help="acceleration curve INC (raw, unit not documented)"),
        Field("curve_dec", "b5", lo=10, hi=70, help="acceleration curve DEC (raw, unit not documented)"),
    )),
    StatusFrame(6, "config", (
        Field("max_rpm", "b3", scale=1000, unit="rpm", help="maximum engine speed"),
        Field("max_pump_voltage_v", "b4", scale=VOLTAGE, unit="V", help="maximum pump voltage"),
        Field("protocol_version", "b5[7:2]", help="ECU protocol version"),
        Field("status_rate_hz", "b5[1:0]", values=STATUS_RATES, raw_key=None, unit="Hz",
              help="status update rate (20, 50 or 100 Hz)"),
    )),
    StatusFrame(7, "fuel", (
        Field("fuel_flow_l_min", "b4[1:0] b3", scale=0.01, unit="L/min", help="fuel flow rate"),
        Field("fuel_used_l", "b5 b4[7:2]", scale=0.1, unit="L", since=2, help="fuel used"),
    )),
    StatusFrame(8, "setup", (
        Field("idle_rpm", "b3", scale=1000, unit="rpm", help="idle speed"),
        Field("esr", "b4[5]", help="1: the ECU asks the host to send air pressure (control ID 8)"),
        Field("scl", "b4[4]", help="1: speed closed loop, 0: open loop"),
        Field("startup_time_s", "b4[3:0] b5", scale=0.1, unit="s", help="startup time"),
    )),
    StatusFrame(9, "ecu", (
        Field("ecu_temp_c", "b3", offset=-50, unit="°C", since=5, help="ECU temperature"),
        Field("prop_rpm", "b5 b4", unit="rpm", since=6, help="propeller/shaft speed (V1.4)"),
    )),
    StatusFrame(10, "pump", (
        Field("fuel_pump_rpm", "b5 b4", unit="rpm", help="fuel pump speed (V1.4)"),
    ), since=1, help="added by the V1.4 edition"),
)
STATUS_BY_ID = {s.id: s for s in STATUS}
#: The keys each status frame ID carries (``rpm`` in every one, ``error_code`` in ID 1's).
STATUS_KEYS_BY_ID = {s.id: frozenset(s.layout.keys()) for s in STATUS}

#: Every status key in table order (CSV columns, snapshot rows).
STATUS_KEYS = []
for _s in STATUS:
    for _k in _s.layout.keys():
        if _k not in STATUS_KEYS:
            STATUS_KEYS.append(_k)
CONTROL_KEYS = []
for _c in CONTROL:
    for _k in _c.layout.keys():
        if _k not in CONTROL_KEYS:
            CONTROL_KEYS.append(_k)
# the list of out-of-range fields comes last (a CSV column after every field)
for _keys in (STATUS_KEYS, CONTROL_KEYS):
    if OUT_OF_RANGE in _keys:
        _keys.remove(OUT_OF_RANGE)
        _keys.append(OUT_OF_RANGE)
del _s, _c, _k, _keys


class FrameError(ZkzapError, ValueError):
    """A frame of the wrong length, head or ID: bad input (exit 2), also a ``ValueError``."""

    code = USAGE


class CrcError(FrameError, CheckFailed):
    """A frame whose CRC does not match: a failed check (exit 1), with the ``expected`` and
    ``found`` CRC bytes."""

    code = CHECK_FAILED

    def __init__(self, message: str, expected: int, found: int) -> None:
        super().__init__(message, expected=expected, found=found)


# --- control frames ----------------------------------------------------------------------------

def control_frame(cmd_id: int, b1_low: int, b2: int) -> bytes:
    """Assemble ``FF b1 b2 CRC`` from the command ID, b1[3:0] and b2."""
    b1 = (cmd_id << 4) | (b1_low & 0x0F)
    return bytes((CONTROL_HEAD, b1, b2, crc8_maxim((b1, b2))))


def control_command(name_or_id: Union[str, int]) -> ControlCommand:
    """The control command by ``zk send`` name or command ID; FieldValueError naming the
    closest names otherwise."""
    cmd = CONTROL_BY_NAME.get(name_or_id) if isinstance(name_or_id, str) else CONTROL_BY_ID.get(name_or_id)
    if cmd is None:
        names = ", ".join(c.name for c in CONTROL)
        raise unknown_name("command", name_or_id, CONTROL_BY_NAME, noun="kind",
                           otherwise=f"; allowed {names} (or IDs 0..8)", cls=FieldValueError)
    return cmd


def encode_control(name_or_id: Union[str, int], **values: Any) -> tuple[bytes, list[str]]:
    """Encode a control command from physical values. Returns ``(frame, notes)``.

    Enumerated fields take names or numbers (``sw="run"``); context parameters go in the
    same keyword arguments (``rpm_factor=3``). Missing fields are 0. Raises
    :class:`FieldValueError` naming the field and its range.
    """
    cmd = control_command(name_or_id)
    ctx = {}
    for p in cmd.params:
        if p.key not in values:
            raise FieldValueError(f"{p.label}: required; allowed {p.lo}..{p.hi}")
        ctx[p.key] = p.check(values.pop(p.key))
    frame = bytearray((CONTROL_HEAD, cmd.id << 4, 0, 0))
    notes = []
    known = {f.key for f in cmd.fields} | {f.name_key for f in cmd.fields if f.name_key}
    for key in values:
        if key not in known:
            raise FieldValueError(f"{key}: not a field of {cmd.name}"
                                  + did_you_mean(key, known, otherwise=f"; fields: {', '.join(sorted(known)) or 'none'}"),
                                  suggestions=close_names(key, known))
    for f in cmd.fields:
        v = values.get(f.key, values.get(f.name_key, 0) if f.name_key else 0)
        raw, note = f.to_raw(v, ctx)
        if note:
            notes.append(note)
        f.insert(frame, raw)
    frame[3] = crc8_maxim(frame[1:3])
    return bytes(frame), notes


def encode_control_raw(cmd_id: int, **raws: Union[int, str]) -> bytes:
    """Encode a control frame from raw field values (``throttle_pct=500``). Reserved bits may be
    set with ``reserved_b1`` / ``reserved_b2`` for one-off crafting (only bits no field of the
    command uses: they never change a real field); unknown keys are an error."""
    cmd = control_command(cmd_id)
    frame = bytearray((CONTROL_HEAD, cmd.id << 4, 0, 0))
    fields = {f.key: f for f in cmd.fields}
    fields.update({f.raw_key: f for f in cmd.fields if f.raw_key})
    fields.update({f.name_key: f for f in cmd.fields if f.name_key})
    for key, raw in raws.items():
        key = key.replace("-", "_")
        if key in ("reserved_b1", "reserved_b2"):
            byte = 1 if key == "reserved_b1" else 2
            mask = cmd.layout.reserved[byte] & (0x0F if byte == 1 else 0xFF)
            frame[byte] |= _check_byte(key, raw, mask, cmd)
            continue
        f = fields.get(key)
        if f is None:
            allowed = ", ".join(sorted(fields)) or "none"
            raise FieldValueError(f"{key}: not a field of command {cmd.id} ({cmd.name})"
                                  + did_you_mean(key, [*fields, "reserved_b1", "reserved_b2"],
                                                 otherwise=f"; fields: {allowed}; reserved bits: reserved_b1, reserved_b2"),
                                  suggestions=close_names(key, [*fields, "reserved_b1", "reserved_b2"]))
        if f.names is not None and isinstance(raw, str):
            raw, _ = f.to_raw(raw)
        f.insert(frame, f.check_raw(raw, key))
    frame[3] = crc8_maxim(frame[1:3])
    return bytes(frame)


def _check_byte(key, value, mask, cmd):
    """A reserved-bits value: only the bits no field of ``cmd`` uses (the ID nibble and the
    fields' bits are never reachable this way)."""
    if not isinstance(value, int) or value < 0 or value > 0xFF:
        raise FieldValueError(f"{key}: {quote_value(value)} is out of range; allowed bits {mask:#04x}")
    if value & ~mask:
        where = (f"allowed bits {mask:#04x}" if mask
                 else f"command {cmd.id} ({cmd.name}) has no reserved bits in that byte")
        raise FieldValueError(f"{key}: {value:#04x} sets bits {value & ~mask:#04x} that are not reserved; {where}")
    return value


def check_control(frame: Bytes) -> None:
    """Raise :class:`FrameError`/:class:`CrcError` unless ``frame`` is a well-formed control frame."""
    if len(frame) != CONTROL_LEN:
        raise FrameError(f"control frame: {len(frame)} bytes; a control frame has {CONTROL_LEN}")
    if frame[0] != CONTROL_HEAD:
        raise FrameError(f"control frame: head {frame[0]:02X}; expected FF")
    crc = crc8_maxim(frame[1:3])
    if crc != frame[3]:
        raise CrcError(f"control frame: CRC mismatch: expected {crc:02X}, found {frame[3]:02X}", crc, frame[3])


def decode_control(frame: Bytes, ctx: Optional[Mapping[str, Any]] = None, raw: bool = False) -> Record:
    """Decode a checked control frame into a record."""
    cmd_id = frame[1] >> 4
    cmd = CONTROL_BY_ID.get(cmd_id)
    rec = {"kind": "control", "id": cmd_id}
    if cmd is None:
        rec["command"] = None
        rec["payload"] = f"{frame[1] & 0x0F:X}{frame[2]:02X}"
        return rec
    rec["command"] = cmd.name
    rec.update(cmd.layout.decode(frame, ctx or {}, None, raw))
    reserved = cmd.layout.reserved_bits(frame)
    if reserved:
        rec["reserved"] = reserved
    return rec


# --- status frames -----------------------------------------------------------------------------

def status_frame(status_id: int, payload: Bytes) -> bytes:
    """Assemble ``F0|ID b1..b5 CRC`` from five payload bytes."""
    body = bytes((STATUS_HEAD | status_id,)) + bytes(payload)
    return body + bytes((crc8_maxim(body),))


def encode_status(status_id: int, version: int = DEFAULT_PROTOCOL_VERSION, **values: Any) -> bytes:
    """Encode a status frame from physical values (used by the simulator and the tests)."""
    st = STATUS_BY_ID.get(status_id)
    if st is None:
        raise FieldValueError(f"status id: {status_id} is unknown; allowed 1..{max(STATUS_BY_ID)}")
    ctx = {"version": version}
    frame = bytearray(STATUS_LEN)
    frame[0] = STATUS_HEAD | status_id
    keys = {f.key: f for f in st.fields}
    for key in values:
        if key not in keys:
            raise FieldValueError(f"{key}: not a field of status {status_id}"
                                  + did_you_mean(key, keys, otherwise=f"; fields: {', '.join(keys)}"),
                                  suggestions=close_names(key, keys))
    for f in st.fields:
        v = values.get(f.key)
        if v is None:
            continue
        raw, _ = f.to_raw(v, ctx)
        f.insert(frame, raw)
    frame[6] = crc8_maxim(frame[:6])
    return bytes(frame)


def check_status(frame: Bytes) -> None:
    """Raise :class:`FrameError`/:class:`CrcError` unless ``frame`` is a well-formed status frame."""
    if len(frame) != STATUS_LEN:
        raise FrameError(f"status frame: {len(frame)} bytes; a status frame has {STATUS_LEN}")
    if frame[0] & 0xF0 != STATUS_HEAD:
        raise FrameError(f"status frame: head {frame[0]:02X}; expected F1..F{max(STATUS_BY_ID):X}")
    crc = crc8_maxim(frame[:6])
    if crc != frame[6]:
        raise CrcError(f"status frame: CRC mismatch: expected {crc:02X}, found {frame[6]:02X}", crc, frame[6])


#: Head byte of status ID 6, the frame that carries the ECU's protocol version.
VERSION_HEAD = STATUS_HEAD | 6


def protocol_version_of(frame: Bytes) -> Optional[int]:
    """The protocol version a status ID 6 frame reports (``b5[7:2]``), or None for any other frame."""
    if len(frame) == STATUS_LEN and frame[0] == VERSION_HEAD:
        return frame[5] >> 2
    return None


def decode_status(frame: Bytes, version: int = DEFAULT_PROTOCOL_VERSION, known: Optional[int] = None,
                  raw: bool = False) -> Record:
    """Decode a checked status frame. ``version`` sets version-dependent units; ``known`` is the
    version actually known (seen or given) and gates fields newer than it (None: ungated)."""
    sid = frame[0] & 0x0F
    st = STATUS_BY_ID.get(sid)
    rec = {"kind": "status", "id": sid}
    if st is None:
        rec["rpm"] = (frame[2] << 8 | frame[1]) * 10
        rec["payload"] = bytes(frame[3:6]).hex(" ").upper()
        return rec
    if sid == 6:
        version = known = protocol_version_of(frame)
    rec.update(st.layout.decode(frame, {"version": version}, known, raw))
    return rec


def check_defined(frame: Bytes) -> None:
    """Raise :class:`FrameError` for a control frame whose command ID is not defined (0..8);
    its CRC may well be right (``crc check`` accepts it, the decoders skip it)."""
    if len(frame) == CONTROL_LEN and frame[1] >> 4 not in CONTROL_BY_ID:
        raise FrameError(f"control frame: command ID {frame[1] >> 4} is not defined; "
                         f"allowed 0..{max(CONTROL_BY_ID)}")


def check_frame(frame: Bytes) -> str:
    """Check a whole ZK frame of either kind by its length. Returns ``"control"`` or ``"status"``."""
    if len(frame) == CONTROL_LEN:
        check_control(frame)
        return "control"
    if len(frame) == STATUS_LEN:
        check_status(frame)
        return "status"
    raise FrameError(f"ZK frame: {len(frame)} bytes; a control frame has 4, a status frame 7")


#: Status IDs with a field whose unit depends on the protocol version (ID 6 carries its own).
VERSIONED_STATUS = frozenset(st.id for st in STATUS if st.id != 6 and any(
    isinstance(f.scale, VersionScale) for f in st.fields))


class ZkDecoder:
    """Stateful record decoder for a ZK byte stream's frames.

    Tracks the protocol version (from status ID 6, else the one given, else the default) and
    the RPM factor of the last control ID 6, so ID 2/6 voltages and ID 7 targets decode right.
    ``version_source`` is ``"frame"``, ``"given"`` or ``"default"``; ``assumed`` becomes True
    when a frame with a version-dependent unit was decoded with the default version.
    """

    def __init__(self, protocol_version: Optional[int] = None, raw: bool = False) -> None:
        self.given = protocol_version
        self.version = protocol_version if protocol_version is not None else DEFAULT_PROTOCOL_VERSION
        self.known = protocol_version
        self.version_source = "given" if protocol_version is not None else "default"
        self.rpm_factor: Optional[int] = None
        self.raw = raw
        self.assumed = False

    def decode(self, frame: Bytes) -> Record:
        """The record of one checked frame of either kind (tracking version and RPM factor)."""
        if len(frame) == STATUS_LEN:
            v = protocol_version_of(frame)
            if v is not None:
                self.version = self.known = v
                self.version_source = "frame"
            elif self.version_source == "default" and frame[0] & 0x0F in VERSIONED_STATUS:
                self.assumed = True
            return decode_status(frame, self.version, self.known, self.raw)
        rec = decode_control(frame, {"rpm_factor": self.rpm_factor}, self.raw)
        if rec["id"] == 6:
            self.rpm_factor = rec["rpm_factor"]
        return rec


#: What a session controlling the engine sends on an abnormal end: control ID 1 with that state
#: and throttle 0, or ``none`` (nothing). ``standby`` lets a hot engine cool.
ABORTS = ("standby", "stop", "none")
DEFAULT_ABORT = "standby"

#: Control ID 2 actions that run hardware: each needs consent on a real port.
HAZARDOUS_ACTIONS = frozenset({1, 2, 3, 4, 5, 6, 12})


class ControlFrame:
    """A control frame (host -> ECU) and what sending it means, answered here once.

    ``frame`` (the 4 bytes), ``id`` (the command ID), ``command`` (the
    :class:`ControlCommand`, None for an undefined ID). :attr:`hazard` says what it can do to
    an engine and :meth:`needs` the permission that takes (ENGINE: consent on a real port);
    :attr:`controls_engine` whether a session sending it
    is in control of the engine (and gets the abort command on an abnormal end).
    """

    __slots__ = ("frame", "id", "command")
    frame: bytes
    id: int
    command: Optional[ControlCommand]

    def __init__(self, frame: Bytes) -> None:
        self.frame = bytes(frame)
        self.id = self.frame[1] >> 4
        self.command = CONTROL_BY_ID.get(self.id)

    @classmethod
    def build(cls, name_or_id: Union[str, int], **values: Any) -> Self:
        """Encode a command from physical values (see :func:`encode_control`)."""
        return cls(encode_control(name_or_id, **values)[0])

    def __repr__(self) -> str:
        return f"ControlFrame({self.frame.hex(' ').upper()})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ControlFrame) and other.frame == self.frame

    def __hash__(self) -> int:
        return hash(self.frame)

    @property
    def sw(self) -> int:
        """The state bits: ID 1 ``b1[3:2]``, ID 6 ``b2[1:0]`` (0 for other IDs)."""
        if self.id == 1:
            return (self.frame[1] >> 2) & 3
        if self.id == 6:
            return self.frame[2] & 3
        return 0

    @property
    def action(self) -> Optional[str]:
        """ID 2's action name (None for other IDs or an undefined parameter)."""
        return ACTIONS.get(self.frame[2]) if self.id == 2 else None

    @property
    def hazard(self) -> Optional[str]:
        """What the frame can do to an engine, or None when it is harmless.

        Hazardous: ID 1 or ID 6 with state run (can start the engine), ID 2 actions that drain
        fuel, fire the igniter, open valves, run the pump or the starter.
        """
        if self.id in (1, 6) and self.sw == 3:
            return "state run can start the engine"
        if self.id == 2 and self.frame[2] in HAZARDOUS_ACTIONS:
            return f"action {ACTIONS[self.frame[2]]} runs ECU hardware ({ACTION_TEXT[self.frame[2]].lower()})"
        return None

    @property
    def hazardous(self) -> bool:
        """True when sending it on a real port needs consent (see :attr:`hazard`)."""
        return self.hazard is not None

    def needs(self) -> dict[Permission, str]:
        """``{Permission: reason}``: what sending this frame needs (see
        :mod:`zkzap.codec.permissions`): ENGINE for a hazardous frame, else nothing."""
        hazard = self.hazard
        if hazard is None:
            return {}
        from .permissions import Permission

        return {Permission.ENGINE: hazard}

    @property
    def permissions(self) -> Permission:
        """The :class:`~zkzap.codec.permissions.Permission` flags sending this frame needs."""
        from .permissions import Permission

        return Permission.ENGINE if self.hazard is not None else Permission.NONE

    @property
    def controls_engine(self) -> bool:
        """True when sending it controls the engine: ID 1 with a state other than pwm, ID 6 with
        a state or an RPM factor, ID 7, or an action that runs hardware. Keep-alives, unlock,
        settings, air pressure and harmless actions (rates, reset-fuel, zero-thrust, pump-off)
        do not."""
        if self.id == 1:
            return self.sw != 0
        if self.id == 6:
            return self.frame[2] & 0x1F != 0
        if self.id == 7:
            return True
        if self.id == 2:
            return self.hazardous
        return False

    @property
    def since(self) -> int:
        """The protocol version an ECU needs for this frame: the command's, or the action's
        (``reset-fuel`` needs 2, ``pump-on``/``pump-off`` 5); 1 for an undefined ID."""
        if self.command is None:
            return 1
        if self.id == 2:
            return max(self.command.since, ACTION_SINCE.get(self.frame[2], 1))
        return self.command.since

    @property
    def rpm_factor(self) -> Optional[int]:
        """ID 6's RPM factor RPM_X (0: throttle mode); None for other IDs."""
        return (self.frame[2] >> 2) & 7 if self.id == 6 else None

    @property
    def rpm_value(self) -> Optional[int]:
        """ID 7's 12-bit RPM value (target rpm = value x 10 x RPM_X); None for other IDs."""
        return ((self.frame[1] & 0x0F) << 8) | self.frame[2] if self.id == 7 else None

    def leaves(self, rpm_factor: Optional[int] = None) -> Optional[str]:
        """What the engine is left doing once this frame was the last one it got, in words, when
        that is more than standing safe (None: stop, standby, pwm and harmless commands).
        ``rpm_factor``: the RPM_X in force, for an ID 7 target."""
        if self.id == 1 and self.sw == 3:
            throttle = (((self.frame[1] & 3) << 8) | self.frame[2]) / 10
            return f"running at {throttle:g} % throttle (state run)"
        if self.id == 6 and self.frame[2] & 0x1F:
            what = []
            if self.sw == 3:
                what.append("in state run")
            if self.rpm_factor:
                what.append(f"in RPM mode (RPM_X {self.rpm_factor})")
            return " and ".join(what) if what else None
        if self.id == 7:
            target = (f"{self.rpm_value * 10 * rpm_factor:,} rpm" if rpm_factor
                      else f"RPM value {self.rpm_value} (x 10 x RPM_X rpm)")
            return f"holding a target of {target} (RPM mode)"
        if self.id == 2 and self.frame[2] == 12:
            return "with the fuel pump on (until pump-off)"
        return None

    def decode(self, ctx: Optional[Mapping[str, Any]] = None) -> Record:
        """The frame's record (as ``zk decode`` gives it)."""
        return decode_control(self.frame, ctx)


def control_hazard(frame: Bytes) -> Optional[str]:
    """What a control frame can do to an engine, or None (see :attr:`ControlFrame.hazard`)."""
    return ControlFrame(frame).hazard
