"""The one timing policy of mightyZAP transactions (zkzap.link.zap_timing): late windows, learned
latency, attribution, and scans that find slow actuators, against the in-process simulator (its
replies are there whenever the host reads: a loaded machine cannot make them late). Where a
test needs a reply to come after a window, it comes hundreds of milliseconds after it: a host
held up that long would read it as if in time."""

import re
import time

import pytest

from zkzap.codec import zap
from zkzap.errors import BadReply, NoReply
from zkzap.link.port import open_port, sim_url
from zkzap.link.zap_bus import ZapBus, wire_time
from zkzap.link.zap_scan import scan
from zkzap.link.zap_timing import FLOOR, LATE_WINDOW, MARGIN, Estimator, Pairing, Policy, policy_for, window_for
from zkzap.sim.zap_actuators import MODEL_NUMBER


def make(ids="1,2", return_mode=1, **opts):
    return ZapBus(open_port(sim_url("zap", ids=ids, **opts), 57600, timeout=0.1), return_mode=return_mode)


def host_collisions(bus):
    return [c for c in bus.port.device.collisions if c["kind"] == "host"]


# -- the estimator and the policy ---------------------------------------------------------------

def test_estimator_smooths_like_tcps_retransmission_timer():
    e = Estimator()
    assert e.timeout(FLOOR, LATE_WINDOW) == LATE_WINDOW            # nothing known: the whole window
    e.sample(0.010)
    assert (e.srtt, e.rttvar) == (0.010, 0.005)                     # RFC 6298: R, R/2
    assert e.timeout(FLOOR, LATE_WINDOW) == pytest.approx(0.010 + 4 * 0.005)
    for _ in range(50):
        e.sample(0.010)
    assert e.srtt == pytest.approx(0.010) and e.timeout(FLOOR, LATE_WINDOW) == pytest.approx(0.010 + MARGIN, abs=1e-4)
    e.sample(0.5)
    assert e.timeout(FLOOR, LATE_WINDOW) == LATE_WINDOW             # bounded by the window
    tiny = Estimator()
    tiny.sample(0.0)
    assert tiny.timeout(FLOOR, LATE_WINDOW) >= FLOOR                # ... and by the floor


def test_policy_learns_per_actuator_and_knows_the_bus_typical_latency():
    p = Policy()
    assert p.quick() == pytest.approx(FLOOR * 1.25) and p.latency(1) is None
    for _ in range(5):
        p.learn(1, 0.002, LATE_WINDOW)
        p.learn(2, 0.002, LATE_WINDOW)
        p.learn(3, 0.040, LATE_WINDOW)
    assert p.latency(3) == pytest.approx(0.040) and p.latency(1) == pytest.approx(0.002)
    assert p.typical() == pytest.approx(0.002)                      # one slow actuator is not the bus
    assert p.learn(1, 0.030, LATE_WINDOW) is True                   # after ID 1's timeout: late
    assert p.summary()[1]["late"] == 1
    assert p.latency(9, hint=0.05) == p.typical()                   # an unknown ID: the bus-typical one
    assert Policy().latency(9, hint=0.05) == 0.05
    pair = Policy()
    pair.learn(1, 0.002, LATE_WINDOW)
    pair.learn(2, 0.042, LATE_WINDOW)
    assert pair.typical() == pytest.approx(0.002)                   # ... even among two
    assert pair.courtesy() == pytest.approx(0.002 * 1.25)
    slow = Policy()
    slow.learn(1, 0.040, LATE_WINDOW)
    assert slow.courtesy() == pytest.approx(0.040 * 1.25)           # a write's courtesy: the bus's latency
    assert slow.quick() == pytest.approx(FLOOR * 1.25)              # a free ID's probe: the floor
    assert slow.quick(hint=0.030) == pytest.approx(0.030 * 1.25)    # ... or what --latency says


def test_the_window_and_the_latency_hint():
    assert window_for() == LATE_WINDOW and window_for(0.02) == 0.02
    assert window_for(hint=0.040) == LATE_WINDOW                    # fits the default window
    assert window_for(hint=0.300) == pytest.approx(0.300 * 1.25 + MARGIN)   # widened for it
    assert window_for(0.02, hint=0.300) == 0.02                     # an explicit window is never widened


