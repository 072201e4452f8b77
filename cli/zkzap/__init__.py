"""zkzap: the ZK turbine ECU protocol and the mightyZAP IR protocol, as a library and a
command-line suite.

The public API (imported lazily: ``from zkzap import Bus`` loads neither click nor rich):

- :class:`Ecu` (:mod:`zkzap.api.zk`): a ZK ECU session: status records, send, hold, profiles,
  abort, health;
- :class:`Bus`, :class:`Actuator`, :class:`Reading` (:mod:`zkzap.api.zap`): a mightyZAP bus,
  every instruction and procedure, registers as attributes;
- :mod:`zkzap.codec` (``zk``, ``zap``, framers): the pure protocol tables and codecs, with typed
  frames (:class:`zkzap.codec.zk.ControlFrame`, :class:`zkzap.codec.zap.Command`);
- :mod:`zkzap.sim`: the simulators, started from Python (:func:`zkzap.sim.start_zk`,
  :func:`zkzap.sim.start_zap`), and the pytest fixtures ``zk_sim``/``zap_sim``;
- :mod:`zkzap.errors`: one exception hierarchy with exit codes (:class:`ZkzapError`,
  :class:`NoReply`, :class:`PermissionNeeded`, ...);
- :class:`Permission` (:mod:`zkzap.codec.permissions`): what a frame needs from its sender
  (engine start, stored write, identity change, ...), given with ``allow=``.
"""

__version__ = "0.1.0"

_LAZY = {
    "Ecu": "zkzap.api.zk",
    "Status": "zkzap.api.zk",
    "Bus": "zkzap.api.zap",
    "Actuator": "zkzap.api.zap",
    "Reading": "zkzap.api.zap",
    "ZkzapError": "zkzap.errors",
    "UsageError": "zkzap.errors",
    "CheckFailed": "zkzap.errors",
    "NoReply": "zkzap.errors",
    "PortError": "zkzap.errors",
    "DeviceError": "zkzap.errors",
    "BadReply": "zkzap.errors",
    "OutputError": "zkzap.errors",
    "PermissionNeeded": "zkzap.errors",
    "Permission": "zkzap.codec.permissions",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'zkzap' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
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
