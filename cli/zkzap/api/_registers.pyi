"""An Actuator's registers as typed attributes, for type checkers only.

Written by `python -m zkzap.docs all` from the register table (zkzap.codec.zap.REGISTERS):
do not edit. Registers with a unit read as a Reading; read-only ones have no setter.
"""

from .zap import Reading


class RegisterAttributes:
    """The registers of the 12Lf data map, named as in ``zap registers`` with underscores."""

    @property
    def model_number(self) -> int:
        """0x00 model-number (read-only, 2 bytes)"""

    @property
    def firmware_version(self) -> int:
        """0x02 firmware-version (read-only, 1 byte)"""

    @property
    def id(self) -> int:
        """0x03 id (stored, 1 byte)"""
    @id.setter
    def id(self, value: int) -> None: ...

    @property
    def baud_rate(self) -> int:
        """0x04 baud-rate (stored, 1 byte)"""
    @baud_rate.setter
    def baud_rate(self, value: int) -> None: ...

    @property
    def short_stroke_limit(self) -> int:
        """0x06 short-stroke-limit (stored, 2 bytes)"""
    @short_stroke_limit.setter
    def short_stroke_limit(self, value: int) -> None: ...

    @property
    def long_stroke_limit(self) -> int:
        """0x08 long-stroke-limit (stored, 2 bytes)"""
    @long_stroke_limit.setter
    def long_stroke_limit(self, value: int) -> None: ...

    @property
    def protocol_type(self) -> int:
        """0x0A protocol-type (stored, 1 byte)"""
    @protocol_type.setter
    def protocol_type(self, value: int) -> None: ...

    @property
    def lowest_limit_voltage(self) -> Reading:
        """0x0C lowest-limit-voltage (read-only, 1 byte) 0.1 V"""

    @property
    def highest_limit_voltage(self) -> Reading:
        """0x0D highest-limit-voltage (read-only, 1 byte) 0.1 V"""

    @property
    def motor_operating_rate_limit(self) -> int:
        """0x0E motor-operating-rate-limit (stored, 2 bytes)"""
    @motor_operating_rate_limit.setter
    def motor_operating_rate_limit(self, value: int) -> None: ...

    @property
    def feedback_return_mode(self) -> int:
        """0x10 feedback-return-mode (stored, 1 byte)"""
    @feedback_return_mode.setter
    def feedback_return_mode(self, value: int) -> None: ...

    @property
    def alarm_led(self) -> int:
        """0x11 alarm-led (stored, 1 byte)"""
    @alarm_led.setter
    def alarm_led(self, value: int) -> None: ...

    @property
    def alarm_shutdown(self) -> int:
        """0x12 alarm-shutdown (stored, 1 byte)"""
    @alarm_shutdown.setter
    def alarm_shutdown(self, value: int) -> None: ...

    @property
    def start_compliance_margin(self) -> int:
        """0x13 start-compliance-margin (stored, 1 byte)"""
    @start_compliance_margin.setter
    def start_compliance_margin(self, value: int) -> None: ...

    @property
    def end_compliance_margin(self) -> int:
        """0x14 end-compliance-margin (stored, 1 byte)"""
    @end_compliance_margin.setter
    def end_compliance_margin(self, value: int) -> None: ...

    @property
    def speed_limit(self) -> int:
        """0x15 speed-limit (stored, 2 bytes)"""
    @speed_limit.setter
    def speed_limit(self, value: int) -> None: ...

    @property
    def calibration_short_stroke(self) -> int:
        """0x18 calibration-short-stroke (read-only, 2 bytes)"""

    @property
    def calibration_long_stroke(self) -> int:
        """0x1A calibration-long-stroke (read-only, 2 bytes)"""

    @property
    def acceleration(self) -> int:
        """0x21 acceleration (stored, 1 byte)"""
    @acceleration.setter
    def acceleration(self, value: int) -> None: ...

    @property
    def deceleration(self) -> int:
        """0x22 deceleration (stored, 1 byte)"""
    @deceleration.setter
    def deceleration(self, value: int) -> None: ...

    @property
    def current_i_gain(self) -> int:
        """0x23 current-i-gain (stored, 1 byte)"""
    @current_i_gain.setter
    def current_i_gain(self, value: int) -> None: ...

    @property
    def current_p_gain(self) -> int:
        """0x24 current-p-gain (stored, 1 byte)"""
    @current_p_gain.setter
    def current_p_gain(self, value: int) -> None: ...

    @property
    def speed_d_gain(self) -> int:
        """0x25 speed-d-gain (stored, 1 byte)"""
    @speed_d_gain.setter
    def speed_d_gain(self, value: int) -> None: ...

    @property
    def speed_i_gain(self) -> int:
        """0x26 speed-i-gain (stored, 1 byte)"""
    @speed_i_gain.setter
    def speed_i_gain(self, value: int) -> None: ...

    @property
    def speed_p_gain(self) -> int:
        """0x27 speed-p-gain (stored, 1 byte)"""
    @speed_p_gain.setter
    def speed_p_gain(self, value: int) -> None: ...

    @property
    def min_position_calibration(self) -> int:
        """0x2E min-position-calibration (stored, 1 byte)"""
    @min_position_calibration.setter
    def min_position_calibration(self, value: int) -> None: ...

    @property
    def max_position_calibration(self) -> int:
        """0x2F max-position-calibration (stored, 1 byte)"""
    @max_position_calibration.setter
    def max_position_calibration(self, value: int) -> None: ...

    @property
    def current_limit(self) -> Reading:
        """0x34 current-limit (stored, 2 bytes) mA"""
    @current_limit.setter
    def current_limit(self, value: int | Reading) -> None: ...

    @property
    def force_on_off(self) -> int:
        """0x80 force-on-off (volatile, 1 byte)"""
    @force_on_off.setter
    def force_on_off(self, value: int) -> None: ...

    @property
    def led(self) -> int:
        """0x81 led (volatile, 1 byte)"""
    @led.setter
    def led(self, value: int) -> None: ...

    @property
    def goal_position(self) -> int:
        """0x86 goal-position (volatile, 2 bytes)"""
    @goal_position.setter
    def goal_position(self, value: int) -> None: ...

    @property
    def goal_speed(self) -> int:
        """0x88 goal-speed (volatile, 2 bytes)"""
    @goal_speed.setter
    def goal_speed(self, value: int) -> None: ...

    @property
    def goal_current(self) -> Reading:
        """0x8A goal-current (volatile, 2 bytes) mA"""
    @goal_current.setter
    def goal_current(self, value: int | Reading) -> None: ...

    @property
    def present_position(self) -> int:
        """0x8C present-position (read-only, 2 bytes)"""

    @property
    def present_current(self) -> Reading:
        """0x8E present-current (read-only, 2 bytes) mA"""

    @property
    def present_motor_operating_rate(self) -> int:
        """0x90 present-motor-operating-rate (read-only, 2 bytes)"""

    @property
    def present_voltage(self) -> Reading:
        """0x92 present-voltage (read-only, 1 byte) 0.1 V"""

    @property
    def moving(self) -> int:
        """0x96 moving (read-only, 1 byte)"""
