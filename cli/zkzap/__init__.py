"""zkzap: command-line suite for the ZK turbine ECU protocol and the mightyZAP IR protocol."""

__version__ = "0.1.0"


def _program_start():
    # Run as one of the programs (zk, zap, zkzap, python -m zkzap), SIGINT and SIGTERM are
    # handled from here on, before click and the command modules load: a signal during
    # start-up exits 130/143 quietly. Imported as a library, nothing changes.
    from . import signals

    if signals.is_program():
        signals.install()


_program_start()
del _program_start
