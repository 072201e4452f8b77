"""pyserial URL handler for ``sim://KIND?option=value&...``: a simulator running in-process.

``KIND`` is ``zk`` (the ECU) or ``zap`` (the actuator bus); the query carries the simulator's
options (``speed`` scales its clock). Reads advance the simulation; writes are delivered to it
immediately with the port's baud rate (and stop bits, for a device with line settings of its
own: what either side sends at other settings arrives misframed, see :mod:`zkzap.sim.uart`). pyserial finds this module through
``serial.protocol_handler_packages`` (see :func:`zkzap.link.port.open_port`).
"""

from __future__ import annotations

import time
from urllib.parse import parse_qsl, urlsplit

import serial
from serial.serialutil import PortNotOpenError, SerialBase, SerialException

from ..sim import make_device
from ..errors import InvalidValue
from ..sim.base import Clock, VirtualClock, keep_wire_time, parse_number


class Serial(SerialBase):
    """A serial port whose other end is a simulated device."""

    def open(self):
        if self._port is None:
            raise SerialException("port must be configured before it can be used")
        if self.is_open:
            raise SerialException("port already open")
        kind, options = self.from_url(self._port)
        self._shared = "instance" in options
        if self._shared:                # a simulator started from Python (zkzap.sim.start)
            from ..sim import INSTANCES

            found = INSTANCES.get(options["instance"])
            if found is None:
                raise SerialException(f"sim://{kind}: no running simulator instance {options['instance']!r}")
            self._device, self._clock = found
        else:
            try:
                kind_of_clock = options.pop("clock", "real")
                if kind_of_clock not in ("real", "virtual"):
                    raise ValueError(f"clock: {kind_of_clock!r}; allowed real, virtual")
                speed = parse_number("speed", options.pop("speed", "1"), 0.001, 10000)
                self._clock = VirtualClock() if kind_of_clock == "virtual" else Clock(speed)
                self._device = keep_wire_time(make_device(kind, **options), self._clock)
            except (TypeError, ValueError) as e:
                # bad input (exit 2 naming the option), not a port failure
                raise InvalidValue(f"sim://{kind}: {e}") from None
        self._rx = bytearray()
        self.is_open = True

    @staticmethod
    def from_url(url):
        parts = urlsplit(url)
        if parts.scheme != "sim":
            raise SerialException(f"expected a URL of the form sim://zk or sim://zap?ids=1,2, got {url!r}")
        return parts.netloc or parts.path.strip("/"), dict(parse_qsl(parts.query))

    def _reconfigure_port(self):
        pass

    def close(self):
        if self.is_open:
            self.is_open = False
            if not self._shared:        # a shared instance belongs to its starter
                self._device.close()

    def _pump(self):
        out = self._device.poll_line(self._clock.now(), self._baudrate)
        if out:
            line = getattr(self._device, "line", None)
            if line is not None:       # the device's UART settings against this port's
                out = line.to_host(out, self._baudrate, int(self._stopbits))
            self._rx += out

    @property
    def in_waiting(self):
        if not self.is_open:
            raise PortNotOpenError()
        self._pump()
        return len(self._rx)

    def read(self, size=1):
        if not self.is_open:
            raise PortNotOpenError()
        if self._clock.virtual:
            return self._read_virtual(size)
        deadline = None if self._timeout is None else time.monotonic() + self._timeout
        while True:
            self._pump()
            if len(self._rx) >= size:
                break
            now = time.monotonic()
            if deadline is not None and now >= deadline:
                break
            wake = self._device.next_wakeup(self._clock.now())
            delay = 0.02 if wake is None else self._clock.real_delay(wake - self._clock.now())
            if deadline is not None:
                delay = min(delay, deadline - now)
            time.sleep(max(delay, 0.0005))
        data = bytes(self._rx[:size])
        del self._rx[:size]
        return data

    def _read_virtual(self, size):
        """On a virtual clock: what is there, else the clock moves on to the device's next byte
        (or the timeout) and what came by then; returns as soon as any byte is there."""
        clock = self._clock
        end = clock.now() + (1.0 if self._timeout is None else max(0.0, self._timeout))
        while True:
            self._pump()
            now = clock.now()
            if self._rx or now >= end:
                break
            wake = self._device.next_wakeup(now)
            clock.advance((end if wake is None or wake > end else wake) - now)
        data = bytes(self._rx[:size])
        del self._rx[:size]
        return data

    def write(self, data):
        if not self.is_open:
            raise PortNotOpenError()
        data = serial.to_bytes(data)
        if getattr(self._device, "line", None) is not None:
            self._device.receive(data, self._clock.now(), self._baudrate, int(self._stopbits))
        else:
            self._device.receive(data, self._clock.now(), self._baudrate)
        return len(data)

    def reset_input_buffer(self):
        if not self.is_open:
            raise PortNotOpenError()
        self._pump()
        self._rx.clear()

    def reset_output_buffer(self):
        if not self.is_open:
            raise PortNotOpenError()

    def flush(self):
        pass

    @property
    def device(self):
        """The simulated device (for tests and fault injection)."""
        return self._device

    @property
    def clock(self):
        """The simulation's model clock (``speed`` times real time): sessions on this port run
        their schedules, durations and rates in model time, as the device does."""
        return self._clock

    # modem lines: a simulator has none worth modelling
    def _update_rts_state(self):
        pass

    def _update_dtr_state(self):
        pass

    def _update_break_state(self):
        pass

    @property
    def cts(self):
        return True

    @property
    def dsr(self):
        return True

    @property
    def ri(self):
        return False

    @property
    def cd(self):
        return True
