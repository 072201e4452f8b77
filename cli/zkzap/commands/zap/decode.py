"""``zap decode``: mightyZAP packets from hex arguments, hex text on stdin, or binary captures."""

from __future__ import annotations


import click

from ...codec import modbus, zap
from ...codec.framing import ZapFramer
from ...errors import CHECK_FAILED, UsageError
from ...io import RECORD_FORMATS
from .. import CONTEXT, Command
from ..complete import binary_inputs
from ..options import (InputPath, checked, close_output, decode_inputs, end_decode, exits, format_option,
                       open_output, output_format, output_options, protocol_options, zap_map)

COLUMNS = list(zap.ZAP_KEYS) + ["frame"]
TABLE_COLUMNS = [("kind", "kind"), ("id", "id"), ("_what", "instruction/error"), ("_detail", "data"),
                 ("frame", "frame")]


def _table_cells(rec):
    if rec["kind"] == "command":
        rec["_what"] = rec["instruction"]
    elif rec["kind"] == "unknown":
        rec["_what"] = f"unknown 0x{rec['code']:02X}"
    else:
        rec["_what"] = ",".join(rec["errors"]) or "ok"
    detail = []
    for k in ("register", "value", "physical", "unit", "length", "values", "targets", "reset_id", "reset_baud"):
        if k in rec:
            detail.append(f"{k}={rec[k]}")
    if not detail and rec.get("params"):
        detail.append(f"params={rec['params']}")
    rec["_detail"] = " ".join(detail)
    return rec


