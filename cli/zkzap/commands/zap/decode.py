"""``zap decode``: mightyZAP packets from hex arguments, hex text on stdin, or binary captures."""

from __future__ import annotations


import click

from ...codec import zap
from ...codec.framing import ZapFramer
from ...errors import UsageError
from .. import CONTEXT, Command
from ..complete import binary_inputs
from ..options import checked, close_output, format_option, note_skipped, open_output, output_options, resolve_format

COLUMNS = list(zap.ZAP_KEYS) + ["frame"]
TABLE_COLUMNS = [("kind", "kind"), ("id", "id"), ("_what", "instruction/error"), ("_detail", "data"),
                 ("frame", "frame")]


def _table_cells(rec):
    if rec["kind"] == "command":
        rec["_what"] = rec["instruction"]
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


@click.command(cls=Command, context_settings=CONTEXT)
@click.argument("inputs", nargs=-1, metavar="[HEX...|FILE...]", shell_complete=binary_inputs)
@click.option("--binary", is_flag=True, help="Inputs are files of raw bytes ('-' or none: stdin).")
@format_option()
@output_options
def decode(inputs, binary, fmt, output, append):
    """Decode mightyZAP packets to a table, JSON, JSON Lines or CSV.

    Commands and feedback are told apart by the byte after SIZE (an instruction code, or error
    bits). In a capture of both directions each feedback is paired with the Load Data it
    answers, so its data is named by register. Bad packets in a stream are skipped and counted
    on stderr; a single packet given as arguments with a bad checksum is an error (exit 1).

    \b
    Examples:
      zap decode FF FF FF 01 05 F3 86 FF 07 7A
      zap decode FF FF FF 00 04 F2 8C 02 7B FF FF FF 00 04 00 FF 07 F5 -f json
      zap decode --binary bus.bin -f csv -o bus.csv
    """
    from ...io.sources import binary_chunks, hex_chunks, run_decode
    from ...io.writers import make_writer

    if binary:
        chunks, explicit = binary_chunks(list(inputs)), False
    else:
        chunks, explicit = hex_chunks(inputs)
    stream, had = open_output(output, append)
    fmt = resolve_format(fmt, stream)
    framer = ZapFramer()
    decoder = zap.ZapDecoder()
    if explicit:
        probe = ZapFramer()
        if not probe.feed(chunks[0]):
            _explain_single(chunks[0])
    decode_one = (lambda p: _table_cells(decoder.decode(p))) if fmt == "table" else decoder.decode
    writer = make_writer(fmt, stream, COLUMNS, table_columns=TABLE_COLUMNS, header=not had)
    try:
        run_decode(chunks, framer, decode_one, writer)
    finally:
        close_output(writer, stream)
    note_skipped(framer, "packet", "checksum")


def _explain_single(data: bytes):
    if not data:
        raise UsageError("hex input: no bytes given")
    checked(zap.check_packet, data)
