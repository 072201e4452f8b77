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


TYPE_CHECKING = False
if TYPE_CHECKING:  # what type checkers see; at run time each name is imported on first use
    from .crc import crc8_maxim as crc8_maxim, zap_checksum as zap_checksum
    from .fields import FieldValueError as FieldValueError
    from .framing import ZapFramer as ZapFramer, ZkFramer as ZkFramer
    from .hexfmt import HexError as HexError, format_hex as format_hex, parse_hex as parse_hex
else:
    def __getattr__(name: str) -> object:
        # Lazy re-exports: importing one codec module does not import the others.
        if name in _WHERE:
            import importlib

            value = globals()[name] = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
            return value
        raise AttributeError(name)
