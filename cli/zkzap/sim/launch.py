"""Start a simulator from Python with typed arguments and get its URL.

>>> from zkzap.sim import start_zap
>>> with start_zap(ids=[1, 2], return_mode=2) as sim:      # doctest: +SKIP
...     with Bus(sim) as bus:                                # or Bus(sim.url)
...         bus[1].goal_position = 2000

Transports: ``"inprocess"`` (default: a ``sim://KIND?instance=N`` URL that any zkzap port in
this process opens; the fastest, no threads), ``"pty"`` (a pseudo-terminal, path in ``url``)
and ``"tcp"`` (``socket://127.0.0.1:PORT``). The pty and TCP servers run on a background
thread of this process, so other processes (``zap``, ``zk``, any serial tool) can talk to them
until :meth:`Simulator.close`. ``device`` is the simulated device itself
(:class:`~zkzap.sim.zk_ecu.ZkEcu` or :class:`~zkzap.sim.zap_actuators.ActuatorBus`) for
inspection and fault injection; with a server thread running, do that under ``lock``.
"""

from __future__ import annotations

import itertools
import os
import threading
TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Callable, Iterable, Literal, Optional, Sequence, Union

    from typing_extensions import Self, TypeAlias

    #: How a simulator is served: in this process (a sim:// URL), on a pty or on TCP.
    Transport: TypeAlias = Literal["inprocess", "pty", "tcp"]
    #: A capture file to replay.
    CapturePath: TypeAlias = Union[str, os.PathLike[str]]
    #: A fault of the actuator-bus simulator: ``"[ID:]KIND[=VALUE][/COUNT]"`` or
    #: ``(id or None, kind, value, count)``.
    Fault: TypeAlias = Union[str, tuple[Optional[int], str, Optional[float], Optional[int]]]

from . import INSTANCES
from ..errors import InvalidValue
from .base import Clock, VirtualClock, keep_wire_time

__all__ = ["Simulator", "start", "start_zk", "start_zap"]

TRANSPORTS = ("inprocess", "pty", "tcp")
_keys = itertools.count(1)