def test_policies_are_shared_per_port_in_one_process():
    assert policy_for("socket://127.0.0.1:9") is policy_for("socket://127.0.0.1:9")
    assert policy_for("sim://zap?instance=77") is policy_for("sim://zap?instance=77")
    assert policy_for("sim://zap?ids=1") is not policy_for("sim://zap?ids=1")     # a new simulator each time
    assert policy_for("socket://10.0.0.9:9").margin > policy_for("socket://127.0.0.1:9").margin


def test_adapter_effect_is_a_fact_only_when_the_latency_shows_the_timer():
    p = Policy(adapter=0.016, device="/dev/ttyUSB0")
    assert p.adapter_effect() is None
    p.learn(1, 0.004, LATE_WINDOW)
    assert p.adapter_effect() is None
    q = Policy(adapter=0.016, device="/dev/ttyUSB0")
    q.learn(1, 0.017, LATE_WINDOW)
    assert q.adapter_effect() == (pytest.approx(0.017), 0.016, "/dev/ttyUSB0")
    assert Policy(adapter=0.001).adapter_effect() is None


def test_passive_pairing_follows_the_same_window():
    pair = Pairing()
    pair.command(1, 0.0, "load")
    pair.command(2, 0.005, "echo")                                  # the host moved on: counted
    assert pair.overlaps == 1
    assert pair.feedback(2, 0.009)[1:] == ("echo", pytest.approx(0.004))
    assert pair.feedback(1, 0.042)[1:] == ("load", pytest.approx(0.042))   # late, to the request it answers
    pair.command(3, 1.0, "load")
    assert pair.expired(1.1) == [] and pair.expired(1.2, busy=True) == []     # a reply is arriving
    assert pair.feedback(3, 1.21)[2] == pytest.approx(0.21)                    # ... that began in time
    pair.command(4, 2.0, "load")
    assert pair.expired(2.2) == [(4, 2.0, "load")] and pair.feedback(4, 2.25) is None
    pair.command(5, 3.0, "echo")                  # request and reply in one read: one time stamp
    assert pair.feedback(5, 3.0) == (3.0, "echo", None)                        # not known, never 0


def test_a_reply_read_with_its_request_has_no_latency_in_records_and_stats():
    from zkzap.api.sniff import ZapSniffer
    from zkzap.codec import zap

    s = ZapSniffer([], 57600)
    s.wall0 = 10.0                                # (set when its ports open)
    s.frame(10.0, 0, zap.echo(1))
    rec = [r for r in s.frame(10.0, 0, zap.packet(1, 0, b"")) if r.get("kind") == "feedback"][0]
    assert rec["pairing"] == "ok" and rec["latency_ms"] is None and rec["latency_unknown"]
    s.frame(11.0, 0, zap.echo(1))
    rec = [r for r in s.frame(11.004, 0, zap.packet(1, 0, b"")) if r.get("kind") == "feedback"][0]
    assert rec["latency_ms"] == pytest.approx(4.0)
    summary = s.stats.summary(2.0)
    assert summary["replies"] == 2 and summary["mean_latency_ms"] == pytest.approx(4.0)


# -- transactions ---------------------------------------------------------------------------------

@pytest.mark.parametrize("delay", [20, 40, 100, 140])
def test_a_late_reply_is_the_answer_of_its_request_with_its_true_latency(delay):
    bus = make()
    bus.port.device.actuator(2).set("goal-speed", 700)
    bus.port.device.inject(2, "delay", delay, count=1)
    r = bus.load(2, 0x8C, 2)
    assert r.value == 0 and bus.sent == 1 and bus.retried == 0      # one request, answered
    assert r.rtt >= delay / 1000 + wire_time(18, 57600)             # measured from that request
    assert bus.read(2, "goal-speed") == 700                         # not the late present-position reply
    assert host_collisions(bus) == []


