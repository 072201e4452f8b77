"""Block writers: many records per write, whole lines only, same text as record by record."""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import time

from zkzap.codec import zk
from zkzap.codec.framing import ZkFramer
from zkzap.io.writers import csv_dialect, json_dialect, make_writer
from zkzap.io.zk_lines import ZkLines

RECS = [{"kind": "status", "id": 1, "rpm": 0, "x": 1.5, "n": None, "l": ["a", "b"]},
        {"kind": "control", "id": 2, "text": 'a,"b"'}]
COLS = ["kind", "id", "rpm", "x", "n", "l", "text"]


def per_record(fmt):
    buf = io.StringIO()
    w = make_writer(fmt, buf, COLS)
    for r in RECS:
        w.write(r)
    w.close()
    return buf.getvalue()


def test_blocks_equal_records_on_a_file_descriptor(tmp_path):
    for fmt in ("jsonl", "json", "csv"):
        path = tmp_path / f"out.{fmt}"
        with open(path, "w", encoding="utf-8", newline="") as f:
            w = make_writer(fmt, f, COLS)
            w.write_many(RECS[:1])
            w.write_many(RECS[1:])
            assert w._fd == f.fileno()         # went straight to the descriptor
            w.close()
        assert path.read_text() == per_record(fmt)


def test_blocks_equal_records_on_a_text_stream():
    for fmt in ("jsonl", "json", "csv"):
        buf = io.StringIO()
        w = make_writer(fmt, buf, COLS)
        w.write_many(RECS)
        w.close()
        assert buf.getvalue() == per_record(fmt)


def test_rendered_lines_through_the_writers():
    frames = [zk.status_frame(i, b"\x01\x02\x03\x04\x05") for i in range(1, 11)]
    for fmt, dialect in (("jsonl", json_dialect()), ("csv", csv_dialect(COLS))):
        buf = io.StringIO()
        w = make_writer(fmt, buf, COLS)
        framer = ZkFramer()
        w.write_lines(framer.feed_lines(b"".join(frames), ZkLines(zk.ZkDecoder(), dialect)))
        w.close()
        assert len(buf.getvalue().splitlines()) == 10 + (fmt == "csv")


def test_a_terminated_decoder_leaves_whole_lines(tmp_path):
    """SIGTERM while a capture streams in: the file holds whole JSON lines only."""
    out = tmp_path / "log.jsonl"
    frame = zk.status_frame(2, b"\x10\x00\x32\x78\x1e")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    p = subprocess.Popen([sys.executable, "-c", "import sys; from zkzap.commands import zk_main; "
                          "sys.argv[0] = 'zk'; zk_main()", "decode", "--binary", "-", "-o", str(out)],
                         stdin=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env)
    block = frame * 9000
    deadline = time.monotonic() + 20
    try:
        while time.monotonic() < deadline:
            p.stdin.write(block)
            p.stdin.flush()
            if out.exists() and out.stat().st_size > 2_000_000:
                break
        p.send_signal(signal.SIGTERM)
    finally:
        try:
            p.stdin.close()
        except BrokenPipeError:
            pass
        p.wait(10)
    text = out.read_text()
    assert text and text.endswith("\n")
    lines = text.splitlines()
    assert all(json.loads(line)["id"] == 2 for line in lines)
