"""A simulated ZK turbine ECU: it streams status frames and runs a model of a small jet engine.

Status stream
    One status frame every ``1 / rate`` seconds of model time, the IDs in turn: 1..8 for protocol
    versions below 5, 1..9 from version 5 (ECU temperature), 1..10 from version 6 (the V1.4
    additions: propeller rpm in ID 9, fuel pump rpm in ID 10). The rate is *per frame*: at
    20 Hz a full cycle of ten IDs takes 0.5 s, so every value is refreshed twice a second; at
    100 Hz 700 bytes/s go out, which even 9600 baud carries. Control ID 2 actions ``rate-20hz``,
    ``rate-50hz`` and ``rate-100hz`` change it; status ID 6 reports it.

Engine model (all times in model seconds; ``--speed`` runs the model faster)
    - state ``run`` from a cold engine: ignition (3 s) -> preheat (4 s) -> fuel ramp (5 s) ->
      running; the throttle is ignored during the start, as an ECU does. The duration of the last
      start is status ID 8's startup time. A run command while the engine is hot (EGT above
      100 degC) first cools it (state ``restart``), then starts.
    - running: RPM follows the throttle (idle .. max rpm, linear) or, once control ID 6 set a
      non-zero RPM factor, the ID 7 target (clamped to idle .. max) with a first-order lag whose
      time constant shrinks as the acceleration curve grows (ID 5, default 40: about 1.2 s up).
      EGT, current, pump voltage, fuel flow, fuel used, thrust (rpm squared) follow.
    - ``standby`` while hot: the starter spins the engine to cool it (state ``cooling``) until
      EGT falls below 100 degC, then ``standby``. ``stop``: fuel off, no cooling (state ``stop``).
    - settings: ID 4 (ignition pump voltage) and ID 5 (acceleration curve, shown as status ID 5's
      curve INC) take effect only within :data:`UNLOCK_S` seconds after an unlock (ID 3);
      otherwise they are ignored, as the protocol says.
    - actions (ID 2): the tests show their engine state for a few seconds (only while the engine is
      stopped); drain-oil shows ``fuel-exhaust-air`` with the pump on; ``pump-on`` runs the pump
      until ``pump-off``; ``reset-fuel`` zeroes fuel used; ``zero-thrust`` calibrates the thrust
      reading (the sensor starts with a small offset). An action repeated frame after frame (as
      ``zk send --for`` does) runs once; another frame or a pause longer than
      :data:`LOSS_OF_SIGNAL_S` re-arms it. Actions newer than the protocol version are ignored.
    - air pressure (ID 8) shows in status ID 3 and scales thrust; with ``esr=1`` the ECU asks for
      it (status ID 8's ESR bit) until it is sent, and with ``esr_again=S`` asks again S seconds
      after each answer (0: an ECU that keeps asking).
    - ID 1 state ``pwm`` hands control to the PWM input, which this simulator reads as stop,
      throttle 0 (no receiver connected). A non-zero ID 6 state overrides ID 1's.
    - errors: an error (injected, or loss of control signal) cuts the fuel (the engine cools if
      hot) and is latched: the host must command stop or standby before the engine starts again,
      which also clears the error code.
    - loss of control signal: below protocol version 5, once the host has sent a control frame,
      a silence longer than :data:`LOSS_OF_SIGNAL_S` raises error 13 and stops the engine. From
      version 5 the ECU keeps its state when the host falls silent.

Control frames with a bad CRC (or garbage) are ignored, as a real ECU would.

Line settings: with ``baud`` (and ``stop_bits``, 1 or 2, default 1) set, the ECU's UART runs at
that setting, like a real one configured so: a host at another baud rate or stop-bit setting
(on a pty or behind ``sim://``, where the host's settings are known; a TCP client has none)
reads misframed garbage (:mod:`zkzap.sim.uart`) and what it sends reaches the ECU as garbage
too. The status stream never outruns the line: at a rate whose frames do not fit the baud rate
(100 Hz of 7-byte frames needs 7 700 baud at 8N1), frames are sent back to back and the
effective rate is what the line carries. Without ``baud`` the ECU follows the host's setting.

Fault injection, for tests: ``corrupt_every=N`` damages every Nth status frame (bad CRC),
``silent_after=S`` stops transmitting after S seconds, ``error=CODE`` (a number or a name such
as ``egt-high``) with ``error_after=S`` raises an engine error at S seconds. The same from Python:
:meth:`ZkEcu.inject_error`, :meth:`ZkEcu.set_silent`, :meth:`ZkEcu.set_corrupt_every`.
"""