def test_a_missed_reply_keeps_the_line_until_its_window_closes():
    bus = make(ids="1")
    t = time.monotonic()
    with pytest.raises(NoReply, match="within 150.0 ms"):
        bus.echo(9)
    assert time.monotonic() - t >= 3 * LATE_WINDOW                  # three tries, each after the window
    assert bus.sent == 3
    device = bus.port.device
    assert [p[3] for p in device.received] == [9, 9, 9]


def test_a_reply_later_than_the_window_is_never_another_requests_answer():
    bus = make()
    bus.timeout = 0.02                                              # a window shorter than the actuator
    bus.port.device.actuator(2).set("goal-speed", 700)
    bus.port.device.inject(2, "delay", 300, count=1)
    with pytest.raises(NoReply):
        bus.read(2, "present-position")                             # three tries, 300 ms too early
    bus.linger(0.4)                                                 # the replies come: strays, skipped
    assert bus.late + bus.stale >= 3 and bus.retried == 2
    assert bus.read(2, "goal-speed") == 700                         # not a late present-position reply


def test_the_line_is_kept_for_an_acknowledgement_another_mode_gives():
    bus = make(ids="1")
    bus.port.device.actuator(1).set("feedback-return-mode", 2)      # the bus is told mode 1
    bus.echo(1)
    for _ in range(3):
        assert bus.store(1, "goal-position", 100) is None
        assert bus.read(1, "goal-position") == 100                  # the ack is skipped, not an answer
    assert host_collisions(bus) == [] and bus.stale >= 3


def test_round_trip_and_latency_are_measured_from_the_answered_request():
    bus = make(turnaround="5")
    r = bus.echo(1)
    assert r.rtt >= wire_time(14, 57600) + 0.005
    assert 0.005 <= r.latency < r.rtt
    assert bus.latencies()[1]["samples"] == 1


def test_latency_is_learned_per_actuator():
    bus = make(faults="2:delay=30")
    for _ in range(4):
        bus.echo(1)
        bus.echo(2)
    learned = bus.latencies()
    assert learned[2]["latency_ms"] >= 30 > learned[1]["latency_ms"]
    assert bus.policy.timeout(2, bus.window) > bus.policy.timeout(1, bus.window)


@pytest.mark.parametrize("opts", [{"turnaround": "20"}, {"turnaround": "20", "gap": "1"},
                                  {"turnaround": "40", "gap": "1", "echo": "1"}, {"turnaround": "140"}])
def test_slow_and_trickling_devices_with_default_timing(opts):
    bus = make(**opts)
    assert bus.echo(1).ident == 1
    reply, values = bus.read_registers(2, 0x00, 17)
    assert len(reply.data) == 17 and values[0][1] == MODEL_NUMBER
    assert bus.sent == 2 and host_collisions(bus) == []


def test_bytes_more_than_the_inter_byte_allowance_apart_are_a_truncated_reply():
    bus = make(gap="100")
    with pytest.raises(BadReply, match="truncated reply"):
        bus.read(1, "present-position", retries=0)


def test_quick_probes_wait_a_measured_actuator_out_and_an_unknown_id_only_the_floor():
    bus = make()
    before = bus.quick_timeout(7)
    assert before == pytest.approx(wire_time(8, 57600) + FLOOR * 1.25 + 0.0005)
    for _ in range(3):
        bus.echo(1)
    assert bus.quick_timeout(7, 1) < bus.reply_timeout(7, 7)
    slow = make(turnaround="15")
    for _ in range(3):
        slow.echo(1)
    assert slow.quick_timeout(7, 1) > 0.015                         # a measured actuator: its own timeout
    assert slow.quick_timeout(7, 2) == pytest.approx(before)        # an unknown ID: the floor, not the bus's
    hinted = make()
    hinted.latency = 0.030
    assert hinted.quick_timeout(7) > 0.030                          # --latency before any sample


# -- scans ----------------------------------------------------------------------------------------

def records(bus, ids, bauds=(57600,), retries=2, notes=None):
    out, warnings = [], []
    for event in scan(bus, ids, list(bauds), retries=retries):
        if event[0] == "record":
            out.append(event[1])
        elif event[0] == "warning":
            warnings.append(event[1])
        elif event[0] == "note" and notes is not None:
            notes.append(event[1])
    return out, warnings


