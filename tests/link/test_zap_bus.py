"""mightyZAP transactions through the in-process simulator (sim://zap) with real pyserial."""

import time

import pytest

from zkzap.codec import zap
from zkzap.codec.permissions import Permission
from zkzap.errors import BadReply, DeviceError, NoReply, PortError, UsageError
from zkzap.link.port import open_port, sim_url
from zkzap.link.zap_bus import (LATE_WINDOW, MARGIN, NETWORK_MARGIN, ZapBus, host_margin, is_simulated,
                                leaves_protocol, open_bus, stored_writes, wire_time)


def make(ids="1,2", return_mode=1, **opts):
    port = open_port(sim_url("zap", ids=ids, **opts), 57600, timeout=0.1)
    return ZapBus(port, return_mode=return_mode)


@pytest.fixture
def bus():
    b = make()
    yield b
    b.close()


@pytest.fixture
def vbus():
    """A bus on the simulator's virtual clock: the moment after a write lasts as long as the
    model says, however long the host is held up (spare work's timing is then the model's)."""
    b = make(clock="virtual")
    yield b
    b.close()


def test_the_wait_is_the_late_window_plus_the_wire():
    b = make()
    assert wire_time(10, 57600) == pytest.approx(10 * 10 / 57600)
    assert b.margin == MARGIN
    t57 = b.reply_timeout(7, 7)
    assert t57 == pytest.approx(14 * 10 / 57600 + LATE_WINDOW + MARGIN)
    b.set_baud(115200)
    assert b.reply_timeout(7, 7) == pytest.approx(14 * 10 / 115200 + LATE_WINDOW + MARGIN)
    assert b.reply_timeout(7, 7) < t57
    b.timeout = 0.5                                              # --timeout: the window
    assert b.window == 0.5 and b.reply_timeout(7, 7) == pytest.approx(14 * 10 / 115200 + 0.5 + MARGIN)
    b.timeout, b.latency = None, 0.3                             # --latency: the window it needs
    assert b.window == pytest.approx(0.3 * 1.25 + MARGIN)


def test_margin_by_port_kind():
    assert host_margin("socket://127.0.0.1:5000") == MARGIN
    assert host_margin("socket://10.1.2.3:5000") == MARGIN + NETWORK_MARGIN
    assert host_margin("/dev/does-not-exist") == MARGIN
    assert is_simulated("sim://zap") and is_simulated("loop://")
    assert not is_simulated("socket://localhost:1") and not is_simulated("/dev/ttyUSB0")


def test_echo_load_and_blocks(bus):
    r = bus.echo(1)
    assert (r.ident, r.error, r.data) == (1, 0, b"")
    assert 0 < r.rtt < 0.05
    assert bus.read(2, "present-voltage") == 120
    reply, values = bus.read_registers(1, 0x00, 5)
    assert [(reg.name, v) for reg, v in values][:4] == [("model-number", 0xA112), ("firmware-version", 21),
                                                       ("id", 1), ("baud-rate", 32)]


def test_writes_wait_only_for_replies_the_mode_gives(bus, monkeypatch):
    def no_wait(*args, **kwargs):
        raise AssertionError("waited for a reply mode 1 never gives")

    with monkeypatch.context() as m:
        m.setattr(bus, "_await", no_wait)
        assert bus.store(1, "goal-position", 2000) is None      # mode 1: not answered
    # the simulator answers in the mode the command arrived in (1: no reply); the link waits
    # because mode 2 would answer, takes the silence, and follows the new mode from now on
    assert bus.store(1, "feedback-return-mode", 2) is None
    assert bus.mode_of(1) == 2 and bus.mode_of(2) == 1 and bus.return_mode == 1   # that actuator's own
    r = bus.store(1, "led", 2)                                   # mode 2: acknowledged
    assert r.ident == 1 and r.error == 0
    assert bus.execute() is None                                 # broadcast
    assert bus.read(1, "goal-position") == 2000


