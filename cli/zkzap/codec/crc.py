"""Checksums of both protocols.

ZK uses CRC-8/MAXIM-DOW (Dallas 1-Wire): reflected polynomial 0x8C (0x31 normal form),
init 0x00, no final xor; catalogue check value ``crc8(b"123456789") == 0xA1``.
mightyZAP uses ``0xFF - (sum & 0xFF)`` over ID, SIZE, instruction/error and parameters.
"""

from __future__ import annotations


def _build_table() -> bytes:
    table = bytearray(256)
    for i in range(256):
        crc = i
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8C if crc & 1 else crc >> 1
        table[i] = crc
    return bytes(table)


#: 256-entry lookup table, identical to the ``crc_array`` of the ZK document.
CRC8_TABLE = _build_table()


def crc8_maxim(data, seed: int = 0) -> int:
    """CRC-8/MAXIM-DOW of ``data`` (bytes-like or iterable of ints), table-driven."""
    crc = seed
    table = CRC8_TABLE
    for b in data:
        crc = table[crc ^ b]
    return crc


def zap_checksum(data) -> int:
    """mightyZAP checksum of the bytes from ID to the last parameter."""
    return 0xFF - (sum(data) & 0xFF)