@pytest.mark.parametrize("opts", [
    {"faults": "2:delay=18,9:delay=20"}, {"turnaround": "20", "gap": "1"}, {"turnaround": "20", "echo": "1"},
    {"faults": "all:delay=12"}, {"faults": "5:delay=60"}, {"faults": "9:delay=140"},
    {"turnaround": "30"}, {"turnaround": "60", "gap": "1", "echo": "1"},
], ids=["some-late", "slow-trickling", "slow-echo", "all-12", "one-60", "one-140", "all-30", "all-60-echo"])
def test_scan_finds_and_identifies_every_slow_actuator(opts):
    bus = make(ids="1,2,5,9,20", **opts)
    notes = []
    found, warnings = records(bus, list(range(0, 24)), notes=notes)
    assert [(r["id"], r["status"], r["model"], r["firmware"], r["return_mode"]) for r in found] == \
        [(i, "ok", MODEL_NUMBER, 21, 1) for i in (1, 2, 5, 9, 20)]
    only_late(warnings, notes, {1, 2, 5, 9, 20})


def only_late(warnings, notes, ids):
    """What a scan of slow actuators says when it found and identified every one: no warning
    (never a duplicate, a garbled ID or a burst), at most a note that some of ``ids`` answered
    after its quick wait, with the latency learned of them."""
    assert warnings == []
    assert len(notes) <= 1, notes
    for n in notes:
        m = re.fullmatch(r"IDs? ([\d, ]+) at 57600 baud answered after the scan's quick wait \(latency "
                         r"[\d.]+(-[\d.]+)? ms\): found and identified; .*", n)
        assert m and {int(i) for i in m.group(1).split(", ")} <= ids, n


def test_scan_of_consecutive_slow_ids_behind_an_echoing_adapter():
    bus = make(ids="1-6", turnaround="20", gap="1", echo="1")
    notes = []
    found, warnings = records(bus, list(range(0, 40)), notes=notes)
    assert [(r["id"], r["status"], r["model"]) for r in found] == [(i, "ok", MODEL_NUMBER) for i in range(1, 7)]
    only_late(warnings, notes, set(range(1, 7)))


def test_a_late_answer_is_a_note_once_per_bus_where_nothing_went_wrong():
    bus = make(ids="1,5", faults="5:delay=60", clock="virtual")
    notes = []
    found, warnings = records(bus, list(range(0, 10)), notes=notes)
    assert [(r["id"], r["status"]) for r in found] == [(1, "ok"), (5, "ok")] and warnings == []
    assert notes == ["ID 5 at 57600 baud answered after the scan's quick wait (latency 62.0 ms): found and "
                     "identified; the IDs near it were probed again"]
    again = []
    records(bus, list(range(0, 10)), notes=again)
    assert again == []                                          # said once on this bus
    # where something went wrong (two units with ID 5, the late one's replies garbled) no note:
    # warnings
    bus = make(ids="1,5,5", faults="5:delay=60", clock="virtual")
    bus.port.device.actuators[2].set("present-position", 2000)
    notes = []
    found, warnings = records(bus, list(range(0, 30)), notes=notes)
    assert [(r["id"], r["status"]) for r in found] == [(1, "ok"), (5, "garbled")] and notes == []
    assert warnings


def test_scan_return_mode_0_is_found_out_not_guessed():
    bus = make(ids="3", return_mode=1)
    bus.port.device.actuator(3).set("feedback-return-mode", 0)
    found, _ = records(bus, [3])
    assert (found[0]["status"], found[0]["return_mode"], found[0]["model"]) == ("ok", 0, None)


def test_scan_warns_of_two_actuators_with_one_id():
    bus = make(ids="1,4,4")
    bus.port.device.actuators[2].set("present-position", 2000)   # two units: the live registers differ
    found, warnings = records(bus, [1, 4])
    by_id = {r["id"]: r for r in found}
    assert by_id[1]["status"] == "ok"
    # colliding replies: garbled at the Echo (the simulator models the wired-AND of two senders a
    # byte apart), or readable Echoes whose live registers then disagree
    assert by_id[4]["status"] in ("duplicate", "garbled")
    named = [w for w in warnings if "ID 4" in w and "two actuators" in w]
    assert len(named) == 1 and all(w in named or "burst" in w for w in warnings), warnings


