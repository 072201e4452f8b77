"""zkzap: the ZK turbine ECU protocol and the mightyZAP IR protocol, as a library and a
command-line suite.

The public API (imported lazily: ``from zkzap import Bus`` loads neither click nor rich):

- :class:`Ecu` (:mod:`zkzap.api.zk`): a ZK ECU session: status records, send, hold, profiles,
  abort, health;
- :class:`Bus`, :class:`Actuator`, :class:`Reading`, :class:`Moved` (:mod:`zkzap.api.zap`): a
  mightyZAP bus, every instruction and procedure, registers as attributes; the records it
  returns are typed (:mod:`zkzap.api.records`: :class:`ScanRecord`, :class:`Identity`,
  :class:`RegisterRow`, :class:`Latency`, ...);
- :mod:`zkzap.codec` (``zk``, ``zap``, framers): the pure protocol tables and codecs, with typed
  frames (:class:`zkzap.codec.zk.ControlFrame`, :class:`zkzap.codec.zap.Command`);
- :mod:`zkzap.sim`: the simulators, started from Python (:func:`zkzap.sim.start_zk`,
  :func:`zkzap.sim.start_zap`), and the pytest fixtures ``zk_sim``/``zap_sim``;
- :mod:`zkzap.errors`: one exception hierarchy with exit codes (:class:`ZkzapError`,
  :class:`NoReply`, :class:`PermissionNeeded`, ...); every error zkzap raises for bad input or
  a device is one, and each is importable from here;
- :class:`Permission` (:mod:`zkzap.codec.permissions`): what a frame needs from its sender
  (engine start, stored write, identity change, ...), given with ``allow=``.
"""

__version__ = "0.1.0"

#: The public names and the modules they are imported from on first use. Type checkers see the
#: same names through the imports below (a test keeps the two lists equal).
_LAZY = {
    "Ecu": "zkzap.api.zk",
    "Status": "zkzap.api.zk",
    "ProfileResult": "zkzap.api.zk",
    "Bus": "zkzap.api.zap",
    "Actuator": "zkzap.api.zap",
    "Reading": "zkzap.api.zap",
    "Moved": "zkzap.api.zap",
    "ScanRecord": "zkzap.api.records",
    "Identity": "zkzap.api.records",
    "RegisterRow": "zkzap.api.records",
    "RegisterValue": "zkzap.api.records",
    "Latency": "zkzap.api.records",
    "MoveRecord": "zkzap.api.records",
    "GoalClamped": "zkzap.errors",
    "ZkzapError": "zkzap.errors",
    "UsageError": "zkzap.errors",
    "InvalidValue": "zkzap.errors",
    "MissingExtra": "zkzap.errors",
    "CheckFailed": "zkzap.errors",
    "IdTaken": "zkzap.errors",
    "NoReply": "zkzap.errors",
    "PortError": "zkzap.errors",
    "DeviceError": "zkzap.errors",
    "BadReply": "zkzap.errors",
    "OutputError": "zkzap.errors",
    "Stalled": "zkzap.offload",
    "PermissionNeeded": "zkzap.errors",
    "MoreToDo": "zkzap.errors",
    "Interrupted": "zkzap.errors",
    "Permission": "zkzap.codec.permissions",
    "FieldValueError": "zkzap.codec.fields",
    "HexError": "zkzap.codec.hexfmt",
    "FrameError": "zkzap.codec.zk",
    "CrcError": "zkzap.codec.zk",
    "PacketError": "zkzap.codec.zap",
    "ChecksumError": "zkzap.codec.zap",
    "ModbusFrameError": "zkzap.codec.modbus",
    "ModbusCrcError": "zkzap.codec.modbus",
    "ExceptionReply": "zkzap.codec.modbus",
    "ReplyMismatch": "zkzap.codec.modbus",
    "MapError": "zkzap.codec.regmap",
    "ExpressionError": "zkzap.api.expr",
    "LimitViolation": "zkzap.api.limits",
    "StartRefused": "zkzap.api.alarms",
    "StartAlarm": "zkzap.api.alarms",
    "EcuLimitError": "zkzap.api.prestart",
    "ScheduleError": "zkzap.api.schedule",
    "ScheduleTargetError": "zkzap.api.schedule",
    "DocumentError": "zkzap.api.fleet",
    "NotFound": "zkzap.api.fleet",
    "TwoAnswer": "zkzap.api.fleet",
    "SharedId": "zkzap.api.fleet",
    "CaptureError": "zkzap.link.pcapng",
    "NoActuator": "zkzap.sim.zap_actuators",
    "PtyUnsupported": "zkzap.sim.serve",
}

