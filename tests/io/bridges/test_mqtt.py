"""The MQTT bridge against a real Mosquitto: every record arrives in order on PREFIX/<kind>/<id>,
the retained state and last will, a broker restart loses only what the counters say while the
serial side keeps its rate, an unreachable broker (exit 4, or --mqtt-optional), and URLs."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
import time

import pytest

mqtt = pytest.importorskip("paho.mqtt.client")

from zkzap.errors import UsageError  # noqa: E402
from zkzap.io.bridges.mqtt import MqttUrl  # noqa: E402


class Subscriber:
    """A persistent-session QoS 1 subscriber collecting (topic, payload, retain)."""

    def __init__(self, broker, topic, client_id="zkzap-test-sub", clean=False):
        self.messages = []
        self.lock = threading.Lock()
        self.subscribed = threading.Event()
        c = self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id, clean_session=clean)
        c.on_connect = lambda cl, u, f, rc, p=None: cl.subscribe(topic, qos=1)
        c.on_subscribe = lambda *a: self.subscribed.set()
        c.on_message = self._on_message
        c.reconnect_delay_set(0.1, 0.5)
        c.connect("127.0.0.1", broker.port, keepalive=5)
        c.loop_start()
        assert self.subscribed.wait(10)

    def _on_message(self, client, userdata, msg):
        with self.lock:
            self.messages.append((msg.topic, msg.payload.decode(), msg.retain))

    def records(self):
        with self.lock:
            return [(t, json.loads(p)) for t, p, _ in self.messages if not t.endswith("/state")]

    def states(self):
        with self.lock:
            return [(p, r) for t, p, r in self.messages if t.endswith("/state")]

    def wait_for(self, n, timeout=20):
        deadline = time.monotonic() + timeout
        while len(self.records()) < n and time.monotonic() < deadline:
            time.sleep(0.02)
        return self.records()

    def close(self):
        self.client.disconnect()
        self.client.loop_stop()


@pytest.fixture
def subscriber(broker):
    made = []

    def make(topic, **kw):
        s = Subscriber(broker, topic, **kw)
        made.append(s)
        return s

    yield make
    for s in made:
        s.close()


def key(rec):
    return rec["t"], rec["id"], rec["frame"]


def stats_from(stderr):
    m = re.search(r"mqtt: (\d+) records, (\d+) published, (\d+) confirmed(?: by the broker)?, (\d+) dropped, "
                  r"(\d+) unconfirmed, (\d+) reconnects", stderr)
    assert m, stderr
    return dict(zip(("submitted", "published", "confirmed", "dropped", "unconfirmed", "reconnects"),
                    map(int, m.groups())))


def test_every_record_arrives_in_order_on_its_topic(cli, broker, subscriber):
    sub = subscriber("stand1/#", clean=True)
    r = cli("zk", "monitor", "-p", "sim://zk?speed=10", "--duration", "15", "--mqtt", f"{broker.url}/stand1",
            "-f", "jsonl")
    assert r.exit_code == 0, r
    want = [json.loads(x) for x in r.stdout.splitlines()]
    got = sub.wait_for(len(want))
    assert [rec for _, rec in got] == want
    assert [t for t, _ in got] == [f"stand1/status/{w['id']}" for w in want]
    s = stats_from(r.stderr)
    assert s["submitted"] == s["published"] == s["confirmed"] == len(want) and s["dropped"] == 0
    deadline = time.monotonic() + 10
    while ("offline", False) not in sub.states() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert sub.states()[0] == ("online", False) and sub.states()[-1] == ("offline", False)
    # the state is retained: a newcomer learns it at once
    late = subscriber("stand1/state", client_id="zkzap-test-late", clean=True)
    deadline = time.monotonic() + 10
    while not late.states() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert late.states() == [("offline", True)]


def test_control_frames_a_session_sends_are_published_too(cli, broker, subscriber):
    sub = subscriber("st/control/#", clean=True)
    r = cli("zk", "send", "control", "--state", "stop", "--for", "10", "--rate", "10", "-p", "sim://zk?speed=10",
            "--end", "hold", "--mqtt", f"{broker.url}/st", "-f", "jsonl")       # only the commanded frames
    assert r.exit_code == 0, r
    got = sub.wait_for(5)
    assert got and all(t == "st/control/1" and rec["state"] == "stop" and rec["command"] == "control"
                       for t, rec in got)


def test_the_last_will_says_offline_when_the_session_dies(broker, subscriber, tmp_path):
    sub = subscriber("will/#", clean=True)
    exe = os.path.join(os.path.dirname(sys.executable), "zk")
    p = subprocess.Popen([exe, "monitor", "-p", "sim://zk", "--mqtt", f"{broker.url}/will", "-f", "jsonl"],
                         stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    try:
        sub.wait_for(1)
        assert ("online", False) in sub.states()
    finally:
        p.kill()
        p.wait(10)
    deadline = time.monotonic() + 30            # the broker notices within 1.5 keep-alive periods
    while ("offline", False) not in sub.states() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert sub.states()[-1] == ("offline", False)


def test_a_broker_restart_loses_only_what_the_counters_say(broker, subscriber):
    sub = subscriber("lab/#")                      # persistent session: survives the restart
    exe = os.path.join(os.path.dirname(sys.executable), "zk")
    p = subprocess.Popen([exe, "monitor", "-p", "sim://zk?rate=100", "--duration", "4", "--mqtt",
                          f"{broker.url}/lab", "--mqtt-qos", "1", "-f", "jsonl"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        sub.wait_for(50)
        broker.stop()
        time.sleep(1.0)                            # the broker is away for a second
        broker.start()
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    want = [json.loads(x) for x in out.splitlines()]
    s = stats_from(err)
    assert s["reconnects"] >= 1
    assert s["submitted"] == len(want) and s["published"] + s["dropped"] == s["submitted"]
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        arrived = {}
        for _, rec in sub.records():
            arrived.setdefault(key(rec), rec)      # QoS 1 may deliver twice
        if len(arrived) >= s["confirmed"]:
            break
        time.sleep(0.05)
    order = [key(w) for w in want]
    first = list(arrived)
    assert set(first) <= set(order)
    assert first == [k for k in order if k in arrived], "in order"
    lost = len(want) - len(arrived)
    assert len(arrived) >= s["confirmed"]
    assert lost <= s["dropped"] + s["unconfirmed"]
    # the serial side kept its rate throughout: 100 frames a second, no gap
    ts = [w["t"] for w in want]
    assert len(want) >= 4 * 100 * 0.8
    assert max(b - a for a, b in zip(ts, ts[1:])) < 0.5


def test_an_unreachable_broker_is_exit_4_before_the_port_opens(cli, broker):
    broker.stop()
    r = cli("zk", "monitor", "-p", "/dev/nonexistent-zkzap", "--mqtt", f"{broker.url}/x", "-o", "out.jsonl")
    assert r.exit_code == 4 and r.stdout == "", r
    assert "mqtt: cannot connect to the broker at 127.0.0.1" in r.stderr and "nonexistent" not in r.stderr
    assert not os.path.exists("out.jsonl")


def test_mqtt_optional_runs_without_the_broker_and_counts_the_drops(cli, broker):
    broker.stop()
    r = cli("zk", "monitor", "-p", "sim://zk?speed=10", "--count", "30", "--mqtt", f"{broker.url}/x",
            "--mqtt-optional", "-f", "jsonl")
    assert r.exit_code == 0, r
    assert len(r.stdout.splitlines()) == 30
    s = stats_from(r.stderr)
    assert s["submitted"] == 30 and s["published"] == 0 and s["dropped"] == 30
    assert "unreachable" in r.stderr


@pytest.mark.parametrize("url,message", [
    ("ftp://host/p", "expected mqtt://"),
    ("mqtt://host", "give a topic prefix"),
    ("mqtt:///prefix", "no broker host"),
    ("mqtt://host/a/+/b", "no wildcards"),
    ("mqtt://host:99999/p", "mqtt:"),
    ("mqtt://host/p?x=1", "no query"),
])
def test_malformed_urls_are_exit_2(cli, url, message):
    r = cli("zk", "monitor", "-p", "/dev/nonexistent-zkzap", "--mqtt", url)
    assert r.exit_code == 2 and r.stdout == "" and message in r.stderr, r


def test_url_parts_and_the_password_from_the_environment():
    u = MqttUrl("mqtts://pilot:s%40cret@broker.lab:9999/site/stand%201", env={})
    assert (u.tls, u.host, u.port, u.username, u.password, u.prefix) == \
        (True, "broker.lab", 9999, "pilot", "s@cret", "site/stand 1")
    assert MqttUrl("mqtt://pilot@h/p", env={"ZKZAP_MQTT_PASSWORD": "pw"}).password == "pw"
    assert MqttUrl("mqtt://h/p/", env={}).port == 1883 and MqttUrl("mqtts://h/p", env={}).port == 8883
    assert "s3cret" not in str(MqttUrl("mqtt://u:s3cret@h/p", env={}))
    with pytest.raises(UsageError) as e:
        MqttUrl("ftp://u:s3cret@h/p", env={})
    assert "s3cret" not in str(e.value)


def test_a_password_in_the_url_is_warned_about_and_never_printed(cli):
    r = cli("zk", "monitor", "-p", "/dev/nonexistent-zkzap", "--mqtt", "mqtt://pilot:s3cret@127.0.0.1:1/a")
    assert r.exit_code == 4 and "s3cret" not in r.stderr, r
    assert "warning: mqtt: the password in the URL can be read by every user of this computer in the process " \
           "list (ps); give it in ZKZAP_MQTT_PASSWORD instead" in r.stderr
    r = cli("zk", "monitor", "-p", "/dev/nonexistent-zkzap", "--mqtt", "mqtt://pilot@127.0.0.1:1/a")
    assert r.exit_code == 4 and "warning" not in r.stderr, r


def test_a_password_from_the_environment_logs_in(cli, broker, subscriber, monkeypatch, tmp_path):
    passwd = tmp_path / "passwd"
    subprocess.run(["mosquitto_passwd", "-b", "-c", str(passwd), "pilot", "s3cret"], check=True,
                   capture_output=True)
    broker.stop()
    broker.conf.write_text(broker.conf.read_text().replace("allow_anonymous true", "allow_anonymous false")
                           + f"password_file {passwd}\n")
    broker.start()
    url = f"mqtt://pilot@127.0.0.1:{broker.port}/a"
    r = cli("zk", "monitor", "-p", "sim://zk?speed=10", "--count", "3", "--mqtt", url)
    assert r.exit_code == 4 and "refused" in r.stderr, r
    monkeypatch.setenv("ZKZAP_MQTT_PASSWORD", "s3cret")
    r = cli("zk", "monitor", "-p", "sim://zk?speed=10", "--count", "3", "--mqtt", url, "-f", "jsonl")
    assert r.exit_code == 0, r
    assert stats_from(r.stderr)["confirmed"] == 3


def test_an_optional_broker_that_comes_later_gets_the_queued_records(broker, subscriber):
    sub = subscriber("late/#")                 # a persistent session: the broker keeps its messages
    broker.stop()
    exe = os.path.join(os.path.dirname(sys.executable), "zk")
    p = subprocess.Popen([exe, "monitor", "-p", "sim://zk", "--duration", "2.5", "--mqtt", f"{broker.url}/late",
                          "--mqtt-optional", "--mqtt-qos", "1", "-f", "jsonl"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert "unreachable" in p.stderr.readline()      # the session runs without its broker
        broker.start()
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    want = [json.loads(x) for x in out.splitlines()]
    s = stats_from(err)
    assert s["dropped"] == 0 and s["published"] == s["confirmed"] == len(want)
    got = sub.wait_for(len(want))
    assert [rec for _, rec in got] == want


def test_mqtts_with_the_systems_certificate_store(cli, broker, subscriber, monkeypatch, tmp_path):
    """TLS: the broker's certificate is checked against the default store, which
    SSL_CERT_FILE points at a private CA here (as a lab with its own CA would)."""
    import shutil as _shutil

    if _shutil.which("openssl") is None:
        pytest.skip("openssl is not installed")
    d = tmp_path / "tls"
    d.mkdir()

    def ssl(*args):
        subprocess.run(["openssl", *args], cwd=d, check=True, capture_output=True)

    ssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem", "-days", "2",
        "-subj", "/CN=zkzap test CA")
    ssl("req", "-newkey", "rsa:2048", "-nodes", "-keyout", "server.key", "-out", "server.csr", "-subj", "/CN=localhost")
    (d / "ext").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    ssl("x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
        "-out", "server.pem", "-days", "2", "-extfile", "ext")
    from .conftest import free_port

    tls_port = free_port()
    broker.stop()
    broker.conf.write_text(broker.conf.read_text() + f"listener {tls_port} 127.0.0.1\ncafile {d}/ca.pem\n"
                           f"certfile {d}/server.pem\nkeyfile {d}/server.key\n")
    broker.start()
    sub = subscriber("tls/#", clean=True)
    url = f"mqtts://localhost:{tls_port}/tls"
    r = cli("zk", "monitor", "-p", "sim://zk?speed=10", "--count", "5", "--mqtt", url, "-f", "jsonl")
    assert r.exit_code == 4 and "certificate" in r.stderr.lower(), r      # an unknown CA is refused
    monkeypatch.setenv("SSL_CERT_FILE", str(d / "ca.pem"))
    r = cli("zk", "monitor", "-p", "sim://zk?speed=10", "--count", "5", "--mqtt", url, "-f", "jsonl")
    assert r.exit_code == 0, r
    want = [json.loads(x) for x in r.stdout.splitlines()]
    assert [rec for _, rec in sub.wait_for(5)] == want