def test_answers_counts_error_bits_and_garbled_replies():
    bus = make(ids="1,2")
    bus.port.device.inject(1, "overload")
    bus.port.device.inject(2, "corrupt")
    assert bus.answers(1) and bus.answers(2) and not bus.answers(3)


class Scripted:
    """A port on which the bytes scripted for a written packet are there the moment it is
    written: what a host finds that was held up (a loaded machine) while they arrived."""

    baudrate = 57600
    port = "scripted"
    timeout = 0.1

    def __init__(self, answers):
        self.answers = answers
        self.rx = bytearray()

    @property
    def in_waiting(self):
        return len(self.rx)

    def write(self, data):
        self.rx += self.answers.get(bytes(data), b"")
        return len(data)

    def read(self, n=1):
        out = bytes(self.rx[:n])
        del self.rx[:n]
        return out

    def reset_input_buffer(self):
        self.rx.clear()

    def close(self):
        pass


# the wired-AND of two Echo replies from ID 1 a byte apart, as a collision leaves it
COLLIDED = bytes.fromhex("ffffff01000000fc")


def test_a_reply_waiting_past_the_deadline_is_read_not_taken_for_silence():
    bus = ZapBus(Scripted({zap.echo(3): zap.packet(3, 0)}), return_mode=1)
    bus.timeout = 1e-9                                        # the deadline has passed before the first read
    assert bus.ping(3).ident == 3


def test_collision_bytes_before_a_reply_are_reported_to_scans():
    # ID 1's quick probe gave up before its colliding replies came; they arrive ahead of ID 2's reply
    bus = ZapBus(Scripted({zap.echo(2): COLLIDED + zap.packet(2, 0)}), return_mode=1)
    assert bus.ping(1, quick=True, early=True) is None
    assert bus.ping(2, quick=True, early=True).ident == 2
    assert [e.kind for e in bus.take_events()] == ["garbled"]


def test_bytes_held_for_a_packet_that_never_completes_are_dated_when_they_came():
    """A scan judges garbled bytes by the windows they fell in: the start of a reply that never
    completes is dated when it was read, not when the line was given up on (a window that had
    closed meanwhile would lose the ID that sent it)."""
    port = Scripted({})
    bus = ZapBus(port, return_mode=1)
    port.rx += bytes.fromhex("ffffff0302")                    # the start of a reply, and nothing more
    came = time.monotonic()
    bus.linger(0.15)
    garbled = [e for e in bus.take_events() if e.kind == "garbled"]
    assert garbled and garbled[0].hi - came < 0.05            # not 0.15 s later, at the flush


def test_scan_identify_failure_leaves_fields_null():
    """ID 3 answers its first-pass Echo only late (while ID 4 is probed: heard, so found), then
    nothing: its identification fails and says why; no field is guessed."""
    port = Scripted({})
    late = [zap.packet(3, 0)]

    def write(data):
        if bytes(data) == zap.echo(4) and late:
            port.rx += late.pop()
        return len(data)

    port.write = write
    bus = ZapBus(port, return_mode=1)
    bus.timeout = 0.01
    found, _ = records(bus, [2, 3, 4, 5], retries=0)
    assert [(r["id"], r["status"], r["model"], r["return_mode"]) for r in found] == [(3, "unidentified", None, None)]
    assert "answers only after the window" in found[0]["errors"][0] and "late" in found[0]["errors"][0]


def test_scan_finds_the_shared_id_whose_collision_came_during_the_next_probe():
    answers = {zap.echo(2): COLLIDED + zap.packet(2, 0),     # the first, quick probe of ID 1
               zap.echo(1): COLLIDED}                         # ... and every later one
    port = Scripted(answers)
    first = True

    def write(data):
        nonlocal first
        if bytes(data) == zap.echo(1) and first:
            first = False
            return len(data)                                  # its collision comes later, see echo(2)
        return Scripted.write(port, data)

    port.write = write
    bus = ZapBus(port, return_mode=1)
    bus.timeout = 0.02                                        # a short window: the scripted port never answers late
    found, warnings = records(bus, [0, 1, 2, 3])
    assert [(r["id"], r["status"]) for r in found][:1] == [(1, "garbled")]
    assert any("ID 1" in w and "garbled" in w for w in warnings)


