"""Checksums of both protocols.

ZK uses CRC-8/MAXIM-DOW (Dallas 1-Wire): reflected polynomial 0x8C (0x31 normal form),
init 0x00, no final xor; catalogue check value ``crc8(b"123456789") == 0xA1``.
mightyZAP uses ``0xFF - (sum & 0xFF)`` over ID, SIZE, instruction/error and parameters on the
IR protocol, and CRC-16/MODBUS on Modbus RTU: reflected polynomial 0xA001 (0x8005 normal form),
init 0xFFFF, no final xor, sent low byte first; catalogue check value
``crc16_modbus(b"123456789") == 0x4B37``.
"""

from __future__ import annotations

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Iterable, Union


def build_table(poly: int = 0x8C) -> bytes:
    """The lookup table of a reflected CRC-8 (how :data:`CRC8_TABLE` was made; a test checks it)."""
    table = bytearray(256)
    for i in range(256):
        crc = i
        for _ in range(8):
            crc = (crc >> 1) ^ poly if crc & 1 else crc >> 1
        table[i] = crc
    return bytes(table)


#: 256-entry lookup table, identical to the ``crc_array`` of the ZK document: ``build_table()``,
#: written out so that starting a command does not compute it.
CRC8_TABLE = bytes.fromhex(
    "005ebce2613fdd83c29c7e20a3fd1f419dc3217ffca2401e5f01e3bd3e6082dc"
    "237d9fc1421cfea0e1bf5d0380de3c62bee0025cdf81633d7c22c09e1d43a1ff"
    "4618faa427799bc584da3866e5bb5907db856739bae406581947a5fb7826c49a"
    "653bd987045ab8e6a7f91b45c6987a24f8a6441a99c7257b3a6486d85b05e7b9"
    "8cd2306eedb3510f4e10f2ac2f7193cd114fadf3702ecc92d38d6f31b2ec0e50"
    "aff1134dce90722c6d33d18f0c52b0ee326c8ed0530defb1f0ae4c1291cf2d73"
    "ca947628abf517490856b4ea6937d58b5709ebb536688ad495cb2977f4aa4816"
    "e9b7550b88d6346a2b7597c94a14f6a8742ac896154ba9f7b6e80a54d7896b35"
)


def crc8_maxim(data: Union[bytes, bytearray, memoryview, Iterable[int]], seed: int = 0) -> int:
    """CRC-8/MAXIM-DOW of ``data`` (bytes-like or iterable of ints), table-driven."""
    crc = seed
    table = CRC8_TABLE
    for b in data:
        crc = table[crc ^ b]
    return crc


def zap_checksum(data: Union[bytes, bytearray, memoryview, Iterable[int]]) -> int:
    """mightyZAP checksum of the bytes from ID to the last parameter."""
    return 0xFF - (sum(data) & 0xFF)


def build_table16(poly: int = 0xA001) -> tuple:
    """The lookup table of a reflected CRC-16 (CRC-16/MODBUS by default)."""
    table = []
    for i in range(256):
        crc = i
        for _ in range(8):
            crc = (crc >> 1) ^ poly if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_CRC16_TABLE: tuple = ()


def crc16_modbus(data: Union[bytes, bytearray, memoryview, Iterable[int]], seed: int = 0xFFFF) -> int:
    """CRC-16/MODBUS of ``data``, table-driven (the table is built on first use: nothing on the
    IR paths pays for it). On the wire it goes low byte first: ``crc.to_bytes(2, "little")``."""
    global _CRC16_TABLE
    table = _CRC16_TABLE
    if not table:
        table = _CRC16_TABLE = build_table16()
    crc = seed
    for b in data:
        crc = (crc >> 8) ^ table[(crc ^ b) & 0xFF]
    return crc
