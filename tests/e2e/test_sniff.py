"""The sniffer on a tapped pty link: a relay copies bytes between the host and a simulator and
feeds the sniffer's ptys. The sniffer must recover every frame, pair every reply, and write
nothing."""

from __future__ import annotations

import json
import os
import selectors
import signal
import subprocess
import time

import pytest

from zkzap.codec import zap
from zkzap.link.pcapng import INBOUND, OUTBOUND, Reader

from .conftest import clean_env, executable
from .relay import Relay


def start_sniffer(*args):
    p = subprocess.Popen([executable("zkzap"), "sniff", *args], stdin=subprocess.DEVNULL,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=clean_env())
    line = _readline(p.stderr, 15)
    assert line.startswith(b"note: sniffing "), line
    return p


def _readline(stream, timeout):
    sel = selectors.DefaultSelector()
    sel.register(stream, selectors.EVENT_READ)
    out = b""
    end = time.monotonic() + timeout
    while not out.endswith(b"\n") and time.monotonic() < end:
        if sel.select(end - time.monotonic()):
            ch = os.read(stream.fileno(), 1)
            if not ch:
                break
            out += ch
    sel.close()
    return out


def read_records(p, n, timeout=20):
    """``n`` JSON records from the sniffer's stdout (fewer if it ends or the time runs out)."""
    recs = []
    end = time.monotonic() + timeout
    while len(recs) < n and time.monotonic() < end:
        line = _readline(p.stdout, end - time.monotonic())
        if not line:
            break
        recs.append(json.loads(line))
    return recs


def stop(p, sig=signal.SIGTERM):
    p.send_signal(sig)
    out, err = p.communicate(timeout=15)
    return p.returncode, out.decode(), err.decode()


@pytest.fixture
def zap_link(start_sim):
    url, _ = start_sim(["zap", "--ids", "1,2", "--pty"])
    relay = Relay(url, 57600, taps=1)
    relay.start()
    yield relay
    relay.stop()


def test_sniff_zap_pairs_every_reply_and_writes_nothing(zap_link, tmp_path):
    from zkzap.link.zap_bus import open_bus

    cap = tmp_path / "bus.pcapng"
    p = start_sniffer("zap", "-p", zap_link.tap_paths[0], "-f", "jsonl", "--capture", str(cap),
                      "--reply-timeout", "0.05", "--stats")
    with open_bus(zap_link.host_path, 57600, retries=0, timeout=0.05) as bus:
        assert bus.echo(1).ident == 1
        value = bus.read(2, "present-position")
        assert bus.ping(3) is None                   # absent: a missing reply
        bus.echo(2)
    # echo 1 + reply, load 2 + reply, echo 3 (missing), echo 2 + reply
    recs = read_records(p, 8)
    code, out, err = stop(p)
    assert code == 143, err
    kinds = [(r["kind"], r["id"]) for r in recs]
    assert kinds == [("command", 1), ("feedback", 1), ("command", 2), ("feedback", 2), ("command", 3),
                     ("missing", 3), ("command", 2), ("feedback", 2)], recs
    fb = [r for r in recs if r["kind"] == "feedback"]
    # a latency is measured, or (request and reply in one read of a held-up reader) not known
    assert all(r["pairing"] == "ok" and (0 < r["latency_ms"] < 1000 if r["latency_ms"] is not None
                                         else r["latency_unknown"]) for r in fb), fb
    assert fb[1]["request"] == "load" and fb[1]["register"] == "present-position" and fb[1]["value"] == value
    assert [r["dir"] for r in recs if r["kind"] == "command"] == ["h2d"] * 4
    assert recs[5]["request"] == "echo" and recs[5]["waited_ms"] > 30   # until the next request or the timeout
    assert "replies: 3" in err and "missing 1" in err
    assert zap_link.sniffer_wrote == b""                # not one byte written to its port
    # the capture holds exactly the bytes on the wire, both directions in one stream
    wire = b"".join(k.data for k in Reader(str(cap), "zap"))
    assert wire == _interleaved(zap_link)


