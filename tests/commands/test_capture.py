"""--capture on the port options, and the decoders reading captures back with their times,
directions and mightyZAP reply latencies."""

from __future__ import annotations

import json

import pytest

from zkzap.codec import zap, zk
from zkzap.codec.framing import ZapFramer
from zkzap.link.pcapng import INBOUND, OUTBOUND, Reader, Writer


def jsonl(text):
    return [json.loads(line) for line in text.splitlines()]


def test_zk_send_for_captures_both_directions(cli, tmp_path):
    cap = tmp_path / "run.pcapng"
    r = cli("zk", "send", "control", "--state", "stop", "--for", "1.5", "--sim", "-f", "jsonl",
            "--capture", str(cap))
    assert r.exit_code == 0, r.stderr
    live = jsonl(r.stdout)
    pkts = list(Reader(str(cap), "zk"))
    assert {p.direction for p in pkts} == {INBOUND, OUTBOUND}
    sent = b"".join(p.data for p in pkts if p.direction == OUTBOUND)
    frame = zk.encode_control("control", sw="stop")[0]
    assert sent.count(frame) >= 10 and len(sent) % 4 == 0
    assert all(a.ts <= b.ts for a, b in zip(pkts, pkts[1:]))
    # what the monitor logged is in the capture, frame for frame, in order
    d = cli("zk", "decode", str(cap), "--accept", "status", "-f", "jsonl")
    assert d.exit_code == 0, d.stderr
    recs = jsonl(d.stdout)
    assert all(rec["dir"] == "d2h" for rec in recs)
    frames = [rec["frame"] for rec in recs]
    logged = [rec["frame"] for rec in live]
    i = frames.index(logged[0])
    assert frames[i:i + len(logged)] == logged
    assert 0 <= recs[0]["t"] < 1 and all(a["t"] <= b["t"] for a, b in zip(recs, recs[1:]))
    both = jsonl(cli("zk", "decode", str(cap)).stdout)
    assert {rec["dir"] for rec in both if rec["kind"] == "control"} == {"h2d"}
    assert both[0]["time"].endswith("Z")


def test_zap_capture_gives_latencies(cli, tmp_path):
    cap = tmp_path / "bus.pcapng"
    r = cli("zap", "load", "present-position", "--id", "1", "--sim", "--capture", str(cap))
    assert r.exit_code == 0, r.stderr
    d = cli("zap", "decode", str(cap), "-f", "jsonl")
    recs = jsonl(d.stdout)
    assert [(x["kind"], x["dir"]) for x in recs] == [("command", "h2d"), ("feedback", "d2h")]
    assert recs[1]["register"] == "present-position" and recs[1]["value"] == int(r.stdout)
    assert 0 <= recs[1]["latency_ms"] < 5000
    csv = cli("zap", "decode", "--binary", str(cap), "-f", "csv").stdout.splitlines()
    assert csv[0].startswith("time,t,dir,kind,id,") and csv[0].endswith(",frame,latency_ms")


def test_a_dry_run_writes_no_capture_and_a_port_gets_an_interface(cli, tmp_path):
    cap = tmp_path / "dump.pcapng"
    assert cli("zap", "echo", "-n", "--capture", str(cap)).exit_code == 0
    assert not cap.exists()
    r = cli("zap", "dump", "--id", "3", "--sim", "--capture", str(cap), "-f", "jsonl")
    assert r.exit_code == 0, r.stderr
    rd = Reader(str(cap), "zap")
    pkts = list(rd)
    assert rd.interfaces == [("zap", "sim://zap?ids=3&baud=57600", 1_000_000)]
    replies = ZapFramer().feed(b"".join(p.data for p in pkts if p.direction == INBOUND))
    requests = ZapFramer().feed(b"".join(p.data for p in pkts if p.direction != INBOUND))
    assert replies and all(d[3] == 3 for d in replies)
    assert len(requests) == len(replies)


def test_capture_that_cannot_be_opened_is_a_usage_error(cli, tmp_path):
    r = cli("zk", "monitor", "--sim", "--count", "1", "--capture", str(tmp_path / "no" / "x.pcapng"))
    assert r.exit_code == 2 and "capture: cannot open" in r.stderr and r.stdout == ""


def _synthetic(path, protocol, chunks):
    w = Writer(str(path))
    i = w.interface(protocol, "test")
    for ts, data, d in chunks:
        w.packet(i, ts, data, d)
    w.close()