from __future__ import annotations

import math
from collections import deque

from ..codec import zk
from ..errors import InvalidValue, unknown_name
from ..codec.framing import ZkFramer
from ..link.port import STOP_BITS, wire_time
from .base import Device, parse_flag, parse_number
from .uart import Line

#: Below protocol version 5, a host silent for longer than this (model seconds) loses control:
#: error 13 and the engine stops.
LOSS_OF_SIGNAL_S = 1.0
#: How long settings stay unlocked after control ID 3 (model seconds).
UNLOCK_S = 10.0
#: EGT below which a cooling engine is considered cool (degC).
COOL_DONE_C = 100.0
#: Start sequence phase durations (model seconds): ignition, preheat, fuel ramp.
IGNITION_S, PREHEAT_S, FUEL_RAMP_S = 3.0, 4.0, 5.0
#: Engine state -> seconds the test actions (and drain-oil) show their state.
TEST_S = {14: 3.0, 15: 2.0, 16: 2.0, 17: 3.0, 18: 3.0, 19: 5.0}
#: Control ID 2 params -> the engine state they show.
TEST_ACTIONS = {1: 19, 2: 14, 3: 15, 4: 16, 5: 17, 6: 18}
#: Starter speed while cooling or testing the starter (rpm).
STARTER_RPM = 5000.0
#: Model integration step (s) and the most status frames emitted at once after a long pause.
STEP_S = 0.02
MAX_BURST = 200

RATE_BY_ACTION = {7: 20, 8: 50, 9: 100}
STATE = {name: code for code, name in zk.ENGINE_STATES.items()}
RUNNING = STATE["running"]
STARTING = (STATE["ignition"], STATE["preheat"], STATE["fuel-ramp"])
SW_CODE = {"stop": 0, "standby": 1, "run": 2}   # status ID 1 SwSt

DEFAULTS = {
    "protocol_version": 6, "rate": 20, "max_rpm": 160000, "idle_rpm": 40000, "max_thrust": 14.0,
    "ambient": 20.0, "battery": 12.0, "max_pump_voltage": 10.0, "esr": False, "esr_again": None, "baud": None,
    "stop_bits": 1, "corrupt_every": 0, "silent_after": None, "error": None, "error_after": 0.0,
}


def _cycle_ids(version):
    return tuple(range(1, 9 if version < 5 else 10 if version < 6 else 11))