def _interleaved(relay):
    """Host and device bytes in wire order (the relay saw them one after the other)."""
    from zkzap.codec.framing import ZapFramer

    host = ZapFramer().feed(bytes(relay.host_bytes))
    dev = ZapFramer().feed(bytes(relay.device_bytes))
    out, di = b"", 0
    for pkt in host:
        out += pkt
        if di < len(dev) and dev[di][3] == pkt[3]:
            out += dev[di]
            di += 1
    return out


def test_sniff_zap_marks_replies_from_an_unexpected_id(start_sim, tmp_path):
    url, _ = start_sim(["zap", "--ids", "1", "--fault", "1:wrong-id=7", "--pty"])
    relay = Relay(url, 57600, taps=1)
    relay.start()
    try:
        p = start_sniffer("zap", "-p", relay.tap_paths[0], "-f", "jsonl")
        from zkzap.link.zap_bus import open_bus

        with open_bus(relay.host_path, 57600, retries=0, timeout=0.05) as bus:
            try:
                bus.echo(1)
            except Exception:  # noqa: BLE001 - the host sees a wrong-ID reply; the sniffer marks it
                pass
        recs = read_records(p, 2)
        stop(p)
    finally:
        relay.stop()
    assert recs[1]["pairing"] == "unexpected-id" and recs[1]["id"] == 7 and recs[1]["expected_id"] == 1


def test_sniff_zk_merges_two_taps_by_time(start_sim, tmp_path):
    url, _ = start_sim(["zk", "--speed", "10", "--pty"])
    relay = Relay(url, 115200, taps=2)
    relay.start()
    try:
        out = tmp_path / "link.jsonl"
        p = start_sniffer("zk", "-p", relay.tap_paths[0], "-p", relay.tap_paths[1], "-o", str(out),
                          "--capture", str(tmp_path / "link.pcapng"), "--stats")
        host_cap = tmp_path / "host.pcapng"
        h = subprocess.run([executable("zk"), "send", "control", "--state", "stop", "--for", "1", "-p",
                            relay.host_path, "-f", "jsonl", "--capture", str(host_cap)],
                           capture_output=True, text=True, env=clean_env(), timeout=30)
        assert h.returncode == 0, h.stderr
        host_pkts = list(Reader(str(host_cap), "zk"))
        sent = b"".join(k.data for k in host_pkts if k.direction == OUTBOUND)
        received = b"".join(k.data for k in host_pkts if k.direction == INBOUND)
        # wait until the sniffer has seen everything the host wrote and read
        n_expected = len(sent) // 4 + len(received) // 7
        end = time.monotonic() + 20
        while time.monotonic() < end and _lines(out) < n_expected:
            time.sleep(0.05)
        code, _, err = stop(p, signal.SIGINT)
    finally:
        relay.stop()
    assert code == 130, err
    assert relay.sniffer_wrote == b""
    recs = [json.loads(x) for x in out.read_text().splitlines()]
    control = [r for r in recs if r["kind"] == "control"]
    status = [r for r in recs if r["kind"] == "status"]
    assert all(r["dir"] == "h2d" for r in control) and all(r["dir"] == "d2h" for r in status)
    assert "".join(r["frame"].replace(" ", "") for r in control) == sent.hex().upper()
    got = bytes.fromhex("".join(r["frame"] for r in status))
    assert received in got                                # every status frame the host read, in order
    assert all(a["t"] <= b["t"] for a, b in zip(recs, recs[1:]))       # one stream, in time order
    assert any(r["id"] == 6 and r["protocol_version"] == 6 for r in status)
    assert "h2d" in err and "d2h" in err
    pk = list(Reader(str(tmp_path / "link.pcapng"), "zk"))
    assert {k.direction for k in pk} == {INBOUND, OUTBOUND}


def _lines(path):
    try:
        return path.read_text().count("\n")
    except FileNotFoundError:
        return 0


