"""Virtual devices on the link: the ECU simulator and the actuator-bus simulator.

From Python, :func:`start_zk` and :func:`start_zap` (or :func:`start`) run one with typed
arguments, in-process (a ``sim://`` URL), on a pseudo-terminal or on a TCP socket, and return a
:class:`~zkzap.sim.launch.Simulator` whose ``url`` any zkzap API or command opens; the pytest
plugin :mod:`zkzap.pytest_plugin` gives them as the ``zk_sim`` and ``zap_sim`` fixtures.

A device implements :class:`zkzap.sim.base.Device`; :mod:`zkzap.sim.serve` runs one on a
pseudo-terminal or a TCP socket, and :mod:`zkzap.link.protocol_sim` runs one in-process
behind a ``sim://`` pyserial URL (``sim://zk?protocol_version=4``, ``sim://zap?ids=1,2``).
"""

from __future__ import annotations

#: Device kinds by URL host: "module:factory". The factory takes the URL's query options as
#: keyword strings and returns a Device.
DEVICES = {
    "zk": "zkzap.sim.zk_ecu:from_options",
    "zap": "zkzap.sim.zap_actuators:from_options",
}

#: Simulators started from Python, by instance key: (device, clock). ``sim://KIND?instance=KEY``
#: opens one of them (see :mod:`zkzap.sim.launch`).
INSTANCES: dict = {}

_LAUNCH = ("start", "start_zk", "start_zap", "Simulator")

TYPE_CHECKING = False
if TYPE_CHECKING:  # what type checkers see; at run time zkzap.sim.launch is imported on first use
    from typing import Any

    from .base import Device
    from .launch import Simulator as Simulator, start as start, start_zap as start_zap, start_zk as start_zk
else:
    def __getattr__(name: str) -> object:
        if name in _LAUNCH:
            from . import launch

            return getattr(launch, name)
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def make_device(kind: str, **options: Any) -> Device:
    """Build a device of ``kind`` ("zk" or "zap") from string options."""
    import importlib

    spec = DEVICES.get(kind)
    if spec is None:
        from ..errors import unknown_name

        raise unknown_name("simulator", kind, DEVICES)
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)(**options)