def test_return_mode_0_answers_echo_only():
    b = make(ids="1", return_mode=0)
    b.port.device.actuator(1).set("feedback-return-mode", 0)
    with pytest.raises(UsageError, match="feedback-return-mode 0"):
        b.load(1, 0x8C, 2)
    assert b.echo(1).ident == 1
    assert b.detect_return_mode(1) == 0
    b.port.device.actuator(1).set("feedback-return-mode", 2)
    assert b.detect_return_mode(1) == 2 and b.mode_of(1) == 2 and b.return_mode == 0


def test_error_bits_raise_device_error_with_the_reply(bus):
    bus.port.device.inject(2, "overload")
    with pytest.raises(DeviceError) as e:
        bus.read(2, "present-position")
    assert e.value.code == 5
    assert "ID 2 reports error 0x20: overload" in str(e.value)
    assert e.value.reply.value == 0
    r = bus.load(2, 0x8C, 2, check=False)
    assert r.errors == ["overload"]
    bus.port.device.inject(1, "voltage", 5.0)
    with pytest.raises(DeviceError, match="input voltage out of the operating range"):
        bus.echo(1)


@pytest.mark.parametrize("kind,code,needle", [
    ("corrupt", 6, "garbled reply (checksum mismatch: a collision, two actuators answering at once, or a line fault) after 3 tries"),
    ("truncate", 6, "truncated reply"),
    ("wrong-id", 6, "reply from ID 3, expected ID 2"),
    ("silent", 3, "no reply from ID 2 at 57600 baud"),
])
def test_failures_after_retries(bus, kind, code, needle):
    bus.port.device.inject(2, kind)
    sent = bus.sent
    with pytest.raises((BadReply, NoReply)) as e:
        bus.read(2, "present-position")
    assert e.value.code == code
    assert needle in str(e.value)
    assert bus.sent - sent == 3                                  # 1 + 2 retries
    assert bus.read(1, "present-position") == 0                  # the bus is usable afterwards


def test_a_single_bad_reply_is_retried(bus):
    bus.port.device.inject(1, "corrupt", count=1)
    assert bus.read(1, "present-voltage") == 120
    assert bus.retried == 1


def test_no_reply_takes_tries_times_timeout(bus):
    limit = bus.reply_timeout(9, 9)
    t = time.monotonic()
    with pytest.raises(NoReply):
        bus.read(7, "present-position")
    took = time.monotonic() - t
    assert took >= 3 * limit                                     # every try waited its whole allowance
    assert (bus.sent, bus.retried) == (3, 2)                     # ... and there were exactly three


def test_half_duplex_echo_is_skipped(bus):
    bus.port.device.echo = True
    assert bus.read(1, "present-voltage") == 120
    assert bus.adapter_echo
    with pytest.raises(NoReply, match="only our own bytes came back"):
        bus.echo(9, retries=0)


def test_late_reply_from_a_slow_actuator_still_counts(bus):
    bus.port.device.inject(1, "delay", 5, count=1)
    assert bus.echo(1, retries=2).ident == 1


def test_id_change_acknowledged_by_either_id():
    b = make(ids="1", return_mode=2)
    b.port.device.actuator(1).set("feedback-return-mode", 2)
    r = b.store(1, "id", 5, allow=Permission.IDENTITY)
    assert r.ident in (1, 5)
    assert b.echo(5).ident == 5


def test_restart_and_wait_ready():
    b = make(ids="1", return_mode=2)
    b.port.device.actuator(1).set("feedback-return-mode", 2)
    b.store(1, "baud-rate", zap.BAUD_TO_CODE[115200], allow=Permission.IDENTITY)
    assert b.restart(1).ident == 1
    b.set_baud(115200)
    assert b.wait_ready(1, within=1.0).ident == 1
    assert b.read(1, "baud-rate") == 16


