"""ZK telemetry to an MQTT broker (the optional ``mqtt`` extra: paho-mqtt), for labs with many
stands.

``mqtt[s]://[user[:password]@]host[:port]/topic/prefix`` (the password may come from
``ZKZAP_MQTT_PASSWORD`` instead; ``mqtts`` is TLS with the system's CA certificates, port 8883
by default, 1883 without TLS). Every record is published as JSON to ``PREFIX/<kind>/<id>``
(``stand1/status/1``, ``stand1/control/1``) with the chosen QoS; ``PREFIX/state`` holds
``online`` while the session runs and ``offline`` after it (retained; the broker's last will
says ``offline`` when the session dies without a word).

The serial loop never waits for the broker: records go through a bounded queue
(:data:`~zkzap.io.bridges.QUEUE_SIZE`) to the bridge's thread, which publishes only while
connected and holds at most :data:`MAX_OUTSTANDING` unconfirmed messages; what does not fit is
dropped and counted. The bridge reconnects (after 0.2 s, doubling up to 5 s); QoS 1 and 2
messages in flight when the connection fails are sent again after the reconnect. Counters:
``submitted`` (records handed over), ``published`` (given to the broker connection),
``confirmed`` (QoS 1/2: acknowledged by the broker; QoS 0: written to the socket), ``dropped``
(queue full while the broker was slow or away), ``unconfirmed`` (published but never
confirmed when the session ended), ``reconnects``.
"""

from __future__ import annotations

import os
import queue
import threading
import time
from urllib.parse import unquote, urlsplit

from ...errors import PortError, UsageError
from ..writers import dumps as _dumps
from . import DRAIN_S, Bridge

EXTRA = "mqtt"
PASSWORD_ENV = "ZKZAP_MQTT_PASSWORD"
#: Messages published but not yet confirmed, at most (paho's own queue stays this small).
MAX_OUTSTANDING = 500
#: Records published together (seconds gathered): fewer thread wake-ups at 100 Hz.
BATCH_S = 0.05
RECONNECT_MIN_S = 0.2
RECONNECT_MAX_S = 5.0
CONNECT_TIMEOUT_S = 5.0
KEEPALIVE_S = 10



class MqttUrl:
    """A parsed ``mqtt[s]://`` URL (see the module's description)."""

    def __init__(self, text, env=None):
        env = os.environ if env is None else env
        try:
            u = urlsplit(text)
            port = u.port
        except ValueError as e:
            raise UsageError(f"mqtt: {text}: {e}") from None
        if u.scheme not in ("mqtt", "mqtts"):
            raise UsageError(f"mqtt: {self._redact(text)}: expected mqtt://[user[:password]@]host[:port]/prefix "
                             f"or mqtts://...")
        if not u.hostname:
            raise UsageError(f"mqtt: {self._redact(text)}: no broker host")
        if "#" in text or "+" in unquote(u.path):
            # urlsplit reads '#' as the start of a fragment: '/x/#' would publish under 'x/'
            raise UsageError(f"mqtt: {self._redact(text)}: a topic prefix has no wildcards (+ #): it names "
                             f"where records are published (mqtt://{u.hostname}/stand1)")
        if u.query or u.fragment:
            raise UsageError(f"mqtt: {self._redact(text)}: no query or fragment expected")
        self.tls = u.scheme == "mqtts"
        self.host = u.hostname
        self.port = port or (8883 if self.tls else 1883)
        self.username = unquote(u.username) if u.username else None
        password = unquote(u.password) if u.password is not None else None
        #: The password was given in the URL, where every local user can read it in the process
        #: list (``ps``); :data:`PASSWORD_ENV` keeps it out of sight.
        self.password_in_url = password is not None
        if password is None and env.get(PASSWORD_ENV):
            password = env[PASSWORD_ENV]
        self.password = password
        prefix = unquote(u.path).strip("/")
        if not prefix:
            raise UsageError(f"mqtt: {self._redact(text)}: give a topic prefix "
                             f"(mqtt://{u.hostname}/stand1)")
        if any(c in prefix for c in "+#\0") or "//" in prefix:
            raise UsageError(f"mqtt: topic prefix {prefix!r}: no wildcards (+ #), NUL or empty levels")
        self.prefix = prefix

    @staticmethod
    def _redact(text):
        try:
            u = urlsplit(text)
        except ValueError:
            return text
        if u.password is None:
            return text
        return text.replace(f":{u.password}@", ":***@", 1)

    def __str__(self):
        user = f"{self.username}@" if self.username else ""
        return f"{'mqtts' if self.tls else 'mqtt'}://{user}{self.host}:{self.port}/{self.prefix}"


