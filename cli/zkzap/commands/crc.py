"""``zkzap crc``: compute and check the CRCs and checksums of both protocols."""

from __future__ import annotations

import click

from ..codec import crc as crcs
from ..codec import modbus, zap, zk
from ..codec.hexfmt import format_hex
from ..errors import CHECK_FAILED, OK, UsageError
from . import CONTEXT, Group
from .options import checked, exits, read_hex_input

HEX = click.argument("hex_bytes", nargs=-1, metavar="HEX...")
APPEND = click.option("-a", "--append", is_flag=True, help="Print the input followed by the checksum.")
CHECK = click.option("-c", "--check", is_flag=True,
                     help="Check a whole frame (ZK control, ZK status, mightyZAP IR or Modbus RTU): exit 0 "
                          "when its CRC/checksum is right, 1 when not (expected and found on stderr).")


@click.group(cls=Group, context_settings=CONTEXT)
def crc():
    """Compute or check CRCs and checksums.

    \b
    Examples:
      zkzap crc zk 14 64                  # D3: CRC-8/MAXIM-DOW of exactly these bytes
      zkzap crc zap 00 02 F1              # 0C: mightyZAP checksum from ID to last parameter
      zkzap crc zk --append 14 64         # 14 64 D3
      zkzap crc modbus 01 03 00 D2 00 01  # 24 33: CRC-16/MODBUS, low byte first
      zkzap crc check FF 14 64 D3         # exit 0; any protocol's whole frame
    """


def check_any(frame: bytes) -> str:
    """Check a whole frame of any protocol; returns a description, raises on mismatch. A frame
    that is neither a mightyZAP IR packet nor a ZK frame but whose last two bytes are its
    CRC-16/MODBUS is a Modbus RTU frame; so is a longer one of a Modbus frame's form (unit ID
    0..247, a function of the family or its exception), whose CRC is then checked. Bytes of no
    protocol's form are bad input, never a "mismatch" of a protocol they are not."""
    if len(frame) >= 7 and frame[:3] == zap.HEADER:
        checked(zap.check_packet, frame)
        return f"mightyZAP packet: checksum {frame[-1]:02X} ok"
    if len(frame) in (4, 7):
        try:
            kind = zk.check_frame(frame)
        except zk.FrameError:
            if modbus.crc_ok(frame):
                return f"Modbus RTU frame: CRC {frame[-2]:02X} {frame[-1]:02X} ok"
        else:
            return f"ZK {kind} frame: CRC {frame[-1]:02X} ok"
    elif len(frame) > 4 and frame[:3] != zap.HEADER and _modbus_form(frame):
        checked(modbus.check_frame, frame, "; a mightyZAP packet starts FF FF FF, a ZK frame has 4 or 7 bytes")
        return f"Modbus RTU frame: CRC {frame[-2]:02X} {frame[-1]:02X} ok"
    kind = checked(zk.check_frame, frame, "; a mightyZAP packet starts FF FF FF, a Modbus RTU frame has "
                                          "a unit ID 0..247 and function " +
                                          ", ".join(f"{f:02X}" for f in sorted(modbus.FUNCTIONS)))
    return f"ZK {kind} frame: CRC {frame[-1]:02X} ok"


def _modbus_form(frame: bytes) -> bool:
    """Whether ``frame`` has a Modbus RTU frame's form: unit ID 0..247 (0 broadcast), then a
    function of the family (its exception: the same with bit 7 set)."""
    return frame[0] <= modbus.MAX_ID and (frame[1] & ~modbus.EXCEPTION_BIT) in modbus.FUNCTIONS