@exits({CHECK_FAILED: "a single packet given as arguments has a bad checksum"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("inputs", nargs=-1, metavar="[HEX...|FILE...]", type=InputPath("frames", "FILE"), shell_complete=binary_inputs)
@click.option("--binary", is_flag=True, help="Inputs are files of raw bytes ('-' or none: stdin).")
@format_option(choices=RECORD_FORMATS, help_extra=" influx: InfluxDB line protocol.")
@output_options(formats=RECORD_FORMATS)
@protocol_options
def decode(inputs, binary, fmt, output, append, protocol, regmap):
    """Decode mightyZAP packets to a table, JSON, JSON Lines or CSV.

    Commands and feedback are told apart by the byte after SIZE (an instruction code, or error
    bits). IR Robot's undocumented vendor instructions (0xF9 system-write, which their Python
    library sends as factory reset; 0x55 status, 0x82 sync-read, 0x92 bulk-read, 0x93
    bulk-write) decode as commands with "documented": false; a byte that is neither an
    instruction nor documented error bits gives kind "unknown" with its code. In a capture of both directions each feedback is paired with the Load Data it
    answers, so its data is named by register. Bad packets in a stream are skipped and counted
    on stderr; a single packet given as arguments with a bad checksum is an error (exit 1).

    pcapng captures (--capture FILE; recognised by their content) add 'time', 't' (seconds since
    the capture began), 'dir' (h2d host to actuator, d2h actuator to host) and, on feedback,
    'latency_ms' since the request it answers. A capture records the protocol its port spoke
    (a Modbus RTU bus's has link type 149): it is decoded by that protocol unless --protocol
    says another, which is then refused.

    --protocol modbus decodes Modbus RTU frames (the 17Lf): requests, replies (a read's values
    named by the request to the same ID just before) and exception replies, named by code and
    meaning; a frame's length comes from its function, and every reading the bytes allow is
    checked with its CRC-16.

    \b
    Examples:
      zap decode FF FF FF 01 05 F3 86 FF 07 7A
      zap decode FF FF FF 00 04 F2 8C 02 7B FF FF FF 00 04 00 FF 07 F5 -f json
      zap decode --binary bus.bin -f csv -o bus.csv
      zap decode bus.pcapng -f json -o bus.json
      zap decode --protocol modbus 01 03 00 D2 00 01 24 33 01 03 02 03 E8 B8 FA
    """
    from ...api.capture import capture_inputs
    from ...io.sources import run_decode, run_text_decode, start
    from ...io.writers import make_writer

    captures = capture_inputs(inputs, binary)
    if captures is not None:
        from ..capture_decode import zap_decode_captures

        protocol = _capture_protocol(captures, protocol)
        return zap_decode_captures(captures, fmt=fmt, output=output, append=append,
                                   table_cells=_modbus_cells if protocol == "modbus" else _table_cells,
                                   protocol="modbus" if protocol == "modbus" else "zap",
                                   regmap=zap_map() if protocol == "modbus" else None)
    if protocol == "modbus":
        return _decode_modbus(inputs, binary, fmt, output, append)
    chunks, explicit = _chunks(inputs, binary)
    fmt = output_format(fmt, output, RECORD_FORMATS)
    framer = ZapFramer()
    decoder = zap.ZapDecoder()
    if explicit:
        probe = ZapFramer()
        if not probe.feed(chunks[0]):
            _explain_single(chunks[0])
    start(chunks)
    stream, had = open_output(output, append, fmt=fmt, columns=COLUMNS,
                              inputs=decode_inputs(inputs, binary, explicit))
    writer = make_writer(fmt, stream, COLUMNS, table_columns=TABLE_COLUMNS, header=not had)
    try:
        if fmt == "table":
            run_decode(chunks, framer, lambda p: _table_cells(decoder.decode(p)), writer)
        elif fmt not in ("csv", "json", "jsonl"):      # influx: record by record
            run_decode(chunks, framer, decoder.decode, writer)
        else:                   # text formats: each distinct (request, packet) rendered once
            from ...io.writers import csv_dialect, json_dialect
            from ...io.zap_lines import ZapLines

            lines = ZapLines(decoder, csv_dialect(COLUMNS) if fmt == "csv" else json_dialect())
            run_text_decode(chunks, framer, lines, writer)
    finally:
        close_output(writer, stream)
    end_decode(framer, chunks, "packet", "checksum")


def _chunks(inputs, binary):
    """``(chunks, explicit)``: the inputs' bytes, and whether they were hex arguments."""
    from ...io.sources import binary_chunks, hex_chunks

    if binary:
        return binary_chunks(list(inputs)), False
    return hex_chunks(inputs)


def _explain_single(data: bytes):
    if not data:
        raise UsageError("hex input: no bytes given")
    checked(zap.check_packet, data)


MODBUS_COLUMNS = list(modbus.MODBUS_KEYS) + ["frame"]
MODBUS_TABLE = [("kind", "kind"), ("id", "id"), ("function", "function"), ("_detail", "data"), ("frame", "frame")]


def _modbus_cells(rec):
    detail = [f"{k}={rec[k]}" for k in ("register", "value", "physical", "unit", "count", "values", "name",
                                         "malformed", "params") if k in rec]
    rec["_detail"] = " ".join(detail)
    return rec


def _capture_protocol(paths, protocol):
    """The protocol captures are decoded by: a capture records which one its port spoke (its
    link type), and that is the one taken unless --protocol (or its environment) says another
    (the capture is then refused, exit 2, naming both)."""
    ctx = click.get_current_context()
    if ctx.get_parameter_source("protocol") != click.core.ParameterSource.DEFAULT:
        return protocol
    from ...link.pcapng import capture_protocol

    found = capture_protocol(paths[0])
    if found == "modbus":
        if ctx.params.get("regmap") is not None and ctx.params["regmap"].protocol != "modbus":
            raise UsageError(f"map: {ctx.params['regmap'].path} describes the ir protocol; {paths[0]} is a "
                             "Modbus RTU capture")
        ctx.params["protocol"] = "modbus"
        return "modbus"
    return protocol


def _decode_modbus(inputs, binary, fmt, output, append):
    from ...codec.framing import RtuFramer
    from ...io.sources import run_decode, start
    from ...io.writers import make_writer

    regmap = zap_map()
    chunks, explicit = _chunks(inputs, binary)
    fmt = output_format(fmt, output, RECORD_FORMATS)
    if explicit:
        data = chunks[0]
        if not data:
            raise UsageError("hex input: no bytes given")
        probe = RtuFramer()
        if not probe.feed(data) and not probe.flush():
            checked(modbus.check_frame, data)
    framer = RtuFramer()
    decoder = modbus.ModbusDecoder(regmap)
    start(chunks)
    stream, had = open_output(output, append, fmt=fmt, columns=MODBUS_COLUMNS,
                              inputs=decode_inputs(inputs, binary, explicit))
    writer = make_writer(fmt, stream, MODBUS_COLUMNS, table_columns=MODBUS_TABLE, header=not had)
    try:
        decode = (lambda f: _modbus_cells(decoder.decode(f))) if fmt == "table" else decoder.decode
        run_decode(chunks, framer, decode, writer)
    finally:
        close_output(writer, stream)
    end_decode(framer, chunks, "frame", "CRC")
