"""The pre-start check: nothing is sent that the ECU cannot follow.

An ECU states its own limits in status ID 6 — its max rpm and its protocol version — within its
first cycle of status frames. Every path that sends control frames (``zk send`` once or
``--for``, ``zk profile``, ``zk batch`` lines, :class:`zkzap.Ecu`'s ``send``/``hold``/
``run_profile``) goes through :class:`Plan`: when a frame it will send needs a protocol version
newer than 1 or carries an RPM target, the session first listens for status ID 6
(:func:`listen`, at most :data:`LISTEN_FRAMES` frames) and refuses the whole plan before its
first frame goes out — :class:`EcuLimitError`, a usage error (exit 2, nothing sent) — when a
target exceeds the max rpm the ECU reports or a frame needs a newer version than it reports.

Without a status ID 6 among the first frames the version is the one given
(``protocol_version``) or the documented default (4), and RPM targets are refused: a max rpm
nobody reported cannot be checked. Nothing here imports click, rich or pyserial.
"""

from __future__ import annotations

from ..codec import zk
from ..errors import NoReply, UsageError

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Callable, Iterable, Optional, Union

    from ..link.zk_sources import LiveSource

#: Status frames listened to at most for status ID 6 (more than one cycle of IDs 1..10).
LISTEN_FRAMES = 12


class EcuLimitError(UsageError):
    """A plan the ECU cannot follow (an RPM target above its max rpm, a command newer than its
    protocol version); nothing was sent. Facts: ``max_rpm``, ``protocol_version`` (what the ECU
    reported; None when it did not) and ``target`` or ``needs``."""


class EcuLimits:
    """What the ECU reported about itself: ``max_rpm`` and ``protocol_version`` from status ID 6
    (None when no ID 6 came), ``version`` the one in force (reported, given or the default) and
    ``version_source`` (``frame``, ``given`` or ``default``)."""

    def __init__(self, frame: Optional[bytes] = None, given: Optional[int] = None, read: bool = True) -> None:
        self.frame = frame
        self.read = read              # False: nothing was read from the ECU (transmit only)
        rec = zk.decode_status(frame) if frame is not None else {}
        self.max_rpm: Optional[float] = rec.get("max_rpm")
        self.protocol_version: Optional[int] = rec.get("protocol_version")
        self.version: int
        self.version_source: str
        if self.protocol_version is not None:
            self.version, self.version_source = self.protocol_version, "frame"
        elif given is not None:
            self.version, self.version_source = given, "given"
        else:
            self.version, self.version_source = zk.DEFAULT_PROTOCOL_VERSION, "default"

    @classmethod
    def reported(cls, max_rpm: Optional[float], protocol_version: Optional[int]) -> "EcuLimits":
        """The limits of an ECU whose status ID 6 values are already known (a live view that
        decodes every frame): ``max_rpm`` and ``protocol_version`` (None: not reported yet)."""
        limits = cls(None, protocol_version)
        limits.max_rpm = max_rpm
        if protocol_version is not None:
            limits.protocol_version, limits.version_source = protocol_version, "frame"
        return limits

    def __repr__(self) -> str:
        return f"EcuLimits(max_rpm={self.max_rpm}, version={self.version} ({self.version_source}))"