def _zap_covered(data: bytes, append: bool) -> bytes:
    """The bytes a mightyZAP checksum covers: ID to the last parameter. Bytes given with the
    packet's header FF FF FF (which the checksum never covers) must be a packet: up to its
    checksum, or whole (its checksum then left out, and nothing to append)."""
    if data[:3] != zap.HEADER:
        return data
    if len(data) < 5:
        raise UsageError(f"{format_hex(data)}: starts with the header FF FF FF but is too short for a packet "
                         f"(the header, ID and SIZE are 5 bytes); give the bytes from ID to the last parameter")
    body, size = data[3:], data[4]
    if len(body) == 1 + size:                # ID SIZE CMD params: the packet without its checksum
        return body
    if len(body) == 2 + size and not append:  # a whole packet: the checksum its last byte should be
        return body[:-1]
    if len(body) == 2 + size:
        raise UsageError(f"{format_hex(data)}: a whole packet already ends with its checksum "
                         f"({format_hex(body[-1:])}); --check checks it")
    raise UsageError(f"{format_hex(data)}: starts with the header FF FF FF but is no packet: SIZE {size} "
                     f"means {size + 5} bytes in all (or {size + 4} before the checksum), {len(data)} given; "
                     f"give the bytes from ID to the last parameter, or the packet")


def _run(hex_bytes, append, check, compute, cover=None):
    data = read_hex_input(hex_bytes)
    if check:
        if append:
            raise UsageError("--append and --check exclude each other")
        click.echo(check_any(data), err=True)
        return
    if not data:
        source = "stdin" if not hex_bytes or list(hex_bytes) == ["-"] else "hex input"
        raise UsageError(f"{source}: no bytes given")
    value = compute(cover(data, append) if cover else data)
    if isinstance(value, int):
        value = bytes((value,))
    click.echo(format_hex(data + value) if append else format_hex(value))


@exits({CHECK_FAILED: "with --check, the frame's CRC or checksum does not match"})
@crc.command("zk", context_settings=CONTEXT)
@HEX
@APPEND
@CHECK
def crc_zk(hex_bytes, append, check):
    """CRC-8/MAXIM-DOW (seed 0) of exactly the given bytes.

    For a control frame give bytes 1..2 (the FF head is not covered); for a status frame
    bytes 0..5. Reads stdin when no bytes are given or HEX is '-'.

    \b
    Examples:
      zkzap crc zk 14 64             # D3
      zkzap crc zk F1 00 00 00 00 4C # A0
    """
    _run(hex_bytes, append, check, crcs.crc8_maxim)


@exits({CHECK_FAILED: "with --check, the frame's CRC or checksum does not match"})
@crc.command("zap", context_settings=CONTEXT)
@HEX
@APPEND
@CHECK
def crc_zap(hex_bytes, append, check):
    """mightyZAP checksum of the bytes from ID to the last parameter.

    Bytes that start with the header FF FF FF are taken as a packet, up to its checksum or
    whole, and the header is not summed; anything else with that header is refused (exit 2).

    \b
    Examples:
      zkzap crc zap 00 02 F1                  # 0C
      zkzap crc zap --append 01 05 F3 88 00 02 # 01 05 F3 88 00 02 7C
      zkzap crc zap FF FF FF 01 05 F3 86 FF 07 # 7A
    """
    _run(hex_bytes, append, check, crcs.zap_checksum, _zap_covered)


@exits({CHECK_FAILED: "with --check, the frame's CRC does not match"})
@crc.command("modbus", context_settings=CONTEXT)
@HEX
@APPEND
@CHECK
def crc_modbus(hex_bytes, append, check):
    """CRC-16/MODBUS of the given bytes, as it goes on the wire: low byte first.

    Give the frame from the ID to the last data byte (polynomial 0xA001 reflected, init 0xFFFF,
    no final xor).

    \b
    Examples:
      zkzap crc modbus 01 03 00 D2 00 01            # 24 33
      zkzap crc modbus --append 01 06 00 CD 03 E8   # 01 06 00 CD 03 E8 18 8B
      zkzap crc modbus --check 01 83 04 40 F3       # exit 0
    """
    _run(hex_bytes, append, check, lambda d: crcs.crc16_modbus(d).to_bytes(2, "little"))


@exits({OK: "the frame is whole and its CRC or checksum matches",
        CHECK_FAILED: "the CRC or checksum does not match"})
@crc.command("check", context_settings=CONTEXT)
@HEX
def crc_check(hex_bytes):
    """Check a whole frame of any protocol (same as --check): ZK, mightyZAP IR, Modbus RTU.

    \b
    Examples:
      zkzap crc check FF 14 64 D3
      zkzap crc check FF FF FF 00 02 F1 0C
      zkzap crc check 01 03 02 03 E8 B8 FA
    """
    _run(hex_bytes, False, True, None)