def test_documented_restart_copy_reply_is_accepted():
    """The document's Restart feedback repeats the command; a loop:// line gives exactly that."""
    b = ZapBus(open_port("loop://", 57600, timeout=0.1), return_mode=2, url="loop://")
    r = b.restart(3)
    assert r.ident == 3 and r.packet == zap.restart(3)


def test_symmetric_store_moves_several(bus):
    bus.symmetric_store("goal-position", [(1, 300), (2, 600)])
    assert bus.read(1, "goal-position") == 300
    assert bus.read(2, "goal-position") == 600


def test_unknown_instruction_reply_is_optional(bus):
    assert bus.command(zap.packet(1, 0x99, b"\x01"), allow=Permission.UNDOCUMENTED) is None


def test_ping_for_scans(bus):
    assert bus.ping(1).ident == 1
    assert bus.ping(9) is None
    bus.port.device.inject(2, "corrupt")
    with pytest.raises(BadReply):
        bus.ping(2, retries=1)


class Vanishing:
    """A port that fails like an unplugged USB adapter."""

    baudrate = 57600
    port = "/dev/ttyUSB9"

    def reset_input_buffer(self):
        pass

    def write(self, data):
        return len(data)

    def read(self, n):
        import serial

        raise serial.SerialException("device reports readiness to read but returned no data")

    timeout = 0.1

    def close(self):
        pass


def test_a_vanished_port_is_a_port_error():
    b = ZapBus(Vanishing())
    with pytest.raises(PortError) as e:
        b.echo(1)
    assert e.value.code == 4 and "/dev/ttyUSB9" in str(e.value)


def test_stored_writes_and_protocol_change():
    assert stored_writes(zap.store(1, "long-stroke-limit", 3000)) == ["long-stroke-limit"]
    assert stored_writes(zap.store(1, "goal-position", 3000)) == []
    assert stored_writes(zap.factory_reset(1)) != []
    (sync,) = zap.symmetric_store("speed-limit", [(1, 5)])
    assert stored_writes(sync) == ["speed-limit"]
    assert stored_writes(zap.packet(1, 0xF3, bytes([0x03, 0x01, 0x20]))) == ["id", "baud-rate"]
    assert leaves_protocol(zap.store(1, "protocol-type", 0))
    assert not leaves_protocol(zap.store(1, "protocol-type", 1))
    (sync,) = zap.symmetric_store("protocol-type", [(1, 1), (2, 0)])
    assert leaves_protocol(sync)


def test_open_bus_needs_a_port():
    with pytest.raises(UsageError, match="no port"):
        open_bus(None)
    with open_bus(sim=True, sim_ids="4", baud=115200) as b:
        assert b.echo(4).ident == 4 and b.baud == 115200


def _raw_pty_bus():
    """A ZapBus on pyserial's own port over a new pty: (bus, port, master, path)."""
    import os
    import tty

    import serial

    master, slave = os.openpty()
    tty.setraw(slave)
    tty.setraw(master)
    path = os.ttyname(slave)
    port = serial.Serial(path, 57600, timeout=0)
    os.close(slave)
    b = ZapBus(port, url=path)
    assert b._raw                                          # written and read through its descriptor
    return b, port, master, path


def test_a_serial_port_whose_line_goes_away_mid_wait_is_a_port_error_in_words():
    # pyserial's own port is read through its descriptor: the words stay pyserial's, made plain
    import os
    import threading

    b, port, master, path = _raw_pty_bus()
    threading.Timer(0.05, os.close, (master,)).start()     # the adapter is unplugged while it waits
    try:
        with pytest.raises(PortError) as e:
            b.echo(1)
        assert e.value.code == 4 and str(e.value).startswith(f"port {path} failed: ")
        assert "Errno" not in str(e.value) and ("Input/output error" in str(e.value) or "went away" in str(e.value))
    finally:
        port.close()