class Simulator:
    """A running simulator: ``kind`` (``zk``/``zap``), ``url`` (what to open), ``transport``,
    ``device``, ``clock`` (model time) and ``lock``. A context manager; :meth:`close` stops it."""

    url: str
    """What to open: ``sim://KIND?instance=N``, the pty's path or ``socket://127.0.0.1:PORT``."""
    device: Any
    """The simulated device (:class:`~zkzap.sim.zk_ecu.ZkEcu`,
    :class:`~zkzap.sim.zap_actuators.ActuatorBus` or a replay), for inspection and fault
    injection."""

    def __init__(self, kind: str, device: Any, clock: Clock, transport: Transport = "inprocess",
                 host: str = "127.0.0.1", port: int = 0) -> None:
        if transport not in TRANSPORTS:
            raise InvalidValue(f"transport: {transport!r}; allowed {', '.join(TRANSPORTS)}")
        self.kind = kind
        self.device = device
        self.clock = clock
        self.transport = transport
        self.lock = threading.RLock()
        self.key = str(next(_keys))
        self._stop = None
        self._thread = None
        self._closed = False
        INSTANCES[self.key] = (device, clock)
        if transport == "inprocess":
            self.url = f"sim://{kind}?instance={self.key}"
        else:
            self._wake_r, self._wake_w = os.pipe()
            ready = threading.Event()
            self._thread = threading.Thread(target=self._serve, args=(ready, host, port), daemon=True,
                                            name=f"zkzap-sim-{kind}-{transport}")
            self._error = None
            self._thread.start()
            ready.wait(10)
            if self._error is not None:
                raise self._error

    def __repr__(self) -> str:
        return f"Simulator({self.kind!r}, url={self.url!r})"

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the simulator (its server thread, if any) and release the device."""
        if self._closed:
            return
        self._closed = True
        if self._thread is not None:
            os.write(self._wake_w, b"x")
            self._thread.join(5)
            os.close(self._wake_r)
            os.close(self._wake_w)
        INSTANCES.pop(self.key, None)
        with self.lock:
            self.device.close()

    def inject(self, *args: Any, **kw: Any) -> Any:
        """Inject a fault (the device's ``inject``/``inject_error``), under :attr:`lock`."""
        with self.lock:
            fn = getattr(self.device, "inject", None) or getattr(self.device, "inject_error")
            return fn(*args, **kw)

    # -- servers --------------------------------------------------------------------------------

    def _serve(self, ready: threading.Event, host: str, port: int) -> None:
        """The server thread: :func:`zkzap.sim.serve.run_pty` or ``run_tcp`` until :meth:`close`."""
        from .serve import run_pty, run_tcp

        def announced(url):
            self.url = url
            ready.set()

        try:
            if self.transport == "pty":
                run_pty(self.device, self.clock, announced, stop_fd=self._wake_r, lock=self.lock)
            else:
                run_tcp(self.device, self.clock, announced, host=host, port=port, stop_fd=self._wake_r,
                        lock=self.lock)
        except Exception as e:  # noqa: BLE001 - no pty, a port in use: raised by the starter
            if not ready.is_set():
                self._error = e
                ready.set()
            else:
                raise


def start_zk(*, protocol_version: int = 6, rate: int = 20, speed: float = 1.0, max_rpm: int = 160000,
             idle_rpm: int = 40000, max_thrust: float = 14.0, ambient: float = 20.0, battery: float = 12.0,
             max_pump_voltage: float = 10.0, esr: bool = False, baud: Optional[int] = None,
             stop_bits: int = 1, corrupt_every: int = 0, silent_after: Optional[float] = None, error: Union[int, str, None] = None,
             error_after: float = 0.0, transport: Transport = "inprocess", host: str = "127.0.0.1",
             port: int = 0, replay: Optional[CapturePath] = None, loop: bool = False,
             on_control: Optional[Callable[[dict[str, Any]], None]] = None) -> Simulator:
    """Start the ECU simulator (a :class:`~zkzap.sim.zk_ecu.ZkEcu`): ``protocol_version``,
    status ``rate`` (20/50/100 Hz), ``speed`` (model time runs this many times faster), engine
    figures, the line settings of its UART (``baud``, ``stop_bits`` 1 or 2, 8 data bits, no
    parity, as ``zkzap sim zk --baud --stop-bits``: a host at another setting reads garbage;
    without ``baud`` the ECU follows the host's settings), and faults (``corrupt_every`` Nth
    frame, ``silent_after`` s, ``error`` code at ``error_after`` s). InvalidValue names a bad
    argument.

    ``replay`` (the path of a zkzap ZK capture) plays a recorded session instead, as ``zkzap sim
    zk --replay``: the ECU's status frames at their recorded times (``speed`` scales them),
    once or, with ``loop``, again and again; the engine, line and fault arguments do not apply.
    The control frames the host sends meanwhile go to ``on_control`` as decoded records.
    :class:`~zkzap.link.pcapng.CaptureError` (a :class:`~zkzap.errors.UsageError`) for a
    file that is not such a capture; InvalidValue for one without a status frame."""
    if replay is not None:
        from ..link.pcapng import check_capture
        from .replay import ZkReplay

        path = os.fspath(replay)
        check_capture(path, "zk")
        return Simulator("zk", ZkReplay(path, loop=bool(loop), log=on_control), Clock(speed), transport,
                         host, port)
    if loop or on_control is not None:
        raise InvalidValue("loop, on_control: only with replay")
    from .zk_ecu import ZkEcu

    if isinstance(stop_bits, bool) or stop_bits not in (1, 2):
        raise InvalidValue(f"stop_bits: {stop_bits!r}; allowed 1, 2")
    device = ZkEcu(protocol_version=protocol_version, rate=rate, max_rpm=max_rpm, idle_rpm=idle_rpm,
                   max_thrust=max_thrust, ambient=ambient, battery=battery, max_pump_voltage=max_pump_voltage,
                   esr=esr, baud=baud, stop_bits=int(stop_bits), corrupt_every=corrupt_every, silent_after=silent_after,
                   error=error, error_after=error_after)
    return Simulator("zk", device, Clock(speed), transport, host, port)


def start_zap(*, ids: Union[Iterable[Union[int, tuple[int, int]]], str, None] = None, baud: int = 57600,
              return_mode: Optional[Literal[0, 1, 2]] = None, echo: bool = False, voltage: Optional[float] = None,
              faults: Sequence[Fault] = (), state: Optional[str] = None, turnaround: Optional[float] = None,
              gap: Optional[float] = None, speed: float = 1.0, transport: Transport = "inprocess",
              host: str = "127.0.0.1", port: int = 0, replay: Optional[CapturePath] = None,
              protocol: Literal["ir", "modbus"] = "ir", virtual: bool = False) -> Simulator:
    """Start the actuator-bus simulator (an :class:`~zkzap.sim.zap_actuators.ActuatorBus`):
    actuators with ``ids`` (integers, or ``(id, baud)`` pairs for one at another rate; default
    ID 0, or with ``replay`` the IDs that answered in the capture) at
    ``baud``, every one in feedback-return-mode ``return_mode`` (None: the factory 1), an
    adapter that echoes (``echo``), a supply ``voltage``, ``faults`` as ``(id or None, kind,
    value, count)`` tuples or ``[ID:]KIND[=VALUE][/COUNT]`` strings, ``state`` (a JSON file
    keeping stored registers across runs), the reply timing — ``turnaround`` (milliseconds from
    a command's last byte to the reply's first, 0..1000, default 2) and ``gap`` (milliseconds
    between two reply bytes, 0..100, default 0), as ``zkzap sim zap --turnaround --gap``.
    ``virtual`` (in-process only): its model time passes only while the host waits
    (:class:`~zkzap.sim.base.VirtualClock`), and a :class:`zkzap.Bus` on it reads that clock:
    a window that closes in silence costs no real time, and every run is the same.
    InvalidValue (a UsageError and a ValueError) names a bad argument.

    ``replay`` (the path of a zkzap mightyZAP capture) answers as recorded, as ``zkzap sim zap
    --replay``: a request recorded in the capture (the same bytes) gets the reply recorded for
    it after the recorded latency (several in turn, then the last again; none when none was
    recorded: a silent actuator is reproduced); other requests go to the simulated bus, whose
    actuators are then the IDs that answered in the capture unless ``ids`` are given.
    :class:`~zkzap.link.pcapng.CaptureError` (a :class:`~zkzap.errors.UsageError`) for a
    file that is not such a capture.

    ``protocol="modbus"``: 17Lf actuators speaking Modbus RTU (:mod:`zkzap.sim.zap_modbus`;
    IDs 1..247, default 1; no return mode, no replay)."""
    from ..codec import zap
    from .zap_actuators import TURNAROUND, ActuatorBus, _millis, parse_ids

    if protocol not in ("ir", "modbus"):
        raise InvalidValue(f"protocol: {protocol!r}; allowed ir, modbus")
    if protocol == "modbus" and (replay is not None or return_mode is not None):
        raise InvalidValue("protocol modbus: a 17Lf has no return mode, and captures are of the IR protocol")

    recorded = None
    if replay is not None:
        from ..link.pcapng import check_capture
        from .replay import recorded_replies

        replay = os.fspath(replay)
        check_capture(replay, "zap")
        recorded = recorded_replies(replay)
        if ids is None and recorded[1]:
            ids = sorted(recorded[1])
    if ids is None:
        ids = (0,) if protocol == "ir" else (1,)
    if baud not in zap.BAUD_TO_CODE:
        raise InvalidValue(f"baud: {baud}; allowed {', '.join(str(v) for v in sorted(zap.BAUD_TO_CODE))}")
    if isinstance(ids, str):
        pairs = parse_ids(ids)
    else:
        pairs = [(i, None) if isinstance(i, int) else (int(i[0]), int(i[1])) for i in ids]
    for ident, _ in pairs:
        if protocol == "modbus":
            from ..codec import modbus

            modbus.check_id(ident, allow_broadcast=False)
        else:
            zap.check_id(ident, allow_broadcast=False)
    timing = {}
    for key, value, top, default in (("turnaround", turnaround, 1000.0, TURNAROUND), ("gap", gap, 100.0, 0.0)):
        if isinstance(value, bool):
            raise InvalidValue(f"{key}: {value!r} is not a number of milliseconds")
        timing[key] = default if value is None else _millis(key, value, top)
    if protocol == "modbus":
        from .zap_modbus import ModbusActuatorBus as ActuatorBus  # noqa: N814 - the protocol's bus
    bus = ActuatorBus([], state_path=state, echo=bool(echo), **timing)
    if not (state and bus.load_state()):
        bus.actuators = [bus.actuator_class(n, ident, b or baud) for n, (ident, b) in enumerate(pairs)]
        if return_mode is not None:
            if return_mode not in (0, 1, 2):
                raise InvalidValue(f"return_mode: {return_mode!r}; allowed 0, 1, 2")
            for a in bus.actuators:
                a.set("feedback-return-mode", return_mode)
        if state:
            bus.save()
    if voltage is not None:
        bus.inject(None, "voltage", float(voltage))
    for fault in faults:
        if isinstance(fault, str):
            bus.inject_text(fault)
        else:
            bus.inject(*fault)
    if recorded is not None:
        from .replay import ZapReplay

        clock = Clock(speed)
        return Simulator("zap", keep_wire_time(ZapReplay(replay, bus, recorded), clock), clock, transport, host,
                         port)
    if virtual and transport != "inprocess":
        raise InvalidValue("virtual: only an in-process simulator has a virtual clock")
    clock = VirtualClock() if virtual else Clock(speed)
    return Simulator("zap", keep_wire_time(bus, clock), clock, transport, host, port)


def start(kind: Literal["zk", "zap"], **options: Any) -> Simulator:
    """Start the ``"zk"`` or ``"zap"`` simulator (see :func:`start_zk`, :func:`start_zap`)."""
    if kind == "zk":
        return start_zk(**options)
    if kind == "zap":
        return start_zap(**options)
    raise InvalidValue(f"simulator: unknown kind {kind!r}; allowed zk, zap")
