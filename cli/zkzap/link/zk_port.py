"""The port to a ZK ECU: :class:`ZkLink` reads whatever arrived within a short slice (kept
byte for byte in a raw log when asked) and writes control frames; a port failure is
:class:`~zkzap.errors.PortError`.

Link-level I/O only: the frame sources are in :mod:`zkzap.link.zk_sources`, the decoding,
telemetry and session loop in :mod:`zkzap.api.telemetry` and :mod:`zkzap.api.session`. Nothing
here imports click or rich; pyserial is imported by :func:`zkzap.link.port.open_port`.
"""

from __future__ import annotations

from ..codec.permissions import Permission, as_permission
from ..errors import ZkzapError
from . import stop

#: Longest a read blocks, so control frames go out on time and signals are seen promptly.
READ_SLICE_S = 0.01
#: Bytes asked for in one read (of a port or a raw log).
READ_SIZE = 4096


def is_simulator(url: str) -> bool:
    """True for the in-process simulator (``sim://``): no consent needed there."""
    return url.startswith("sim://")


class ZkLink:
    """A port to a ZK ECU. :meth:`read` returns the bytes that arrived within a short slice
    (``b""`` if none) and appends them to the raw log; :meth:`write` sends a frame, only when
    the permissions it needs (:meth:`zkzap.codec.zk.ControlFrame.needs`) are :attr:`allow`'s or
    waived by the simulator (:class:`~zkzap.errors.PermissionNeeded` otherwise, nothing sent).
    :attr:`controlled` says whether a frame that controls the engine went out."""

    def __init__(self, ser, url, raw_log=None, baud=None, slice_s=READ_SLICE_S, stop_bits=1, allow=None):
        self.ser = ser
        self.url = url
        self._cleared = {}                # frame -> whether it controls the engine (permitted)
        self.allow = as_permission(allow)
        self.controlled = False
        self._parent = None
        self.raw_log = raw_log
        self.baud = baud if baud is not None else getattr(ser, "baudrate", None)
        self.slice_s = slice_s
        self.stop_bits = stop_bits
        self.bytes_in = 0
        self.frames_out = 0

    @classmethod
    def open(cls, url, baud, raw_log=None, slice_s=READ_SLICE_S, stop_bits=1, allow=None):
        """Open ``url`` at ``baud`` (inside a batch: borrow the batch's one open port);
        ``allow``: the permissions its frames are given."""
        from .port import open_port
        from .shared import shared

        lent = shared("zk")
        if lent is not None:        # a batch: the one open port, left open by close()
            from .. import checking

            checking.effect("port", url=url)
            link = lent.borrow(raw_log, slice_s)
            link.allow = as_permission(allow)
            return link
        ser = open_port(url, baud, timeout=slice_s, write_timeout=1.0, stop_bits=stop_bits)
        return cls(ser, url, raw_log, baud, slice_s, stop_bits, allow)

    def reopen(self, within: float | None = None) -> None:
        """Close the failed port and open the same device again (PortError while it is absent).
        ``within``: real seconds the attempt may take at most (an open that hangs, such as a TCP
        connect to a server that does not answer, which pyserial gives 5 s, is given up then:
        PortError; it is left to end in its thread, and a port it opens after all is closed)."""
        from .port import close_port, open_port, open_within

        close_port(self.ser)
        kw = dict(timeout=self.slice_s, write_timeout=1.0, stop_bits=self.stop_bits)
        if within is None:
            self.ser = open_port(self.url, self.baud, **kw)
        else:
            self.ser = open_within(within, self.url, self.baud, **kw)

    def borrow(self, raw_log=None, slice_s=READ_SLICE_S):
        """A link over this one's port for one command; its close() leaves the port open."""
        self.ser.timeout = slice_s
        link = ZkLink(self.ser, self.url, raw_log, slice_s=slice_s)
        link.close = lambda: None
        link._parent = self
        return link

    def set_slice(self, slice_s: float) -> None:
        """Block at most ``slice_s`` real seconds in a read."""
        if slice_s != self.slice_s:
            self.slice_s = slice_s
            self.ser.timeout = slice_s

    @property
    def device(self):
        """The simulated device behind a ``sim://`` port (None otherwise)."""
        return getattr(self.ser, "device", None)

    def read(self) -> bytes:
        """The bytes that arrived within one slice (``b""`` if none); a failure is PortError."""
        try:
            data = self.ser.read(READ_SIZE)
        except ZkzapError:       # a capture that cannot be written (exit 7)
            raise
        except Exception as e:   # SerialException, OSError, and whatever a URL handler raises
            raise port_failed(self.url, e) from None
        if data:
            self.bytes_in += len(data)
            if self.raw_log is not None:
                self.raw_log.write(data)
                self.raw_log.flush()
        return data

    def authorize(self, frame: bytes) -> bool:
        """Raise :class:`~zkzap.errors.PermissionNeeded` unless ``frame`` may be sent; returns
        whether it controls the engine."""
        controls = self._cleared.get(frame)
        if controls is None:
            from ..codec import zk
            from ..codec.permissions import require

            cf = zk.ControlFrame(frame)
            needs = cf.needs()
            if needs:
                require(needs, self.allow, simulated=is_simulator(self.url), what=f"{cf.frame.hex(' ').upper()} "
                        f"({cf.command.name if cf.command else 'undefined ID'})", frame=frame)
            controls = cf.controls_engine
            if len(self._cleared) < 4096:
                self._cleared[bytes(frame)] = controls
        return controls

    @property
    def allow(self) -> Permission:
        """The permissions this link's frames are given."""
        return self._allow

    @allow.setter
    def allow(self, value) -> None:
        self._allow = as_permission(value)
        self._cleared = {}

    def write(self, frame: bytes) -> None:
        """Send ``frame`` and wait until it is out; a failure is PortError."""
        stop.check()                 # a stop requested (a batch's Ctrl-C) ends the command here
        controls = self.authorize(frame)
        try:
            self.ser.write(frame)
            self.ser.flush()
        except ZkzapError:
            raise
        except Exception as e:
            raise port_failed(self.url, e) from None
        self.frames_out += 1
        if controls and not self.controlled:
            self.controlled = True
            if self._parent is not None:
                self._parent.controlled = True      # a batch's port: a line took control

    def close(self):
        """Close the port."""
        from .port import close_port

        close_port(self.ser)


def port_failed(url, e):
    """The :class:`~zkzap.errors.PortError` for a failure ``e`` of the port ``url``."""
    from .port import port_failed as failed

    return failed(url, e)
