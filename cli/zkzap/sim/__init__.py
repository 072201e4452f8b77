"""Virtual devices on the link: the ECU simulator and the actuator-bus simulator.

A device implements :class:`zkzap.sim.base.Device`; :mod:`zkzap.sim.serve` runs one on a
pseudo-terminal or a TCP socket, and :mod:`zkzap.link.protocol_sim` runs one in-process
behind a ``sim://`` pyserial URL (``sim://zk?protocol_version=4``, ``sim://zap?ids=1,2``).
"""

#: Device kinds by URL host: "module:factory". The factory takes the URL's query options as
#: keyword strings and returns a Device.
DEVICES = {
    "zk": "zkzap.sim.zk_ecu:from_options",
    "zap": "zkzap.sim.zap_bus:from_options",
}


def make_device(kind: str, **options):
    """Build a device of ``kind`` ("zk" or "zap") from string options."""
    import importlib

    spec = DEVICES.get(kind)
    if spec is None:
        raise ValueError(f"simulator: unknown kind {kind!r}; allowed {', '.join(DEVICES)}")
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)(**options)
