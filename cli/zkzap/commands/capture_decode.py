"""``zk decode`` / ``zap decode`` of pcapng captures: records with the capture's time and
direction (and mightyZAP reply latencies), through the same writers as the other inputs."""

from __future__ import annotations

from ..io import RECORD_FORMATS
from .options import close_output, note, open_output, output_format

#: Records per block written (each block flushed whole).
BLOCK = 512


def _run(records, writer, frames_list):
    block = []
    for rec in records:
        block.append(rec)
        if len(block) >= BLOCK:
            writer.write_many(block)
            block = []
    if block:
        writer.write_many(block)


def zk_decode_captures(paths, *, fmt, output, append, protocol_version, accept, raw):
    from ..api.capture import TIME_KEYS, CaptureFrames, check_captures, zk_records
    from ..codec import zk
    from ..io.writers import make_writer
    from .zk.decode import TABLE_COLUMNS, columns, summary

    check_captures(paths, "zk")
    fmt = output_format(fmt, output, RECORD_FORMATS)
    stream, had = open_output(output, append)
    decoder = zk.ZkDecoder(protocol_version, raw=raw)
    if fmt == "table":
        def decode(frame):
            rec = decoder.decode(frame)
            rec["_summary"] = summary(rec)
            return rec
    else:
        decode = decoder.decode
    table = [("t", "t"), ("dir", "dir")] + TABLE_COLUMNS
    writer = make_writer(fmt, stream, TIME_KEYS + columns(accept, raw), table_columns=table, header=not had)
    done = []
    try:
        for path in paths:
            frames = CaptureFrames(path, "zk", accept)
            if fmt not in ("csv", "json", "jsonl"):      # table, influx: record by record
                _run(zk_records(frames, decoder, decode), writer, done)
            else:
                # straight to text: the table-generated encoders and their memo, as for raw bytes
                from ..io.writers import csv_dialect, json_dialect
                from ..io.zk_lines import ZkLines, capture_lines

                lines = ZkLines(decoder, csv_dialect(columns(accept, raw)) if fmt == "csv" else json_dialect())
                pending = []
                for block in capture_lines(frames, lines, fmt == "csv"):
                    pending += block
                    if len(pending) >= BLOCK:
                        writer.write_lines(pending)
                        pending = []
                if pending:
                    writer.write_lines(pending)
            done.append(frames)
    finally:
        close_output(writer, stream)
    if decoder.assumed:
        note(f"voltages assume protocol version {zk.DEFAULT_PROTOCOL_VERSION} (0.2 V) until a status "
             "ID 6 frame is seen; set --protocol-version if the ECU is older")
    _notes(done, "frames", "CRC")


def zap_decode_captures(paths, *, fmt, output, append, table_cells, protocol="zap", regmap=None):
    """``zap decode`` of captures: the IR protocol's (``protocol`` zap) or Modbus RTU's
    (``modbus``, named by ``regmap``)."""
    from ..api.capture import TIME_KEYS, CaptureFrames, check_captures, modbus_records, zap_records
    from ..io.writers import make_writer
    from .zap import decode as zap_decode

    check_captures(paths, protocol)
    fmt = output_format(fmt, output, RECORD_FORMATS)
    stream, had = open_output(output, append)
    if protocol == "modbus":
        from ..codec import modbus

        decoder, records = modbus.ModbusDecoder(regmap), modbus_records
        columns, table_columns = zap_decode.MODBUS_COLUMNS, zap_decode.MODBUS_TABLE
        decode = (lambda f, d: table_cells(decoder.decode(f, d))) if fmt == "table" else decoder.decode
    else:
        from ..codec import zap

        decoder, records = zap.ZapDecoder(), zap_records
        columns, table_columns = zap_decode.COLUMNS, zap_decode.TABLE_COLUMNS
        decode = (lambda p: table_cells(decoder.decode(p))) if fmt == "table" else decoder.decode
    table = [("t", "t"), ("dir", "dir")] + table_columns + [("latency_ms", "latency ms")]
    writer = make_writer(fmt, stream, TIME_KEYS + columns + ["latency_ms"], table_columns=table, header=not had)
    done = []
    try:
        for path in paths:
            frames = CaptureFrames(path, protocol)
            _run(records(frames, decoder, decode), writer, done)
            done.append(frames)
    finally:
        close_output(writer, stream)
    _notes(done, "frames" if protocol == "modbus" else "packets", "CRC" if protocol == "modbus" else "checksum")


def _notes(done, what, check):
    for frames in done:
        if frames.bad or frames.skipped:
            note(f"{frames.path}: {frames.frames} {what} decoded; {frames.bad} bad ({check}), "
                 f"{frames.skipped} bytes skipped")
        text = frames.reading_note()
        if text:
            note(text)