class Plan:
    """The control frames a session may send, checked against the ECU before the first goes out.

    ``frames``: every frame the session can send (bytes or :class:`~zkzap.codec.zk.ControlFrame`);
    ``targets``: its RPM targets as ``(rpm, where)`` (``where`` names them in a refusal:
    ``stand.csv:12``); without them the ID 7 frames' targets follow from ``rpm_factor`` (or the
    RPM factor of an ID 6 frame among ``frames``); a target whose factor nobody knows is not
    checked. ``what`` names the plan in messages.
    """

    def __init__(self, frames: Iterable[Union[bytes, zk.ControlFrame]], *,
                 targets: Optional[Iterable[tuple[float, str]]] = None, rpm_factor: Optional[int] = None,
                 what: str = "command") -> None:
        self.frames = [f if isinstance(f, zk.ControlFrame) else zk.ControlFrame(f) for f in frames]
        self.what = what
        if targets is None:
            factors = [cf.rpm_factor for cf in self.frames if cf.rpm_factor]
            factor = rpm_factor or (max(factors) if factors else None)
            targets = [(cf.rpm_value * 10 * factor, what) for cf in self.frames
                       if cf.id == 7 and factor]
        self.targets: list[tuple[float, str]] = list(targets)
        self.needs = max((cf.since for cf in self.frames), default=1)

    @property
    def needs_ecu(self) -> bool:
        """True when the ECU's limits must be known before the first frame goes out."""
        return self.needs > 1 or bool(self.targets)

    def check(self, limits: EcuLimits) -> None:
        """Raise :class:`EcuLimitError` when the ECU of ``limits`` cannot follow the plan."""
        version = limits.version
        if self.needs > version:
            cf = next(cf for cf in self.frames if cf.since > version)
            name = cf.action or (cf.command.name if cf.command is not None else f"ID {cf.id}")
            told = {"frame": "reports", "given": "was given as",
                    "default": "is assumed to be (no status ID 6)" if limits.read
                    else "is assumed to be (its status frames were not read)"}
            who = self.what if name == self.what else f"{self.what}: {name}"
            raise EcuLimitError(
                f"{who} needs protocol version {cf.since} or later; the ECU "
                f"{told[limits.version_source]} {version}; nothing sent",
                max_rpm=limits.max_rpm, protocol_version=limits.protocol_version, needs=cf.since)
        if not self.targets:
            return
        top, where = max(self.targets, key=lambda t: t[0])
        if limits.max_rpm is None:
            why = ("no status ID 6 among its first frames" if limits.read
                   else "its status frames were not read")
            raise EcuLimitError(
                f"{where}: target {top:g} rpm: the ECU's max rpm is not known ({why}), so no RPM target "
                f"can be checked; nothing sent",
                max_rpm=None, protocol_version=limits.protocol_version, target=top)
        if top > limits.max_rpm:
            raise EcuLimitError(
                f"{where}: target {top:g} rpm is above the ECU's max rpm {limits.max_rpm:g} (status ID 6); "
                f"nothing sent", max_rpm=limits.max_rpm, protocol_version=limits.protocol_version,
                target=top)


def listen(source: LiveSource, silence: Optional[float], *, given: Optional[int] = None,
           on_frame: Optional[Callable[[float, bytes], Any]] = None, where: Optional[str] = None) -> EcuLimits:
    """Read ``source`` (a live source: ``poll()``, ``now()``) until a status ID 6 frame, or
    :data:`LISTEN_FRAMES` status frames without one; returns the :class:`EcuLimits`.
    ``on_frame(t, frame)`` sees every frame read. Raises :class:`~zkzap.errors.NoReply` when no
    status frame comes for ``silence`` session seconds (None: wait for ever), nothing sent."""
    start = last = None
    n = 0
    while True:
        got = source.poll()
        polled = source.now()
        if start is None:
            start = last = polled          # silence counts from the first read, never a stall before it
        for t, frame in got:
            n += 1
            last = t
            if on_frame is not None:
                on_frame(t, frame)
            if frame[0] == zk.VERSION_HEAD:
                return EcuLimits(frame, given)
            if n >= LISTEN_FRAMES:
                return EcuLimits(None, given)
        if not got and silence is not None and polled - max(last, start) > silence:
            raise silence_error(source, silence, heard=n > 0, where=where)


def silence_error(source: Any, seconds: float, *, heard: bool, where: Optional[str] = None,
                  ran: bool = False) -> NoReply:
    """The :class:`~zkzap.errors.NoReply` for ``seconds`` session seconds without a status frame
    from ``source`` (``ran``: the whole session, which ended by its time, ran that long). Facts:
    ``port``, ``timeout``, ``protocol`` and ``noise``: True when the line carried bytes that
    were not an ECU's frames, with ``bytes`` and ``chance_frames``."""
    where = where or getattr(getattr(source, "link", None), "url", "the port")
    facts = getattr(source, "noise_facts", lambda: {})() if not heard else {}
    within = f"in the {seconds:.1f} s the session ran" if ran else f"within {seconds:g} s"
    if heard:
        msg = f"the ECU on {where} fell silent: no status frame for {seconds:g} s"
    elif facts:
        msg = (f"no status frame from the ECU on {where} {within}: {facts['bytes']:,} bytes came, but "
               f"not as a stream of status frames ({facts['chance_frames']} CRC-valid by chance among "
               f"them): line noise, another device, or a wrong baud rate or stop bits")
    else:
        msg = f"no status frame from the ECU on {where} {within} (check the port, baud rate and wiring)"
    return NoReply(msg, port=where, timeout=seconds, protocol="zk", noise=bool(facts), **facts)
