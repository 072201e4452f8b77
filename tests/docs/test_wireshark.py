"""The Wireshark dissector: the committed file is what the generator makes from the tables, and
tshark with it decodes captures zkzap wrote exactly as zkzap does, frame by frame."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import xml.etree.ElementTree as ET

import pytest

from zkzap.codec import zap, zk
from zkzap.docs import wireshark
from zkzap.link.pcapng import INBOUND, OUTBOUND, UNKNOWN, Writer

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LUA = os.path.join(REPO, wireshark.PATH)
TSHARK = shutil.which("tshark")
needs_tshark = pytest.mark.skipif(TSHARK is None, reason="tshark is not installed (.ci/run installs it)")


def test_committed_dissector_is_current():
    with open(LUA, encoding="utf-8") as f:
        assert f.read() == wireshark.source(), "share/wireshark/zkzap.lua is stale; run python -m zkzap.docs all"


def test_the_wheel_installs_it():
    with open(os.path.join(REPO, "pyproject.toml"), encoding="utf-8") as f:
        assert '"share/wireshark" = "share/zkzap/wireshark"' in f.read()


_DISSECTED = {}


def tshark(path):
    """Every dissected frame of the capture: (proto, {field: [shows]}) in order; bad ones too.
    Each capture is dissected once per session (tshark's start-up is most of its cost)."""
    key = str(path)
    if key not in _DISSECTED:
        _DISSECTED[key] = _run_tshark(path)
    return _DISSECTED[key]


def _run_tshark(path):
    env = dict(os.environ, HOME=os.environ.get("HOME", "/tmp"))
    p = subprocess.run([TSHARK, "-n", "-X", f"lua_script:{LUA}", "-o", "gui.max_tree_depth:64", "-r", str(path),
                        "-T", "pdml"], capture_output=True, text=True, timeout=120, env=env)
    assert p.returncode == 0, p.stderr
    assert "Lua" not in p.stderr and "error" not in p.stderr.lower(), p.stderr
    frames = []
    for packet in ET.fromstring(p.stdout).iter("packet"):
        for proto in packet.iter("proto"):
            name = proto.get("name")
            if name not in ("zk", "zap", "zapmodbus"):
                continue
            fields = {}
            for f in proto.iter("field"):
                fields.setdefault(f.get("name"), []).append(f.get("show"))
            frames.append((name, fields))
    return frames


def same(expected, shown: str) -> bool:
    if isinstance(expected, bool):
        return shown in (("True", "1") if expected else ("False", "0"))
    if isinstance(expected, (int, float)):
        if shown.startswith("0x"):
            return int(shown, 16) == expected
        return abs(float(shown) - expected) <= 1e-6 * max(1.0, abs(expected))
    if isinstance(expected, list):
        return shown == ",".join(str(x) for x in expected)
    if isinstance(expected, dict):
        return shown == ";".join(f"{k}={v}" for k, v in expected.items())
    return shown == expected


SKIP = {"frame", "time", "t"}


def compare(records, frames, proto):
    good = [f for p, f in frames if p == proto and f"{proto}.bad" not in f]
    assert len(good) == len(records), (len(good), len(records))
    for n, (rec, fields) in enumerate(zip(records, good)):
        assert fields[f"{proto}.frame"][0].replace(":", "").upper() == rec["frame"].replace(" ", ""), n
        for key, value in rec.items():
            if key in SKIP or (key == "dir" and value is None):
                continue
            shown = fields.get(f"{proto}.{key}")
            if value is None or (key in ("errors", "params") and value in ([], "")):
                assert shown is None or shown == [""], (n, key, shown, rec)
                continue
            assert shown is not None, (n, key, rec)
            assert same(value, shown[0]), (n, key, value, shown, rec)
        assert fields[f"{proto}.{'checksum_ok' if proto == 'zap' else 'crc_ok'}"][0] in ("True", "1")
    return len(good)


def decoded(cli, cmd, path):
    r = cli(cmd, "decode", str(path), "-f", "jsonl")
    assert r.exit_code == 0, r.stderr
    return [json.loads(x) for x in r.stdout.splitlines()]


@pytest.fixture(scope="module")
def zk_captures(tmp_path_factory):
    d = tmp_path_factory.mktemp("zk")
    from zkzap.commands import root, run
    from click.testing import CliRunner

    out = []
    for name, url, args in [
        ("run", "sim://zk?speed=20", ["send", "control", "--state", "run", "--throttle", "45", "--for", "15",
                                      "--yes"]),
        ("v3", "sim://zk?speed=20&protocol_version=3", ["monitor", "--count", "30"]),
    ]:
        path = d / f"{name}.pcapng"
        with CliRunner().isolation():
            assert run(root, "zkzap", ["zk", *args, "-p", url, "-f", "jsonl", "--capture", str(path)]) == 0
        out.append(path)
    # every control command and odd status frames, split across chunks, one bad CRC
    frames = [zk.encode_control("mode", sw="run", rpm_factor=3)[0], zk.encode_control("rpm", target_rpm=60000,
                                                                                     rpm_factor=3)[0],
              zk.encode_control("action", param="pump-on")[0], zk.encode_control("ignition-voltage",
                                                                                ignition_voltage_v=3.2)[0],
              zk.encode_control("accel-curve", accel_curve=40)[0], zk.encode_control("pressure", pressure_hpa=1013)[0],
              zk.control_frame(1, 0x0F, 0xFF),
              zk.encode_control_raw(0, reserved_b1=5), zk.encode_control("unlock")[0]]
    status = [zk.encode_status(i, 6, rpm=12340) for i in range(1, 11)] + [zk.status_frame(12, b"\x01\x02\x03\x04\x05")]
    w = Writer(str(d / "all.pcapng"))
    i = w.interface("zk", "synthetic")
    ts = 1767225600.0
    host = b"".join(frames)
    for k in range(0, len(host), 5):
        w.packet(i, ts, host[k:k + 5], OUTBOUND)
        ts += 0.001
    ecu = b"".join(status[:5]) + b"\xf1\x00\x00\x00\x00\x00\x00" + b"".join(status[5:])
    for k in range(0, len(ecu), 9):
        w.packet(i, ts, ecu[k:k + 9], INBOUND)
        ts += 0.001
    mixed = b"".join(frames[:3]) + b"".join(status[:3])
    w.packet(i, ts, mixed, UNKNOWN)
    w.close()
    out.append(d / "all.pcapng")
    return out


@needs_tshark
def test_tshark_decodes_zk_captures_as_zkzap_does(cli, zk_captures):
    total = 0
    for path in zk_captures:
        total += compare(decoded(cli, "zk", path), tshark(path), "zk")
    assert total > 100


@needs_tshark
def test_tshark_marks_a_bad_crc(zk_captures):
    frames = tshark(zk_captures[-1])
    bad = [f for p, f in frames if "zk.bad" in f]
    assert len(bad) == 1 and bad[0]["zk.bad"][0].replace(":", "") == "f1000000000000"
    assert bad[0]["zk.crc_ok"] == ["False"] or bad[0]["zk.crc_ok"] == ["0"]


@pytest.fixture(scope="module")
def zap_captures(tmp_path_factory):
    d = tmp_path_factory.mktemp("zap")
    from zkzap.commands import root, run
    from click.testing import CliRunner

    out = []
    sim = "sim://zap?ids=1,2&return_mode=2&faults=2:voltage=6.5"
    for n, args in enumerate([
        ["echo", "--id", "5", "-p", "sim://zap?ids=1"],          # never answered: three tries
        ["scan", "--sim", "--sim-ids", "1,3", "--ids", "0-40"],
        ["dump", "--id", "1", "-p", sim],
        ["store", "goal-position", "2000", "--id", "1", "-p", sim, "--return-mode", "2"],
        ["load", "present-voltage", "--id", "2", "-p", sim],
        ["sync-move", "1:1000", "2:3000", "-p", sim],
        ["factory-reset", "--id", "1", "--reset-id", "-p", sim, "--yes", "--force", "--return-mode", "2"],
        ["load", "model-number", "--length", "4", "--id", "1", "-p", sim],
    ]):
        path = d / f"c{n}.pcapng"
        with CliRunner().isolation():
            code = run(root, "zkzap", ["zap", *args, "--capture", str(path)])
        assert code in (0, 3, 5) and path.exists(), args
        out.append(path)
    return out


@needs_tshark
def test_tshark_decodes_zap_captures_as_zkzap_does_and_links_replies(cli, zap_captures):
    total = linked = 0
    for path in zap_captures:
        recs = decoded(cli, "zap", path)
        frames = tshark(path)
        total += compare(recs, frames, "zap")
        good = [f for p, f in frames if p == "zap" and "zap.bad" not in f]
        for rec, f in zip(recs, good):
            if rec["kind"] == "feedback" and rec["latency_ms"] is not None:
                assert abs(float(f["zap.latency_ms"][0]) - rec["latency_ms"]) <= 0.002
                assert "zap.request_in" in f
                linked += 1
    assert total > 60 and linked >= 10


@needs_tshark
def test_one_corrupted_frame_is_one_bad_frame_even_when_its_bytes_look_like_a_head(cli, tmp_path):
    # a corrupted status frame whose second byte is also a status head, at the end of a packet:
    # the bytes held back for the next packet must not be reported as a second bad frame
    good = [zk.encode_status(i, 6, rpm=12340) for i in range(1, 5)]
    corrupted = bytearray(zk.encode_status(1, 6, rpm=12340))
    corrupted[1] = 0xF2
    path = tmp_path / "bad.pcapng"
    w = Writer(str(path))
    i = w.interface("zk", "synthetic")
    w.packet(i, 1767225600.0, good[0] + bytes(corrupted), INBOUND)
    w.packet(i, 1767225600.01, b"".join(good[1:]), INBOUND)
    w.close()
    frames = tshark(path)
    assert len([f for p, f in frames if "zk.bad" in f]) == 1
    assert len([f for p, f in frames if p == "zk" and "zk.bad" not in f]) == 4
    r = cli("zk", "decode", str(path), "-f", "jsonl")
    assert r.exit_code == 0 and len(r.stdout.splitlines()) == 4 and "1 bad (CRC)" in r.stderr, r


@pytest.fixture(scope="module")
def modbus_captures(tmp_path_factory):
    """Captures of Modbus RTU buses (link type 149): the commands' own, and a synthetic one with
    frames split across chunks, an adapter's echo, an exception reply, a mixture of unknown
    direction and a bad CRC."""
    from click.testing import CliRunner

    from zkzap.codec import modbus
    from zkzap.commands import root, run

    d = tmp_path_factory.mktemp("modbus")
    out = []
    for n, args in enumerate([
        ["load", "present-position", "--id", "1", "--sim"],
        ["store", "goal-speed", "500", "--id", "1", "--sim", "--verify"],
        ["sync-move", "1:1000", "2:3000", "--sim", "--verify"],
        ["dump", "--id", "1", "--sim"],
        ["scan", "--sim", "--sim-ids", "1,3", "--ids", "1-6"],
        ["raw", "read", "00 D4 00 01", "--id", "1", "--sim"],              # 212: exception 2
        ["load", "present-position", "--id", "9", "--sim", "--sim-ids", "1", "--retries", "0"],   # unanswered
    ]):
        path = d / f"m{n}.pcapng"
        with CliRunner().isolation():
            code = run(root, "zkzap", ["zap", args[0], "--protocol", "modbus", *args[1:], "--capture", str(path)])
        assert code in (0, 3, 5) and path.exists(), args
        out.append(path)
    req = modbus.read_registers(1, 205, 6)
    reply = modbus.read_reply(1, [1, 2, 3, 4, 5, 6])
    w = Writer(str(d / "synthetic.pcapng"))
    i = w.interface("modbus", "synthetic")
    ts = 1767225600.0
    for chunk, direction in [(req[:3], OUTBOUND), (req[3:], OUTBOUND), (req, INBOUND),      # the echo
                             (reply[:4], INBOUND), (reply[4:], INBOUND),
                             (modbus.write_register(2, 205, 77), OUTBOUND), (modbus.write_register(2, 205, 77), INBOUND),
                             (modbus.read_registers(3, 212, 1), OUTBOUND), (modbus.exception_reply(3, 3, 2), INBOUND),
                             (modbus.read_registers(4, 0, 2) + modbus.read_reply(4, [17, 0x0102]), UNKNOWN),
                             (b"\x01\x03\x00\xd2\x00\x01\x24\x34", OUTBOUND)]:
        w.packet(i, ts, chunk, direction)
        ts += 0.002
    w.close()
    out.append(d / "synthetic.pcapng")
    return out


@needs_tshark
def test_tshark_decodes_modbus_captures_as_zkzap_does_and_links_replies(cli, modbus_captures):
    total = linked = exceptions = 0
    for path in modbus_captures:
        recs = decoded(cli, "zap", path)                # the capture says Modbus RTU: no --protocol
        frames = tshark(path)
        total += compare(recs, frames, "zapmodbus")
        good = [f for p, f in frames if p == "zapmodbus" and "zapmodbus.bad" not in f]
        for rec, f in zip(recs, good):
            exceptions += rec["kind"] == "exception"
            if rec["kind"] != "request" and rec.get("latency_ms") is not None:
                assert abs(float(f["zapmodbus.latency_ms"][0]) - rec["latency_ms"]) <= 0.002
                assert "zapmodbus.request_in" in f
                linked += 1
    assert total > 60 and linked >= 20 and exceptions >= 2
    bad = [f for p, f in tshark(modbus_captures[-1]) if "zapmodbus.bad" in f]
    assert len(bad) == 1 and bad[0]["zapmodbus.crc_ok"][0] in ("False", "0")