class MqttBridge(Bridge):
    name = "mqtt"

    def __init__(self, url: MqttUrl, *, qos=0, optional=False, queue_size=None, notify=None):
        super().__init__() if queue_size is None else super().__init__(queue_size)
        self.url = url
        self.qos = qos
        self.optional = optional
        self.notify = notify or (lambda message: None)
        self.client = None
        self.published = 0
        self.confirmed = 0
        self.unconfirmed = 0
        self.reconnects = 0
        self.connects = 0
        self.refused = None
        self._connected = threading.Event()
        self._answered = threading.Event()
        self._lock = threading.RLock()
        self._state_mids = set()
        self._backoff = RECONNECT_MIN_S
        self._next_try = 0.0
        self._done = False
        self._state_topic = f"{url.prefix}/state"
        self._topics = {}

    # connection: paho's callbacks run inside client.loop(), in the thread that calls it
    def _on_connect(self, client, userdata, flags, reason_code, properties=None):
        if getattr(reason_code, "is_failure", False):
            self.refused = str(reason_code)
            self._answered.set()
            return
        self.refused = None
        if self.connects:
            self.reconnects += 1
        self.connects += 1
        self._backoff = RECONNECT_MIN_S
        self._publish_state(client, "online")
        self._connected.set()
        self._answered.set()

    def _publish_state(self, client, text):
        with self._lock:
            info = client.publish(self._state_topic, text, qos=1, retain=True)
            self._state_mids.add(info.mid)
        return info

    def _on_disconnect(self, client, userdata, flags, reason_code, properties=None):
        self._connected.clear()

    def _on_publish(self, client, userdata, mid, reason_code=None, properties=None):
        with self._lock:
            if mid in self._state_mids:
                self._state_mids.discard(mid)
            else:
                self.confirmed += 1

    def connect(self):
        """Connect and wait for the broker's answer (this thread drives paho until the bridge's
        own thread takes over: paho runs no network thread of its own, so a record costs no
        extra thread wake-up)."""
        import paho.mqtt.client as mqtt

        u = self.url
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"zkzap-{os.getpid()}-{int(time.time())}",
                        clean_session=True, protocol=mqtt.MQTTv311)
        if u.username is not None:
            c.username_pw_set(u.username, u.password)
        if u.tls:
            c.tls_set()
        c.will_set(self._state_topic, "offline", qos=1, retain=True)
        c.max_inflight_messages_set(100)
        c.connect_timeout = CONNECT_TIMEOUT_S
        c.on_connect = self._on_connect
        c.on_disconnect = self._on_disconnect
        c.on_publish = self._on_publish
        self.client = c
        self._mqtt = mqtt
        where = f"{u.host}:{u.port}"
        try:
            c.connect(u.host, u.port, keepalive=KEEPALIVE_S)
        except (OSError, ValueError) as e:
            reason = getattr(e, "strerror", None) or str(e) or type(e).__name__
            if not self.optional:
                raise PortError(f"mqtt: cannot connect to the broker at {where}: {reason}") from None
            self.notify(f"mqtt: broker at {where} unreachable ({reason}); records are queued until it answers "
                        f"(--mqtt-optional)")
            self._next_try = time.monotonic() + self._backoff
            return
        deadline = time.monotonic() + CONNECT_TIMEOUT_S
        while not self._answered.is_set() and time.monotonic() < deadline:
            if c.loop(timeout=0.05) != 0 and not self._answered.is_set():
                break
        if not self._answered.is_set() or self.refused:
            why = f"refused: {self.refused}" if self.refused else f"no answer within {CONNECT_TIMEOUT_S:g} s"
            if not self.optional:
                c.disconnect()
                raise PortError(f"mqtt: broker at {where} {why}")
            self.notify(f"mqtt: broker at {where} {why}; still trying (--mqtt-optional)")
            self._next_try = time.monotonic() + self._backoff

    def _topic(self, rec):
        key = (rec.get("kind") or "status", rec.get("id"))
        t = self._topics.get(key)
        if t is None:
            t = self._topics[key] = f"{self.url.prefix}/{key[0]}/{key[1]}"
        return t

    def _outstanding(self):
        with self._lock:
            return self.published - self.confirmed

    def _service(self):
        """Let paho read acknowledgements and send keep-alives; reconnect when it is time."""
        c = self.client
        if c.socket() is not None:            # connected, or waiting for the broker's answer
            if c.loop(timeout=0) == 0:
                return
            self._connected.clear()
            self._next_try = time.monotonic() + self._backoff
            return
        now = time.monotonic()
        if now < self._next_try:
            return
        try:
            c.reconnect()
        except (OSError, ValueError):
            pass
        self._backoff = min(self._backoff * 2, RECONNECT_MAX_S)
        self._next_try = now + self._backoff

    def run(self, q, stop):
        client = self.client
        connected = self._connected
        closing = self._closing
        deadline = None
        while True:
            # wake every BATCH_S (at once when closing): several records per wake-up
            if not closing.is_set():
                closing.wait(BATCH_S)
            else:
                time.sleep(0.005)
            self._service()
            stopped = False
            while connected.is_set() and self._outstanding() < MAX_OUTSTANDING:
                try:
                    rec = q.get_nowait()
                except queue.Empty:
                    break
                if rec is stop:
                    stopped = True
                    break
                # a QoS 0 message published as the connection fails is lost (paho keeps QoS 1/2
                # ones and sends them again after a reconnect): it stays unconfirmed
                client.publish(self._topic(rec), _dumps({k: v for k, v in rec.items() if k[:1] != "_"}),
                               qos=self.qos)
                with self._lock:
                    self.published += 1
            if stopped:
                break
            if closing.is_set():
                # at the end: a broker that is away gets a second, a slow one DRAIN_S
                deadline = deadline or time.monotonic() + (DRAIN_S if connected.is_set() else 1.0)
                if time.monotonic() > deadline:
                    rest, _ = self.drain(q, stop)
                    self.dropped += len(rest)
                    break
        self._finish()

    def _finish(self):
        """Wait (at most DRAIN_S) for the broker to confirm what was published, say offline, and
        disconnect."""
        c = self.client
        deadline = time.monotonic() + DRAIN_S
        while self._connected.is_set() and self._outstanding() > 0 and time.monotonic() < deadline:
            if c.loop(timeout=0.02) != 0:
                break
        if self._connected.is_set():
            info = self._publish_state(c, "offline")
            end = time.monotonic() + 1.0
            while not info.is_published() and time.monotonic() < end:
                if c.loop(timeout=0.02) != 0:
                    break
        with self._lock:
            self.unconfirmed = max(0, self.published - self.confirmed)
        try:
            c.disconnect()
            c.loop(timeout=0)
        except (OSError, ValueError):
            pass
        self._connected.clear()
        self._done = True

    def disconnect(self):
        c = self.client
        if c is not None and not self._done:
            # the thread never ran or did not finish in time: just close the connection
            with self._lock:
                self.unconfirmed = max(0, self.published - self.confirmed)
            try:
                c.disconnect()
            except (OSError, ValueError):
                pass
        self.client = None

    def stats(self) -> dict:
        s = super().stats()
        with self._lock:
            s.update({"published": self.published, "confirmed": self.confirmed,
                      "unconfirmed": self.unconfirmed if self._done else max(0, self.published - self.confirmed),
                      "reconnects": self.reconnects, "connected": self._connected.is_set(), "qos": self.qos})
        return s

    def describe(self) -> str:
        s = self.stats()
        return (f"{s['submitted']} records, {s['published']} published, {s['confirmed']} confirmed"
                f"{' by the broker' if self.qos else ''}, {s['dropped']} dropped, {s['unconfirmed']} unconfirmed, "
                f"{s['reconnects']} reconnects (QoS {self.qos}) to {self.url}")
