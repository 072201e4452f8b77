"""Attribution and timing of mightyZAP transactions against slow, late and trickling devices."""

import time

import pytest

from zkzap.codec import zap
from zkzap.errors import BadReply, NoReply
from zkzap.link.port import open_port, sim_url
from zkzap.link.zap_bus import LATE_WINDOW, MAX_TURNAROUND, TURNAROUND, ZapBus, wire_time
from zkzap.link.zap_scan import scan
from zkzap.sim.zap_actuators import MODEL_NUMBER


def make(ids="1,2", return_mode=1, **opts):
    return ZapBus(open_port(sim_url("zap", ids=ids, **opts), 57600, timeout=0.1), return_mode=return_mode)


def test_a_late_reply_is_never_the_answer_to_the_next_request():
    bus = make()
    bus.port.device.actuator(2).set("goal-speed", 700)
    bus.port.device.inject(2, "delay", 30, count=1)          # later than the whole first wait
    assert bus.read(2, "present-position") == 0               # answered (by the retry or the late reply)
    assert bus.read(2, "goal-speed") == 700                   # not the late present-position reply
    assert bus.echo(1).ident == 1
    bus.linger(0.05)
    assert bus.late >= 1 and bus.retried >= 1


def test_a_late_reply_is_not_a_wrong_id_for_another_actuator():
    bus = make()
    bus.port.device.inject(2, "delay", 30, count=1)
    assert bus.echo(2).ident == 2
    assert bus.ping(5) is None                                # the retry's reply is owed, not "wrong ID"
    assert not bus.answers(5)
    assert bus.answers(2)


def test_round_trip_is_measured_from_the_answered_attempt():
    bus = make(turnaround="5")
    r = bus.echo(1)
    assert r.rtt >= wire_time(14, 57600) + 0.005
    assert r.rtt < 0.2


@pytest.mark.parametrize("opts", [{"turnaround": "20"}, {"turnaround": "20", "gap": "1"},
                                  {"turnaround": "20", "gap": "1", "echo": "1"}])
def test_slow_and_trickling_devices_with_default_timing(opts):
    bus = make(**opts)
    assert bus.echo(1).ident == 1
    reply, values = bus.read_registers(2, 0x00, 17)
    assert len(reply.data) == 17 and values[0][1] == MODEL_NUMBER


def test_bytes_more_than_the_inter_byte_allowance_apart_are_a_truncated_reply():
    bus = make(gap="30")
    with pytest.raises(BadReply, match="truncated reply"):
        bus.read(1, "present-position", retries=0)


def test_quick_probe_learns_the_turnaround():
    bus = make()
    before = bus.quick_timeout(7)
    assert before == pytest.approx(wire_time(8, 57600) + TURNAROUND + 0.0005)
    for _ in range(3):
        bus.echo(1)
    assert bus.typical_turnaround < MAX_TURNAROUND
    assert bus.quick_timeout(7) < bus.reply_timeout(7, 7)
    slow = make(turnaround="15")
    for _ in range(3):
        slow.echo(1)
    assert slow.quick_timeout(7) > 0.015                      # a slow bus gets waits to match


def test_no_reply_waits_the_full_allowance():
    bus = make()
    t = time.monotonic()
    with pytest.raises(NoReply, match="within"):
        bus.echo(9, retries=0)
    assert time.monotonic() - t >= MAX_TURNAROUND


def records(bus, ids, bauds=(57600,)):
    out, warnings = [], []
    for event in scan(bus, ids, list(bauds)):
        if event[0] == "record":
            out.append(event[1])
        elif event[0] == "warning":
            warnings.append(event[1])
    return out, warnings


@pytest.mark.parametrize("opts", [{"faults": "2:delay=18,9:delay=20"}, {"turnaround": "20", "gap": "1"},
                                  {"turnaround": "20", "echo": "1"}, {"faults": "all:delay=12"}])
def test_scan_finds_every_slow_actuator(opts):
    bus = make(ids="1,2,5,9,20", **opts)
    found, warnings = records(bus, list(range(0, 24)))
    assert sorted(r["id"] for r in found) == [1, 2, 5, 9, 20]
    assert all(r["status"] == "ok" and r["model"] == MODEL_NUMBER and r["return_mode"] == 1 for r in found)
    assert warnings == []


def test_scan_identify_failure_leaves_fields_null():
    bus = make(ids="3")
    bus.timeout = 0.003                                      # shorter than any reply can take
    found, _ = records(bus, [2, 3, 4])
    assert [(r["id"], r["status"], r["model"], r["return_mode"]) for r in found] == [(3, "unidentified", None, None)]
    assert "late" in found[0]["errors"][0]


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
    assert len(warnings) == 1 and "ID 4" in warnings[0] and "two actuators" in warnings[0]


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
    assert bus.ping(1, quick=True) is None
    assert bus.ping(2, quick=True).ident == 2
    assert [kind for kind, _, _ in bus.take_events()] == ["garbled"]


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
    found, warnings = records(bus, [0, 1, 2, 3])
    assert [(r["id"], r["status"]) for r in found][:1] == [(1, "garbled")]
    assert any("ID 1" in w and "garbled" in w for w in warnings)


@pytest.mark.parametrize("turnaround,late", [("10", False), ("40", True)])
def test_lateness_is_measured_against_the_full_allowance(turnaround, late):
    bus = make(ids="1", turnaround=turnaround)
    assert bus.ping(1, quick=True) is None                    # the quick wait is far shorter than either
    bus.linger(0.1)
    assert [kind for kind, _, _ in bus.take_events()] == ["late"]
    # a reply within the full allowance says nothing of the actuator being slow
    assert (bus.lateness > 0.01) is late and (bus.patience() > 0) is late
    assert bus.patience() <= LATE_WINDOW


@pytest.mark.parametrize("turnaround", ["30", "60"])
def test_scan_identifies_actuators_slower_than_the_allowance(turnaround):
    bus = make(ids="1,2,5", turnaround=turnaround)
    found, warnings = records(bus, list(range(10)))
    assert [(r["id"], r["status"], r["model"], r["return_mode"]) for r in found] == \
        [(i, "ok", MODEL_NUMBER, 1) for i in (1, 2, 5)]
    assert warnings == []
