"""MCAP logs (``-o run.mcap``, ``-f mcap``): schemas from the protocol tables, read back with the
``mcap`` reader and compared with the JSON Lines of the same frames, control channels, and a
whole file after Ctrl-C."""

from __future__ import annotations

import calendar
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from zkzap.codec import zk

pytest.importorskip("mcap")
from mcap.reader import make_reader  # noqa: E402

from zkzap.io.mcap import control_schema, status_schema  # noqa: E402


def read(path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = [(schema, channel, message, json.loads(message.data))
                    for schema, channel, message in reader.iter_messages(log_time_order=False)]
    return summary, messages


def ns(text):
    sec = calendar.timegm(time.strptime(text[:19], "%Y-%m-%dT%H:%M:%S"))
    return sec * 10**9 + int(text[20:23]) * 10**6


@pytest.mark.parametrize("spec", zk.STATUS, ids=lambda s: f"status-{s.id}")
def test_every_status_key_is_in_its_schema_with_its_unit(spec):
    schema = status_schema(spec.id)
    props = schema["properties"]
    assert props["id"]["const"] == spec.id
    for f in spec.fields:
        assert f.key in props, f.key
        if f.unit:
            assert f"({f.unit})" in props[f.key]["description"]
        if f.name_key:
            assert props[f.name_key]["type"] == ["string", "null"]
    assert set(spec.layout.keys()) <= set(props)


def test_units_and_types_in_a_worked_schema():
    props = status_schema(7)["properties"]
    assert props["fuel_flow_l_min"] == {"type": ["number", "null"], "description": "fuel flow rate (L/min)"}
    assert status_schema(1)["properties"]["egt_c"]["type"] == ["integer", "null"]
    assert "(°C)" in status_schema(1)["properties"]["egt_c"]["description"]
    assert control_schema("control")["properties"]["throttle_pct"]["description"].endswith("(%)")


def _compare(messages, want, summary, timing=True):
    got = [m[3] for m in sorted(messages, key=lambda m: (m[2].log_time, m[3]["t"]))]
    # a live run's times are its own; the frames, their order and every decoded value are the same
    skip = {"time"} if timing else {"time", "t", "stale", "stale_ids"}
    strip = lambda rec: {k: v for k, v in rec.items() if k not in skip}   # noqa: E731
    assert [strip(g) for g in got] == [strip(w) for w in want]
    per_channel = {}
    for _, channel, message, data in messages:
        assert channel.topic == f"/zk/status/{data['id']}"
        want_ns = ns(data["time"]) if data["time"] is not None else round(data["t"] * 1e9)
        # the record's time, or (records within its millisecond) the nanoseconds after it:
        # every message has its own time
        assert message.log_time == message.publish_time and 0 <= message.log_time - want_ns < 1000
        assert message.sequence == per_channel.get(channel.id, 0)
        per_channel[channel.id] = message.sequence + 1
        schema = json.loads(summary.schemas[channel.schema_id].data)
        assert set(data) <= set(schema["properties"])
    times = [(m[1].topic, m[2].log_time) for m in messages]
    assert len(set(times)) == len(times)                       # per channel, each its own time


def test_a_live_run_in_mcap_equals_the_json_lines_of_its_frames(cli, tmp_path):
    raw, out = tmp_path / "run.bin", tmp_path / "run.mcap"
    r = cli("zk", "monitor", "-p", "sim://zk?speed=10", "--duration", "15", "-o", str(out), "--raw-log", str(raw))
    assert r.exit_code == 0 and r.stdout == "", r
    r = cli("zk", "monitor", "--replay", str(raw), "--fast", "-f", "jsonl")
    assert r.exit_code == 0, r
    want = want_all = [json.loads(x) for x in r.stdout.splitlines()]
    summary, messages = read(out)
    assert summary is not None and summary.chunk_indexes, "chunked and indexed"
    # the raw log keeps every byte received; the live run stops its records at --duration, so
    # the last read may have brought a frame or two more than it recorded
    assert summary.statistics.message_count == len(messages) > 100 and 0 <= len(want) - len(messages) <= 3
    want = want[:len(messages)]
    assert {c.topic for c in summary.channels.values()} == {f"/zk/status/{i}" for i in range(1, 11)}
    assert {s.encoding for s in summary.schemas.values()} == {"jsonschema"}
    assert {c.message_encoding for c in summary.channels.values()} == {"json"}
    _compare(messages, want, summary, timing=False)
    # a replay into MCAP gives the very records of the replay into JSON Lines, times included
    out2 = tmp_path / "replay.mcap"
    r = cli("zk", "monitor", "--replay", str(raw), "--fast", "-o", str(out2))
    assert r.exit_code == 0, r
    summary, messages = read(out2)
    _compare(messages, want_all, summary)


def test_a_controlling_session_logs_its_control_frames_too(cli, tmp_path):
    out = tmp_path / "run.mcap"
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "40", "--for", "10", "-p", "sim://zk?speed=10",
            "--rate", "20", "--end", "hold", "-f", "mcap", "-o", str(out))
    assert r.exit_code == 0, r
    summary, messages = read(out)
    control = [d for _, c, _, d in messages if c.topic == "/zk/control/control"]
    status = [d for _, c, _, d in messages if c.topic.startswith("/zk/status/")]
    # 20 Hz for 10 s of model time: at most 200 (the rate itself: benchmarks/session_clock.py)
    assert 1 <= len(control) <= 201 and len(status) > 50
    assert all(d["state"] == "run" and d["throttle_pct"] == 40.0 and d["frame"] for d in control)
    # one clock: control and status records map session time to the same wall clock (t in model
    # seconds at speed 10), so both channels span the same stretch of real time
    offsets = {c.topic.split("/")[2]: set() for _, c, _, _ in messages}
    for _, c, m, d in messages:
        offsets[c.topic.split("/")[2]].add(round((m.log_time / 1e9 - d["t"] / 10) * 100))
    both = offsets["control"] | offsets["status"]
    assert max(both) - min(both) <= 1                  # the same origin, within the ms rounding
    schema = next(json.loads(s.data) for s in summary.schemas.values() if s.name == "zk.control.control")
    assert schema["properties"]["command"]["const"] == "control"


def test_mcap_is_whole_after_ctrl_c(tmp_path):
    exe = os.path.join(os.path.dirname(sys.executable), "zk")
    if not os.path.exists(exe):
        pytest.skip("zk is not installed")
    out, raw = tmp_path / "run.mcap", tmp_path / "raw.bin"
    env = {k: v for k, v in os.environ.items() if not k.startswith("ZKZAP_")}
    p = subprocess.Popen([exe, "monitor", "-p", "sim://zk?speed=50", "-o", str(out), "--raw-log", str(raw)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    try:
        deadline = time.monotonic() + 60
        while (not raw.exists() or raw.stat().st_size == 0) and time.monotonic() < deadline and p.poll() is None:
            time.sleep(0.05)                # records are flowing once the raw log has bytes
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, err
    summary, messages = read(out)
    assert summary is not None and summary.statistics.message_count == len(messages) > 0


def test_mcap_refusals_touch_nothing(cli, tmp_path):
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"keep")
    for args, word in ((("-o", str(existing), "--append"), "append"),
                       (("-o", str(existing), "--snapshot"), "snapshot")):
        r = cli("zk", "monitor", "-p", "/dev/nonexistent-zkzap", *args)
        assert r.exit_code == 2 and r.stdout == "" and word in r.stderr, r
    assert existing.read_bytes() == b"keep"
    r = cli("zk", "monitor", "-p", "/dev/nonexistent-zkzap", "-f", "mcapx")
    assert r.exit_code == 2