class LateLine(Scripted):
    """One actuator, ``ident``, answering ``latency`` s after a request's last byte left, its
    reply on the line for its bytes' time; a host write while it is on the line garbles it (a
    collision). Its first Echo reply meets a probe whatever the host does (the collision this
    test is about); later ones only if the host transmits over them (counted in
    ``collisions``)."""

    port = "late-line"

    def __init__(self, ident, latency):
        super().__init__({})
        self.ident, self.latency = ident, latency
        self.byte = wire_time(1, 57600)
        self.line = []                    # [start, bytes] of replies on their way
        self.echoes = 0
        self.collisions = 0

    def _deliver(self):
        now = time.monotonic()
        for item in [x for x in self.line if x[0] + len(x[1]) * self.byte <= now]:  # [start, bytes, counted]
            self.line.remove(item)
            self.rx += item[1]

    @property
    def in_waiting(self):
        self._deliver()
        return len(self.rx)

    def write(self, data):
        data = bytes(data)
        start = time.monotonic()
        end = start + len(data) * self.byte
        for item in self.line:
            if item[0] < end and item[0] + len(item[1]) * self.byte > start:
                item[1] = bytes(b & 0x5A for b in item[1])     # garbled on the line
                self.collisions += item[2]
        if data[3] != self.ident:
            return len(data)
        if data == zap.echo(self.ident):
            self.echoes += 1
            reply = zap.packet(self.ident, 0)
            if self.echoes == 1:
                reply = bytes(b & 0x5A for b in reply)          # it met a probe
        elif data[5] == zap.LOAD_DATA:
            reply = zap.packet(self.ident, 0, bytes(data[7]))
        else:
            return len(data)
        self.line.append([end + self.latency, reply, int(self.echoes > 1 or data[5] != zap.ECHO)])
        return len(data)

    def read(self, n=1):
        deadline = time.monotonic() + (self.timeout or 0)
        while not self.in_waiting and time.monotonic() < deadline:
            time.sleep(0.0002)
        return super().read(n)


def test_a_late_reply_that_met_a_probe_is_found_in_a_quick_round_not_by_asking_every_suspect():
    """ID 9's Echo reply, 140 ms late, is garbled on the line: any of the ~35 IDs probed in the
    150 ms before may have sent it. The quick round probes them again with the line kept free
    where those bytes would come again: ID 9's reply comes through clean, and nothing in its
    window is left to ask with the whole window (which would cost about 155 ms an ID)."""
    port = LateLine(9, 0.140)
    bus = ZapBus(port, return_mode=1)
    phases, found = [], []
    for event in scan(bus, list(range(0, 41)), [57600]):
        if event[0] == "probe":
            phases.append(event[4])
        elif event[0] == "record":
            found.append((event[1]["id"], event[1]["status"]))
    assert found == [(9, "ok")]
    assert phases.count("first") == 41
    assert phases.count("round") >= 20                        # the suspects, once more, quickly
    assert phases.count("ask") <= 3                           # not every suspect at 155 ms each
    # the round kept the line free where the reply came (a host held up for longer than the free
    # slot's margin, 12 ms, could still meet it once: the spaced second round finds it then)
    assert port.collisions <= 1


def test_what_is_learned_of_an_actuator_goes_with_it_when_its_id_or_baud_changes():
    from zkzap.link.zap_timing import Policy

    pol = Policy(margin=0.0)
    pol.switch(57600)
    for _ in range(4):
        pol.learn(1, 0.022, 0.1)
        pol.learn(2, 0.300, 1.0)
    pol.moved(1, 9)                                   # set-id 1 -> 9
    assert 1 not in pol.estimators and pol.estimators[9].srtt == pytest.approx(0.022)
    pol.moved_to(2, 115200)                           # set-baud of ID 2
    assert 2 not in pol.estimators
    pol.switch(115200)
    assert pol.estimators[2].srtt == pytest.approx(0.300)