def test_a_serial_port_whose_line_is_gone_before_a_write_is_a_port_error_in_words():
    import os

    b, port, master, path = _raw_pty_bus()
    os.close(master)                                       # unplugged between two commands
    try:
        with pytest.raises(PortError) as e:
            b.echo(1)
        assert e.value.code == 4 and str(e.value).startswith(f"port {path} failed: ")
        assert "Errno" not in str(e.value) and "Input/output error" in str(e.value)
        with pytest.raises(PortError) as e:                # the write itself, in pyserial's words
            b._write_fd(zap.echo(1))
        assert str(e.value) == f"port {path} failed: write failed: Input/output error"
    finally:
        port.close()


def test_a_request_the_driver_cannot_take_at_once_waits_for_room_and_goes_out_whole():
    # the descriptor's write takes what fits; the rest goes through pyserial's write, which
    # waits until the line has room: nothing is lost or sent twice
    import os
    import threading

    b, port, master, _ = _raw_pty_bus()
    filled = 0
    try:
        while True:
            filled += os.write(port.fd, b"\0" * 256)
    except BlockingIOError:
        pass
    got = bytearray()
    os.set_blocking(master, False)

    def drain():
        time.sleep(0.05)                                   # the write waits meanwhile
        end = time.monotonic() + 5
        while time.monotonic() < end and len(got) < filled + 7:
            try:
                got.extend(os.read(master, 65536))
            except BlockingIOError:
                time.sleep(0.001)

    t = threading.Thread(target=drain)
    t.start()
    try:
        b._write(zap.echo(1))
        t.join()
        assert len(got) == filled + 7 and bytes(got[filled:]) == zap.echo(1) and not any(got[:filled])
    finally:
        t.join()
        port.close()
        os.close(master)


def test_spare_work_runs_while_the_request_is_on_the_wire_and_never_before_it(vbus):
    bus = vbus
    seen = []
    bus.spare(lambda: seen.append((bus.sent, bus.replies)))
    assert seen == []                                   # nothing runs when it is handed over
    assert bus.read(1, "present-position") == 0
    assert seen == [(1, 0)]                             # after the write, before the reply was read
    bus.read(1, "present-position")
    assert seen == [(1, 0)]                             # once
    bus.spare(lambda: seen.append("at close"))
    bus.close()
    assert seen[-1] == "at close"                       # what is left runs when the bus closes


def test_spare_work_that_outlasts_the_request_leaves_the_latency_unknown_not_longer(vbus):
    bus = vbus
    bus.read(1, "present-position")
    est = bus.policy.estimator(1)
    samples, srtt = est.samples, est.srtt
    bus.spare(lambda: bus.sleep(bus.wire(9) * 3))       # a blocked output, say
    r = bus.load(1, 0x8C, 2)
    assert r.latency is None and r.rtt > bus.wire(9) * 3      # the round trip is what it was
    assert (est.samples, est.srtt) == (samples, srtt)        # and nothing was learned from it
    assert bus.load(1, 0x8C, 2).latency is not None


def test_spare_work_waits_for_a_request_whose_reply_it_can_wait_for(vbus):
    bus = vbus
    seen = []
    bus.spare(lambda: seen.append(bus.sent))
    bus.store(1, "goal-position", 100)                   # return mode 1: no reply, no wait
    assert seen == []
    bus.read(1, "goal-position")
    assert seen == [2]
    bus.run_spare()
    assert seen == [2]


def test_a_request_interrupted_while_its_reply_is_on_its_way_leaves_every_id_readable():
    # a Ctrl-C in a play's log read: the stop that follows must read every actuator's position
    # (the interrupted read's reply is that read's, late; it never makes its ID suspect)
    b = make(clock="virtual")
    read = b.port.read

    def interrupted(n):
        b.port.read = read
        raise KeyboardInterrupt

    for ident in (1, 2):
        b.port.read = interrupted
        with pytest.raises(KeyboardInterrupt):
            b.load(ident, 0x8C, 6)
        assert b.read(1, "present-position") == 0 and b.read(2, "present-position") == 0
        assert b.devices[ident].late == 1
    b.close()