class ZkEcu(Device):
    """The simulated ECU. Options are documented in the module docstring and :func:`from_options`."""

    def __init__(self, protocol_version=6, rate=20, max_rpm=160000, idle_rpm=40000, max_thrust=14.0,
                 ambient=20.0, battery=12.0, max_pump_voltage=10.0, esr=False, esr_again=None, baud=None,
                 stop_bits=1, corrupt_every=0, silent_after=None, error=None, error_after=0.0):
        if not 1 <= protocol_version <= 63:
            raise InvalidValue(f"protocol_version: {protocol_version} is out of range; allowed 1..63")
        if rate not in RATE_BY_ACTION.values():
            raise InvalidValue(f"rate: {rate} is not a status rate; allowed 20, 50, 100")
        if max_rpm % 1000 or not 1000 <= max_rpm <= 255000:
            raise InvalidValue(f"max_rpm: {max_rpm}; allowed multiples of 1000 in 1000..255000")
        if idle_rpm % 1000 or not 1000 <= idle_rpm < max_rpm:
            raise InvalidValue(f"idle_rpm: {idle_rpm}; allowed multiples of 1000 below max_rpm")
        if baud is not None and not 300 <= baud <= 4_000_000:
            raise InvalidValue(f"baud: {baud} is out of range; allowed 300..4000000 (the document lists "
                             f"2400, 4800, 9600, 19200, 38400, 57600, 115200)")
        if stop_bits not in STOP_BITS:
            raise InvalidValue(f"stop_bits: {stop_bits}; allowed 1, 2")
        if corrupt_every < 0:
            raise InvalidValue(f"corrupt_every: {corrupt_every} is out of range; allowed 0 (off) or more")
        self.version = protocol_version
        self.rate = rate
        self.max_rpm = float(max_rpm)
        self.idle_rpm = float(idle_rpm)
        self.max_thrust = max_thrust
        self.ambient = ambient
        self.battery = battery
        self.max_pump_v = max_pump_voltage
        self.baud = baud
        self.stop_bits = stop_bits
        #: the ECU's UART settings (the transports reframe through it)
        self.line = Line(baud, stop_bits)
        self._line_free = 0.0         # model time the line is free again (paced stream)
        self.frames_skipped = 0       # status ticks the line had no room for
        self.corrupt_every = corrupt_every
        self.silent_after = silent_after
        self._error_at = (error_after, _error_code(error)) if error is not None else None
        self.ids = _cycle_ids(protocol_version)

        # host commands
        self.id1_sw = 0               # 0 pwm, 1 stop, 2 standby, 3 run
        self.throttle = 0.0           # % (ID 1)
        self.mode_sw = 0              # ID 6 SW: 0 none
        self.rpm_factor = 0           # ID 6 RPM_X: non-zero selects RPM mode
        self.rpm_value = 0            # ID 7 raw value
        self.pressure_hpa = 1013
        self.esr = bool(esr)
        self.esr_again = esr_again        # ask again this long after an answer (None: never)
        self._esr_at = None
        self.pressure_answers = 0         # control ID 8 frames received
        self.unlocked_until = -1.0
        self.ignition_pump_v = 1.2
        self.curve_inc = 40
        self.curve_dec = 40
        # engine
        self.state = STATE["stop"]
        self.error_code = 0
        self.rearm = False            # after an error: stop/standby needed before a new start
        self.rpm = 0.0
        self.egt = ambient
        self.ecu_temp = ambient + 10.0
        self.fuel_flow = 0.0          # L/min
        self.fuel_used = 0.0          # L
        self.pump_v = 0.0
        self.current = 0.3
        self.thrust_offset = 0.2      # kg until zero-thrust
        self.startup_time = 0.0
        self.pump_on = False
        self._phase_t0 = 0.0          # start of the current start phase / test
        self._start_t0 = 0.0
        self._test_until = 0.0
        # link
        self._framer = ZkFramer("control")
        self.received = deque(maxlen=1000)   # decoded control records, newest last
        self.rx_ignored = 0           # valid frames the ECU ignored (locked, too new, wrong state)
        self.rx_wrong_baud = 0        # bytes dropped because the host's baud differs
        self._last_rx = None          # model time of the last valid control frame
        self._last_frame = None
        self._t = 0.0
        self._schedule(0.0)
        self._cycle = 0
        self.frames_sent = 0
        self.silent = silent_after is not None and silent_after <= 0
        self._out = bytearray()
        self._ranges = {}
        if self._error_at is not None and self._error_at[0] <= 0:
            self._fault(self._error_at[1])      # present from power-up
            self._error_at = None

    # --- Device interface ------------------------------------------------------------------------
    def receive(self, data, now, baud=None, stop_bits=None):
        self._advance_to(now)
        if self.baud is not None and baud is not None and (baud != self.baud or (stop_bits or 1) < self.stop_bits):
            self.rx_wrong_baud += len(data)
            data = self.line.from_host(data, baud, stop_bits)   # what the ECU's UART makes of it
        for frame in self._framer.feed(data):
            self._command(frame, now)

    def poll(self, now):
        self._advance_to(now)
        if not self._out:
            return b""
        out = bytes(self._out)
        self._out.clear()
        return out

    def next_wakeup(self, now):
        return self._next_tick

    # --- fault injection and inspection ----------------------------------------------------------
    def inject_error(self, code):
        """Raise engine error ``code`` (number or appendix name) now."""
        self._fault(_error_code(code))

    def set_silent(self, silent=True):
        """Stop (or resume) transmitting status frames; the model keeps running."""
        self.silent = bool(silent)
        if not silent:
            self.silent_after = None

    def set_corrupt_every(self, n):
        """Damage every ``n``th status frame (0: none)."""
        self.corrupt_every = int(n)

    @property
    def rx_bad(self):
        """Candidate control frames dropped for a bad CRC."""
        return self._framer.bad

    @property
    def engine_state_name(self):
        return zk.ENGINE_STATES[self.state]

    @property
    def unlocked(self):
        return self._t < self.unlocked_until

    @property
    def rpm_mode(self):
        return self.version >= 4 and self.rpm_factor != 0

    def effective_sw(self):
        """The host's state command in force: ``stop``, ``standby`` or ``run``."""
        sw = self.mode_sw if self.version >= 4 and self.mode_sw else self.id1_sw
        return {0: "stop", 1: "stop", 2: "standby", 3: "run"}[sw]   # pwm input reads stop

    def target_rpm(self):
        if self.rpm_mode:
            target = self.rpm_value * 10 * self.rpm_factor
        else:
            target = self.idle_rpm + (self.max_rpm - self.idle_rpm) * self.throttle / 100.0
        return min(max(target, self.idle_rpm), self.max_rpm)

    def values(self):
        """The physical values the status frames carry now, by status key."""
        span = self.max_rpm - self.idle_rpm
        if self.rpm_mode:
            throttle = (self.target_rpm() - self.idle_rpm) / span * 100.0
        else:
            throttle = self.throttle
        thrust = self.max_thrust * (self.rpm / self.max_rpm) ** 2 * self.pressure_hpa / 1013.0
        return {
            "rpm": self.rpm, "engine_state": self.state, "error_code": self.error_code,
            "egt_c": self.egt, "sw_state": SW_CODE[self.effective_sw()],
            "radio_voltage_v": 5.0, "power_voltage_v": self.battery - 0.03 * self.current,
            "pump_voltage_v": self.pump_v,
            "throttle_pct": throttle, "pressure_pa": self.pressure_hpa * 100,
            "current_a": self.current, "thrust_kg": max(thrust + self.thrust_offset, 0.0),
            "ignition_pump_voltage_v": self.ignition_pump_v, "curve_inc": self.curve_inc,
            "curve_dec": self.curve_dec,
            "max_rpm": self.max_rpm, "max_pump_voltage_v": self.max_pump_v,
            "protocol_version": self.version, "status_rate_hz": self.rate,
            "fuel_flow_l_min": self.fuel_flow, "fuel_used_l": self.fuel_used,
            "idle_rpm": self.idle_rpm, "esr": int(self.esr), "scl": int(self.rpm_mode),
            "startup_time_s": self.startup_time,
            "ecu_temp_c": self.ecu_temp, "prop_rpm": 0,
            "fuel_pump_rpm": self.pump_v * 800.0,
        }

    def status_frame(self, sid):
        """Encode status frame ``sid`` from the current model state (through the codec)."""
        vals = self.values()
        st = zk.STATUS_BY_ID[sid]
        out = {}
        for f in st.fields:
            if f.since > self.version:
                continue
            v = vals[f.key]
            if f.names is None and f.values is None:
                lo, hi, step = self._grid(sid, f)
                v = round((min(max(v, lo), hi) - f.offset) / step) * step + f.offset
            out[f.key] = v
        return zk.encode_status(sid, self.version, **out)

    def _grid(self, sid, f):
        """(low, high, step) of a field in physical units at this ECU's protocol version."""
        key = (sid, f.key)
        r = self._ranges.get(key)
        if r is None:
            ctx = {"version": self.version}
            r = self._ranges[key] = (*f.physical_range(ctx), f.scale_for(ctx))
        return r

    # --- commands ----------------------------------------------------------------------------------
    def _command(self, frame, now):
        rec = zk.decode_control(frame)
        self.received.append(rec)
        repeated = frame == self._last_frame and self._last_rx is not None \
            and now - self._last_rx <= LOSS_OF_SIGNAL_S
        self._last_frame = frame
        self._last_rx = now
        cid = rec["id"]
        if cid == 0:
            return
        if cid == 1:
            self.id1_sw, self.throttle = rec["sw"], rec["throttle_pct"]
        elif cid == 2:
            self._action(rec["param"], repeated)
        elif cid == 3:
            self.unlocked_until = now + UNLOCK_S
        elif cid in (4, 5):
            if not self.unlocked:
                self.rx_ignored += 1
            elif cid == 4:
                self.ignition_pump_v = rec["ignition_voltage_v"]
            else:
                self.curve_inc = rec["accel_curve"]
        elif cid in (6, 7):
            if self.version < 4:
                self.rx_ignored += 1
            elif cid == 6:
                self.mode_sw, self.rpm_factor = rec["sw"], rec["rpm_factor"]
            else:
                self.rpm_value = rec["rpm_value"]
        elif cid == 8:
            self.pressure_hpa = rec["pressure_hpa"]
            self.pressure_answers += 1
            self.esr = False
            if self.esr_again is not None:
                self._esr_at = now + self.esr_again
        if cid in (1, 6) and self.rearm and self.effective_sw() != "run":
            self.rearm = False
            self.error_code = 0

    def _action(self, param, repeated):
        if self.version < zk.ACTION_SINCE.get(param, 1):
            self.rx_ignored += 1
            return
        if param in RATE_BY_ACTION:
            if self.rate != RATE_BY_ACTION[param]:
                self.rate = RATE_BY_ACTION[param]
                self._schedule(min(self._next_tick, self._t + 1.0 / self.rate))
        elif param == 10:
            self.fuel_used = 0.0
        elif param == 11:
            self.thrust_offset = -self.max_thrust * (self.rpm / self.max_rpm) ** 2
        elif param == 12:
            self.pump_on = self.state in (0, 1)
        elif param == 13:
            self.pump_on = False
        elif param in TEST_ACTIONS:
            if repeated:
                return
            if self.state not in (0, 1) or self.effective_sw() == "run":
                self.rx_ignored += 1
                return
            self.state = TEST_ACTIONS[param]
            self._test_until = self._t + TEST_S[self.state]

    def _fault(self, code):
        self.error_code = code
        self.rearm = True
        self.pump_on = False
        if self.state != STATE["stop"] or self.rpm > 0:
            self.state = STATE["cooling"] if self.egt > COOL_DONE_C else STATE["stop"]

    # --- time --------------------------------------------------------------------------------------
    def _schedule(self, first):
        """Status ticks at ``first + n / rate`` (computed, not accumulated: no drift)."""
        self._tick_base = first
        self._tick_n = 0
        self._next_tick = first

    def _advance_to(self, now):
        period = 1.0 / self.rate
        if now - self._next_tick > MAX_BURST * period:
            self._integrate(now - MAX_BURST * period)
            self._schedule(now - (MAX_BURST - 1) * period)
        while self._next_tick <= now + 1e-9:
            self._integrate(self._next_tick)
            self._tick()
            self._tick_n += 1
            self._next_tick = self._tick_base + self._tick_n / self.rate
        self._integrate(now)

    def _tick(self):
        sid = self.ids[self._cycle % len(self.ids)]
        self._cycle += 1
        if self.silent_after is not None and self._t >= self.silent_after:
            self.silent = True
        if self.silent:
            return
        if self.baud is not None:
            if self._t < self._line_free - 1e-9:
                self.frames_skipped += 1      # the line is still busy with the frame before
                return
            self._line_free = self._t + wire_time(zk.STATUS_LEN, self.baud, self.stop_bits)
        frame = self.status_frame(sid)
        self.frames_sent += 1
        if self.corrupt_every and self.frames_sent % self.corrupt_every == 0:
            frame = frame[:3] + bytes((frame[3] ^ 0x01,)) + frame[4:]
        self._out += frame

    def _integrate(self, t):
        while self._t < t - 1e-12:
            dt = min(STEP_S, t - self._t)
            self._t += dt
            self._step(dt)

    def _step(self, dt):
        t = self._t
        if self._esr_at is not None and t >= self._esr_at:
            self._esr_at, self.esr = None, True
        if self._error_at is not None and t >= self._error_at[0]:
            code = self._error_at[1]
            self._error_at = None
            self._fault(code)
        if (self.version < 5 and self._last_rx is not None and t - self._last_rx > LOSS_OF_SIGNAL_S
                and self.error_code != 13):
            self._fault(13)
        self._transition(t)
        self._physics(dt)

    def _transition(self, t):
        s = self.state
        sw = self.effective_sw()
        if s in TEST_S:
            if t >= self._test_until:
                self.state = STATE["stop"]
            return
        if sw == "run" and not self.rearm:
            if s in (0, 1, 12):
                self.pump_on = False
                if self.egt > COOL_DONE_C:
                    self.state = STATE["restart"]
                else:
                    self._begin_start(t)
            elif s == STATE["restart"] and self.egt <= COOL_DONE_C:
                self._begin_start(t)
            elif s == STATE["ignition"] and t - self._phase_t0 >= IGNITION_S:
                self.state, self._phase_t0 = STATE["preheat"], t
            elif s == STATE["preheat"] and t - self._phase_t0 >= PREHEAT_S:
                self.state, self._phase_t0 = STATE["fuel-ramp"], t
            elif s == STATE["fuel-ramp"] and t - self._phase_t0 >= FUEL_RAMP_S:
                self.state = RUNNING
                self.startup_time = t - self._start_t0
            return
        # stop or standby (or an error latched): shut down
        if s == STATE["cooling"]:
            if self.egt <= COOL_DONE_C:
                self.state = STATE["standby"] if sw == "standby" else STATE["stop"]
            elif sw == "stop" and not self.rearm:
                self.state = STATE["stop"]
            return
        if sw == "standby":
            if s != STATE["standby"]:
                self.state = STATE["cooling"] if self.egt > COOL_DONE_C else STATE["standby"]
        elif s != STATE["stop"]:
            self.state = STATE["stop"]

    def _begin_start(self, t):
        self.state = STATE["ignition"]
        self._phase_t0 = self._start_t0 = t

    def _physics(self, dt):
        s = self.state
        span = self.max_rpm - self.idle_rpm
        amb = self.ambient
        flow = 0.0
        pump = 0.0
        current = 0.3
        phase = self._t - self._phase_t0
        if s == STATE["ignition"]:
            rpm_t, rpm_tau = STARTER_RPM * 1.6, 0.8
            lit = phase > IGNITION_S / 2
            egt_t, egt_tau = (180.0, 1.0) if lit else (self.egt, 1.0)
            flow, pump = (0.02, self.ignition_pump_v) if lit else (0.0, 0.0)
            current += 10.0 + 4.0
        elif s == STATE["preheat"]:
            rpm_t, rpm_tau = 15000.0, 1.0
            egt_t, egt_tau = 450.0, 1.2
            flow, pump = 0.05, 1.5
            current += 10.0
        elif s == STATE["fuel-ramp"]:
            frac = min(phase / FUEL_RAMP_S, 1.0)
            rpm_t, rpm_tau = 15000.0 + (self.idle_rpm - 15000.0) * frac, 0.5
            egt_t, egt_tau = 640.0, 1.0
            flow, pump = 0.05 + 0.07 * frac, 1.5 + 1.0 * frac
            current += 6.0 * (1 - frac)
        elif s == RUNNING:
            target = self.target_rpm()
            up = target >= self.rpm
            curve = self.curve_inc if up else self.curve_dec
            rpm_t, rpm_tau = target, (1.2 if up else 1.0) * 40.0 / max(curve, 1)
            f = (self.rpm - self.idle_rpm) / span
            accel = max(0.0, (target - self.rpm) / span)
            egt_t, egt_tau = 480.0 + 220.0 * f + 200.0 * accel, 1.0
            flow = 0.12 + 0.48 * max(f, 0.0) ** 1.3 + 0.2 * accel
            pump = min(self.max_pump_v, 1.0 + (self.max_pump_v - 1.0) * flow / 0.65)
        elif s in (STATE["cooling"], STATE["restart"]):
            rpm_t, rpm_tau = STARTER_RPM, 1.5
            egt_t, egt_tau = amb, 4.0
            current += 8.0
        elif s == STATE["test-starter"]:
            rpm_t, rpm_tau = STARTER_RPM, 0.8
            egt_t, egt_tau = amb, 25.0
            current += 10.0
        else:   # stop, standby, the other tests
            rpm_t, rpm_tau = 0.0, 2.0
            egt_t, egt_tau = amb, 25.0
            if s == STATE["test-glowplug"]:
                current += 4.0
            elif s in (STATE["test-main-valve"], STATE["test-ignition-valve"]):
                current += 0.5
            elif s == STATE["test-pump"]:
                flow, pump = 0.05, 3.0
            elif s == STATE["fuel-exhaust-air"]:
                flow, pump = 0.1, 4.0
            if self.pump_on and s in (0, 1):
                flow, pump = 0.08, 3.0
        self.rpm += (rpm_t - self.rpm) * (1.0 - math.exp(-dt / rpm_tau))
        if rpm_t == 0.0 and self.rpm < 1000.0:     # bearing friction stops a slow rotor
            self.rpm = 0.0
        self.egt += (egt_t - self.egt) * (1.0 - math.exp(-dt / egt_tau))
        load = max(0.0, (self.rpm - self.idle_rpm) / span) if s == RUNNING else 0.0
        ecu_t = amb + 10.0 + 15.0 * load
        self.ecu_temp += (ecu_t - self.ecu_temp) * (1.0 - math.exp(-dt / 60.0))
        self.fuel_flow = flow
        self.fuel_used += flow * dt / 60.0
        self.pump_v = pump
        self.current = current + 0.4 * pump


