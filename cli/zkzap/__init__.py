"""zkzap: command-line suite for the ZK turbine ECU protocol and the mightyZAP IR protocol."""

__version__ = "0.1.0"
