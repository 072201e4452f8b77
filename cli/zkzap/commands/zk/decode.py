"""``zk decode``: ZK frames from hex arguments, hex text on stdin, or binary captures."""

from __future__ import annotations


import click

from ...codec import zk
from ...codec.framing import ZkFramer
from ...errors import CHECK_FAILED, UsageError
from ...io import RECORD_FORMATS
from .. import CONTEXT, Command
from ..complete import binary_inputs
from ..options import (Choice, InputPath, checked, close_output, decode_inputs, end_decode, exits, format_option,
                       note, open_output, output_format, output_options, protocol_version_option)


def columns(accept="both", raw=False):
    """The fixed CSV column set of ``zk decode`` / ``zk monitor`` records."""
    cols = ["kind", "id"]
    if accept != "status":
        cols.append("command")
    keys = []
    if accept != "control":
        keys += zk.STATUS_KEYS
    if accept != "status":
        keys += [k for k in zk.CONTROL_KEYS if k not in keys]
    for k in keys:
        cols.append(k)
        if raw and not k.endswith("_name") and k not in ("state", "action", zk.OUT_OF_RANGE):
            cols.append(k + "_raw")
    if accept != "status":
        cols.append("reserved")
    cols += ["payload", "frame"]
    return cols


UNITS = {}
for _t in zk.STATUS + zk.CONTROL:
    for _f in _t.fields:
        UNITS.setdefault(_f.key, _f.unit)
del _t, _f
_SKIP = {"kind", "id", "command", "frame"}


def summary(rec) -> str:
    """``rpm 0 rpm, engine_state_name stop, ...``: a record's fields for a table cell."""
    parts = []
    for k, v in rec.items():
        if k in _SKIP or v is None or k.endswith("_raw"):
            continue
        unit = UNITS.get(k, "")
        if k + "_name" in rec or k in ("sw",):
            continue
        parts.append(f"{k}={v}{' ' + unit if unit and unit != '%' else unit}")
    return "  ".join(parts)


TABLE_COLUMNS = [("kind", "kind"), ("id", "id"), ("_summary", "fields"), ("frame", "frame")]


@exits({CHECK_FAILED: "a single frame given as arguments has a bad CRC"})
@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("inputs", nargs=-1, metavar="[HEX...|FILE...]", type=InputPath("frames", "FILE"), shell_complete=binary_inputs)
@click.option("--binary", is_flag=True, help="Inputs are files of raw bytes ('-' or none: stdin).")
@format_option(choices=RECORD_FORMATS, help_extra=" influx: InfluxDB line protocol.")
@output_options(formats=RECORD_FORMATS)
@protocol_version_option
@click.option("--accept", type=Choice(["both", "status", "control"]), default="both", show_default=True,
              help="Which frame kinds to look for (a one-direction capture: status or control).")
@click.option("--raw", "raw", is_flag=True, help="Add <key>_raw entries with the undecoded field values.")
def decode(inputs, binary, fmt, output, append, protocol_version, accept, raw):
    """Decode ZK frames to a table, JSON, JSON Lines or CSV.

    Input is hex in any common notation (FF 14 64 D3, ff1464d3, 0xFF,0x14, xxd and
    hexdump -C dumps) as arguments or on stdin, raw bytes with --binary, or pcapng captures
    (--capture FILE; recognised by their content): their records add 'time', 't' (seconds
    since the capture began) and 'dir' (h2d host to ECU, d2h ECU to host). A stream may mix
    control and status frames and garbage: bad frames are skipped and counted on stderr. A
    single frame given as arguments with a bad CRC is an error (exit 1).

    Voltages of status IDs 2 and 6 are in 0.1 V up to protocol version 3 and 0.2 V from 4; the
    version comes from status ID 6 frames as they are seen, before that from
    --protocol-version, else 4 (and a note says so).

    \b
    Examples:
      zk decode FF 1D F4 70
      zk decode F1 00 00 00 00 4C A0 -f json
      zk decode --binary capture.bin -f csv -o capture.csv
      zk decode run.pcapng -o run.csv
      xxd capture.bin | zk decode --accept status
    """
    from ...api.capture import capture_inputs
    from ...io.sources import binary_chunks, hex_chunks, run_decode, run_text_decode, start
    from ...io.writers import csv_dialect, json_dialect, make_writer

    captures = capture_inputs(inputs, binary)
    if captures is not None:
        from ..capture_decode import zk_decode_captures

        return zk_decode_captures(captures, fmt=fmt, output=output, append=append,
                                  protocol_version=protocol_version, accept=accept, raw=raw)
    if binary:
        chunks, explicit = binary_chunks(list(inputs)), False
    else:
        chunks, explicit = hex_chunks(inputs)
    fmt = output_format(fmt, output, RECORD_FORMATS)
    cols = columns(accept, raw)
    framer = ZkFramer(accept)
    decoder = zk.ZkDecoder(protocol_version, raw=raw)
    warned = []

    def check_assumed():
        if decoder.assumed and not warned:
            warned.append(1)
            note(f"voltages assume protocol version {zk.DEFAULT_PROTOCOL_VERSION} (0.2 V) until a status "
                 "ID 6 frame is seen; set --protocol-version if the ECU is older")

    def decode_one(frame):
        rec = decoder.decode(frame)
        check_assumed()
        rec["_summary"] = summary(rec)
        return rec

    if explicit:
        data = chunks[0]
        frames = framer.feed(data)
        framer.flush()
        if not frames:
            _explain_single(data)
        framer = ZkFramer(accept)
    start(chunks)
    stream, had = open_output(output, append, fmt=fmt, columns=cols, inputs=decode_inputs(inputs, binary, explicit))
    writer = make_writer(fmt, stream, cols, table_columns=TABLE_COLUMNS, header=not had)
    try:
        if fmt in ("table", "influx"):
            run_decode(chunks, framer, decode_one, writer)
        else:
            # straight to text: encoders generated from the tables, a memo of repeated frames
            from ...io.zk_lines import ZkLines

            lines = ZkLines(decoder, csv_dialect(cols) if fmt == "csv" else json_dialect())
            run_text_decode(chunks, framer, lines, writer, check_assumed)
    finally:
        close_output(writer, stream)
    end_decode(framer, chunks, "frame", "CRC")


def _explain_single(data: bytes):
    """No valid frame in explicit input: say why, as precisely as the input allows."""
    if not data:
        raise UsageError("hex input: no bytes given")
    checked(zk.check_frame, data)
    checked(zk.check_defined, data)      # CRC right, but not a frame the framer takes