def _error_code(value):
    if isinstance(value, str):
        text = value.strip().lower()
        for code, name in zk.ERRORS.items():
            if name == text:
                return code
        try:
            value = int(text, 0)
        except ValueError:
            raise InvalidValue(f"error={value}: not an ECU error code or name; allowed 1..18 or a name: "
                             f"{', '.join(n for c, n in zk.ERRORS.items() if c)}") from None
    if not isinstance(value, int) or not 1 <= value <= 31:
        raise InvalidValue(f"error={value!r} is out of range; allowed 1..31 (18 documented)")
    return value


def _num(kind, lo=None, hi=None):
    def conv(key, v):
        if kind is float:
            return parse_number(key, v, lo, hi)
        try:
            return kind(v) if not isinstance(v, str) else int(v, 0)
        except (TypeError, ValueError):
            raise InvalidValue(f"{key}: {v!r} is not an integer") from None
    return conv


_INT = _num(int)
OPTIONS = {
    "protocol_version": _INT, "rate": _INT, "max_rpm": _INT, "idle_rpm": _INT,
    "max_thrust": _num(float, 0, 1000), "ambient": _num(float, -60, 100), "battery": _num(float, 0, 51),
    "max_pump_voltage": _num(float, 0, 51), "esr": parse_flag, "esr_again": _num(float, 0, 1e6), "baud": _INT,
    "stop_bits": _INT,
    "corrupt_every": _INT,
    "silent_after": _num(float, 0, 1e6), "error": lambda k, v: v, "error_after": _num(float, 0, 1e6),
}
#: Options accepted and handled elsewhere: ``speed`` scales the Clock that drives the device.
PASSED_THROUGH = {"speed"}