def test_frames_split_across_chunks_are_whole_again_and_directions_do_not_mix(cli, tmp_path):
    req = zap.packet(1, 0xF2, bytes([0x8C, 2]))
    rep = zap.packet(1, 0, (2047).to_bytes(2, "little"))
    cap = tmp_path / "split.pcapng"
    _synthetic(cap, "zap", [(10.0, req[:4], OUTBOUND), (10.0005, rep[:3], INBOUND), (10.001, req[4:], OUTBOUND),
                            (10.0125, rep[3:], INBOUND)])
    recs = jsonl(cli("zap", "decode", str(cap)).stdout)
    assert [x["kind"] for x in recs] == ["command", "feedback"]
    assert recs[1]["value"] == 2047 and recs[1]["latency_ms"] == 11.5 and recs[1]["t"] == 0.0125


def test_monitor_replays_a_capture_with_its_own_times(cli, tmp_path):
    frames = [zk.encode_status(i % 10 + 1, 6, rpm=1000 * i) for i in range(1, 31)]
    frames[5] = zk.encode_status(6, 6, protocol_version=6, status_rate_hz=50)
    cap = tmp_path / "ecu.pcapng"
    t0 = 1767225600.0               # 2026-01-01T00:00:00Z
    _synthetic(cap, "zk", [(t0 + i * 0.02, f, INBOUND) for i, f in enumerate(frames)])
    r = cli("zk", "monitor", "--replay", str(cap), "--fast", "-f", "jsonl")
    assert r.exit_code == 0, r.stderr
    recs = jsonl(r.stdout)
    assert [x["frame"] for x in recs] == [f.hex(" ").upper() for f in frames]
    assert recs[0]["time"] == "2026-01-01T00:00:00.000Z" and recs[10]["t"] == 0.2


def test_a_truncated_capture_decodes_to_its_last_whole_block_and_says_so(cli, tmp_path):
    cap = tmp_path / "cut.pcapng"
    frames = [zk.encode_status(1, 6, rpm=10 * i) for i in range(5)]
    _synthetic(cap, "zk", [(1.0 + i, f, INBOUND) for i, f in enumerate(frames)])
    cap.write_bytes(cap.read_bytes()[:-6])
    r = cli("zk", "decode", str(cap))
    assert r.exit_code == 0
    assert len(jsonl(r.stdout)) == 4
    assert f"{cap}: the capture is truncated: decoded up to its last whole block (4 chunks)" in r.stderr


def _lying(path, protocol, frames, length, dirs=None):
    """A capture of ``frames`` whose third packet block claims ``length`` bytes (0: its body is
    cut to two of its five fields, consistently framed)."""
    import struct

    dirs = dirs or [INBOUND] * len(frames)
    _synthetic(path, protocol, [(1.0 + i, f, d) for i, (f, d) in enumerate(zip(frames, dirs))])
    raw = bytearray(path.read_bytes())
    off, n = 0, []
    while off < len(raw):
        btype, blen = struct.unpack("<II", raw[off:off + 8])
        if btype == 6:
            n.append((off, blen))
        off += blen
    off, blen = n[2]
    if length:
        raw[off + 4:off + 8] = struct.pack("<I", length)
    else:
        raw[off:off + blen] = struct.pack("<II", 6, 20) + bytes(8) + struct.pack("<I", 20)
    path.write_bytes(bytes(raw))


def _limited(limit):
    """A subprocess's address space at most ``limit`` bytes (a 4 GiB allocation fails)."""
    def pre():
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    return pre


@pytest.mark.parametrize("length,said", [(0, "1 malformed block skipped (the first at byte"),
                                         (0xFFFFFFFF, "damaged at byte"), (0xFFFFFFF0, "damaged at byte")])
@pytest.mark.parametrize("cmd", [("zk", "decode"), ("zap", "decode"), ("zk", "monitor", "--fast", "--replay")])
def test_a_capture_that_lies_about_a_block_decodes_the_rest_in_bounded_memory(tmp_path, cmd, length, said):
    import subprocess
    import sys

    cap = tmp_path / "lie.pcapng"
    if cmd[0] == "zap":
        frames = [zap.packet(1, 0, bytes([i])) for i in range(6)]
    else:
        frames = [zk.encode_status(1, 6, rpm=10 * i) for i in range(6)]
    _lying(cap, cmd[0], frames, length)
    code = "import sys; from zkzap.commands import run, root; sys.exit(run(root, 'zkzap', sys.argv[1:]))"
    p = subprocess.run([sys.executable, "-c", code, *cmd, str(cap), "-f", "jsonl"], capture_output=True, text=True,
                       timeout=60, preexec_fn=_limited(1 << 30), env={**__import__("os").environ, "NO_COLOR": "1"})
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr and said in p.stderr
    assert len(jsonl(p.stdout)) == (5 if length == 0 else 2)