__all__ = ["__version__", *_LAZY]

TYPE_CHECKING = False
if TYPE_CHECKING:  # what type checkers see (re-exported: "X as X"); at run time, imported on first use
    from .api.alarms import StartAlarm as StartAlarm, StartRefused as StartRefused
    from .api.expr import ExpressionError as ExpressionError
    from .api.fleet import (DocumentError as DocumentError, NotFound as NotFound, SharedId as SharedId,
                            TwoAnswer as TwoAnswer)
    from .api.limits import LimitViolation as LimitViolation
    from .api.prestart import EcuLimitError as EcuLimitError
    from .api.schedule import ScheduleError as ScheduleError, ScheduleTargetError as ScheduleTargetError
    from .api.records import (Identity as Identity, Latency as Latency, MoveRecord as MoveRecord,
                              RegisterRow as RegisterRow, RegisterValue as RegisterValue, ScanRecord as ScanRecord)
    from .api.zap import Actuator as Actuator, Bus as Bus, Moved as Moved, Reading as Reading
    from .api.zk import Ecu as Ecu, ProfileResult as ProfileResult, Status as Status
    from .codec.fields import FieldValueError as FieldValueError
    from .codec.hexfmt import HexError as HexError
    from .codec.modbus import (ExceptionReply as ExceptionReply, ModbusCrcError as ModbusCrcError,
                               ModbusFrameError as ModbusFrameError, ReplyMismatch as ReplyMismatch)
    from .codec.regmap import MapError as MapError
    from .codec.permissions import Permission as Permission
    from .codec.zap import ChecksumError as ChecksumError, PacketError as PacketError
    from .codec.zk import CrcError as CrcError, FrameError as FrameError
    from .errors import GoalClamped as GoalClamped, IdTaken as IdTaken
    from .errors import (BadReply as BadReply, CheckFailed as CheckFailed, DeviceError as DeviceError,
                         Interrupted as Interrupted, InvalidValue as InvalidValue, MissingExtra as MissingExtra,
                         MoreToDo as MoreToDo, NoReply as NoReply, OutputError as OutputError,
                         PermissionNeeded as PermissionNeeded, PortError as PortError, UsageError as UsageError,
                         ZkzapError as ZkzapError)
    from .link.pcapng import CaptureError as CaptureError
    from .offload import Stalled as Stalled
    from .sim.serve import PtyUnsupported as PtyUnsupported
    from .sim.zap_actuators import NoActuator as NoActuator
else:
    def __getattr__(name: str) -> object:
        module = _LAZY.get(name)
        if module is None:
            raise AttributeError(f"module 'zkzap' has no attribute {name!r}")
        import importlib

        value = getattr(importlib.import_module(module), name)
        globals()[name] = value
        return value

    def __dir__() -> list:
        return sorted(set(globals()) | set(_LAZY))


def _program_start():
    # Run as one of the programs (zk, zap, zkzap, python -m zkzap), SIGINT and SIGTERM are
    # handled from here on, before click and the command modules load: a signal during
    # start-up exits 130/143 quietly. Imported as a library, nothing changes.
    from ._program import is_program

    if is_program():
        from . import signals

        signals.install()


_program_start()
del _program_start