def from_options(**options) -> ZkEcu:
    """A :class:`ZkEcu` from string (or typed) options, as ``sim://zk?...`` and ``zkzap sim zk``
    give them. None values are ignored; unknown names raise InvalidValue (a ValueError) naming them.

    ``protocol_version`` (default 6), ``rate`` (20/50/100 Hz, default 20), ``max_rpm`` (160000),
    ``idle_rpm`` (40000), ``max_thrust`` (kg at max rpm, 14), ``ambient`` (degC, 20), ``battery``
    (V, 12), ``max_pump_voltage`` (V, 10), ``esr`` (0/1: ask for air pressure), ``esr_again`` (ask again
    S seconds after each answer), ``baud`` (the
    ECU's UART speed; unset: the host's), ``stop_bits`` (1 or 2), and the faults
    ``corrupt_every``, ``silent_after``, ``error``, ``error_after``. ``speed`` is accepted (it belongs to the clock).
    """
    options = {k.replace("-", "_"): v for k, v in options.items() if v is not None}
    unknown = sorted(set(options) - set(OPTIONS) - PASSED_THROUGH)
    if len(unknown) == 1:
        raise unknown_name("zk simulator", unknown[0], sorted(set(OPTIONS) | PASSED_THROUGH), noun="option",
                           otherwise="; allowed " + ", ".join(sorted(set(OPTIONS) | PASSED_THROUGH)))
    if unknown:
        raise InvalidValue(f"zk simulator: unknown option{'s' if len(unknown) > 1 else ''} "
                         f"{', '.join(unknown)}; allowed {', '.join(sorted(set(OPTIONS) | PASSED_THROUGH))}")
    kw = {k: OPTIONS[k](k, v) for k, v in options.items() if k in OPTIONS}
    if "error" in kw:
        kw["error"] = _error_code(kw["error"])
    return ZkEcu(**kw)