def test_sniff_port_counts_are_usage_errors(sh):
    r = sh("zkzap", "sniff", "zap", "-p", "/dev/null", "-p", "/dev/zero")
    assert r.exit_code == 2 and "a mightyZAP bus is half-duplex" in r.stderr and r.stdout == ""
    r = sh("zkzap", "sniff", "zk", "-p", "a", "-p", "b", "-p", "c")
    assert r.exit_code == 2 and "3 ports given" in r.stderr


def test_live_summary_on_a_terminal_and_records_in_the_pipe(tmp_path):
    """stderr a terminal, stdout a pipe: the summary is drawn on the terminal, JSON Lines go to
    the pipe, --stats is printed at the end."""
    import pty

    master, slave = pty.openpty()
    p = subprocess.Popen([executable("zkzap"), "sniff", "zk", "-p", "sim://zk?speed=10", "--duration", "1.5",
                          "--stats"], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave,
                         env=clean_env(TERM="xterm", COLUMNS="100"))
    os.close(slave)
    # stdout is read while the terminal is: a pipe that nobody reads fills up and holds the sniffer
    import threading

    got = []
    reader = threading.Thread(target=lambda: got.append(p.stdout.read()), daemon=True)
    reader.start()
    shown = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:
            break
        if not chunk:
            break
        shown += chunk
    p.wait(timeout=15)
    reader.join(15)
    out = got[0] if got else b""
    os.close(master)
    assert p.returncode == 0
    recs = [json.loads(x) for x in out.decode().splitlines()]
    assert len(recs) > 10 and all(r["dir"] == "d2h" for r in recs)
    text = shown.decode(errors="replace")
    import re

    assert re.search(r"sniffing \d+ s  d2h: \d+/s", text), text        # the live summary
    assert "CRC errors: 0" in text and "by ID: d2h ID 1:" in text         # --stats at the end


def test_sniff_modbus_pairs_every_reply_and_captures_as_modbus(start_sim, tmp_path, cli):
    """The same on a 17Lf bus: --protocol modbus frames, names and pairs Modbus RTU, a read of an
    absent ID is missing, and the capture's link type says Modbus RTU, which zap decode follows."""
    from zkzap.link.pcapng import LINKTYPE_MODBUS, capture_protocol
    from zkzap.link.zap_bus import open_bus

    url, _ = start_sim(["zap", "--protocol", "modbus", "--ids", "1,2", "--pty"])
    relay = Relay(url, 57600, taps=1)
    relay.start()
    try:
        cap = tmp_path / "bus.pcapng"
        p = start_sniffer("zap", "--protocol", "modbus", "-p", relay.tap_paths[0], "-f", "jsonl",
                          "--capture", str(cap), "--reply-timeout", "0.05")
        with open_bus(relay.host_path, 57600, retries=0, timeout=0.05, protocol="modbus") as bus:
            value = bus.read(2, "present-position")
            bus.write(1, {"goal-speed": 500})
            assert bus.ping(3) is None
        recs = read_records(p, 5)
        code, out, err = stop(p)
    finally:
        relay.stop()
    assert code == 143, err
    assert [(r["kind"], r["id"]) for r in recs] == [("request", 2), ("reply", 2), ("request", 1), ("reply", 1),
                                                    ("request", 3)], recs
    assert recs[1]["pairing"] == "ok" and recs[1]["request"] == "read" and recs[1]["value"] == value
    assert recs[1]["register"] == "present-position" and 0 < recs[1]["latency_ms"] < 1000
    assert recs[3]["request"] == "write-multiple" and recs[2]["register"] == "goal-speed"
    assert relay.sniffer_wrote == b""
    assert capture_protocol(str(cap)) == "modbus" and LINKTYPE_MODBUS == 149
    r = cli("zap", "decode", str(cap), "-f", "jsonl")          # the capture says which protocol
    got = [json.loads(x) for x in r.stdout.splitlines()]
    assert r.exit_code == 0 and [g["kind"] for g in got][:4] == ["request", "reply", "request", "reply"], r
    assert got[1]["value"] == value
