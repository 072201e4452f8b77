"""The zkzap codec library: pure protocol code, no I/O, no click, rich or pyserial.

- :mod:`.crc`      CRC-8/MAXIM-DOW and the mightyZAP checksum
- :mod:`.fields`   declarative bit fields (the machinery behind the ZK tables)
- :mod:`.zk`       ZK ECU protocol tables, control/status encode and decode
- :mod:`.zap`      mightyZAP instructions, register map, packet encode and decode
- :mod:`.framing`  streaming framers for both protocols (sync, length, checksum)
- :mod:`.hexfmt`   hex text in the common notations, in and out
"""

from .crc import crc8_maxim, zap_checksum
from .fields import FieldValueError
from .framing import ZapFramer, ZkFramer
from .hexfmt import HexError, format_hex, parse_hex

__all__ = ["crc8_maxim", "zap_checksum", "FieldValueError", "ZkFramer", "ZapFramer", "HexError",
           "format_hex", "parse_hex"]