def test_a_replay_simulator_plays_what_is_whole_of_a_lying_capture(tmp_path):
    from zkzap.sim.replay import ZkReplay, recorded_replies

    cap = tmp_path / "zk.pcapng"
    _lying(cap, "zk", [zk.encode_status(1, 6, rpm=10 * i) for i in range(6)], 0)
    sent = ZkReplay(str(cap)).poll(1e9)
    assert sent == b"".join(zk.encode_status(1, 6, rpm=10 * i) for i in range(6) if i != 2)
    cap = tmp_path / "zap.pcapng"
    req = zap.packet(1, 0xF1, b"")
    _lying(cap, "zap", [req, zap.packet(1, 0, b""), req, zap.packet(1, 0x20, b""), req, zap.packet(1, 1, b"")],
           0xFFFFFFFF, [OUTBOUND, INBOUND] * 3)
    table, ids = recorded_replies(str(cap))
    assert table == {req: [(zap.packet(1, 0, b""), 1.0)]} and ids == {1}      # read up to the damage


@pytest.mark.parametrize("cmd", [("zk", "decode"), ("zap", "decode"), ("zk", "monitor", "--fast", "--replay")])
def test_not_a_capture_is_refused_naming_the_file(cli, tmp_path, cmd):
    bad = tmp_path / "notes.pcapng"
    bad.write_text("hello\n")
    out = tmp_path / "out.jsonl"
    out.write_text("keep\n")
    r = cli(*cmd, str(bad), *(["-o", str(out)] if cmd[-1] == "decode" else []))
    assert r.exit_code == 2 and r.stdout == ""
    assert f"{bad}: not a pcapng capture: text (starts with 68 65 6C 6C)" in r.stderr
    assert out.read_text() == "keep\n"


def test_a_capture_of_the_other_protocol_is_refused(cli, tmp_path):
    cap = tmp_path / "zk.pcapng"
    _synthetic(cap, "zk", [(1.0, zk.encode_status(1, 6), INBOUND)])
    r = cli("zap", "decode", str(cap))
    assert r.exit_code == 2 and "a ZK capture (link type 147); expected mightyZAP" in r.stderr


@pytest.mark.parametrize("fmt", ["jsonl", "csv", "json"])
def test_the_text_path_gives_the_records_of_the_record_path(cli, tmp_path, fmt):
    import csv as csvmod
    import io

    from zkzap.api.capture import TIME_KEYS, CaptureFrames, zk_records
    from zkzap.commands.zk.decode import columns
    from zkzap.io.writers import csv_cell

    cap = tmp_path / "run.pcapng"
    assert cli("zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "0.5", "--yes",
               "-p", "sim://zk?speed=20", "--capture", str(cap), "-f", "jsonl").exit_code == 0
    expected = list(zk_records(CaptureFrames(str(cap), "zk"), zk.ZkDecoder()))
    out = cli("zk", "decode", str(cap), "-f", fmt).stdout
    if fmt == "jsonl":
        assert [json.loads(x) for x in out.splitlines()] == expected
    elif fmt == "json":
        assert json.loads(out) == expected
    else:
        rows = list(csvmod.reader(io.StringIO(out)))
        cols = TIME_KEYS + columns()
        assert rows[0] == cols
        assert rows[1:] == [[csv_cell(r.get(c)) for c in cols] for r in expected]


def test_a_batch_captures_every_line_over_its_one_port(sh, tmp_path):
    """The lines of a batch have no --capture of their own: the batch's goes on through all."""
    cap = tmp_path / "batch.pcapng"
    r = sh("zap", "batch", "--sim", "--capture", str(cap), "-",
           input="load present-position --id 1\necho --id 1\nload goal-position --id 1\n")
    assert r.exit_code == 0, r.stderr
    recs = jsonl(sh("zap", "decode", str(cap), "-f", "jsonl").stdout)
    assert [(x["kind"], x.get("instruction"), x["dir"]) for x in recs] == [
        ("command", "load", "h2d"), ("feedback", None, "d2h"), ("command", "echo", "h2d"),
        ("feedback", None, "d2h"), ("command", "load", "h2d"), ("feedback", None, "d2h")]
    cap = tmp_path / "zk.pcapng"
    r = sh("zk", "batch", "--sim", "--capture", str(cap), "-", input="send control --state stop\nsend keepalive\n")
    assert r.exit_code == 0, r.stderr
    sent = [x for x in jsonl(sh("zk", "decode", str(cap), "-f", "jsonl").stdout) if x["kind"] == "control"]
    assert [x["command"] for x in sent] == ["control", "keepalive"]
