"""The zkzap codec library: pure protocol code, no I/O, no click, rich or pyserial.

- :mod:`.crc`      CRC-8/MAXIM-DOW and the mightyZAP checksum
- :mod:`.fields`   declarative bit fields (the machinery behind the ZK tables)
- :mod:`.zk`       ZK ECU protocol tables, control/status encode and decode
- :mod:`.zap`      mightyZAP instructions, register map, packet encode and decode
- :mod:`.framing`  streaming framers for both protocols (sync, length, checksum)
- :mod:`.hexfmt`   hex text in the common notations, in and out
"""

__all__ = ["crc8_maxim", "zap_checksum", "FieldValueError", "ZkFramer", "ZapFramer", "HexError",
           "format_hex", "parse_hex"]

_WHERE = {"crc8_maxim": "crc", "zap_checksum": "crc", "FieldValueError": "fields", "ZkFramer": "framing",
          "ZapFramer": "framing", "HexError": "hexfmt", "format_hex": "hexfmt", "parse_hex": "hexfmt"}


def __getattr__(name):
    # Lazy re-exports: importing one codec module does not import the others.
    if name in _WHERE:
        import importlib

        value = globals()[name] = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
        return value
    raise AttributeError(name)
