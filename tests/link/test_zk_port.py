"""The port to a ZK ECU: bytes in (counted, kept in the raw log), frames out (counted), a failed
port as PortError naming the port, and sim:// recognised as the simulator."""

import io
import time

import pytest
import serial

from zkzap.codec import zk
from zkzap.codec.framing import ZkFramer
from zkzap.errors import PortError
from zkzap.link.zk_port import READ_SLICE_S, ZkLink, is_simulator


class Broken:
    """A port whose every read and write fails like an unplugged adapter."""

    timeout = READ_SLICE_S
    baudrate = 115200

    def read(self, n=1):
        raise serial.SerialException("read failed: [Errno 5] Input/output error")

    def write(self, data):
        raise OSError(5, "Input/output error")

    def flush(self):
        pass

    def close(self):
        pass


def test_reads_are_counted_and_kept_byte_for_byte_in_the_raw_log():
    raw = io.BytesIO()
    link = ZkLink.open("sim://zk?speed=20", 115200, raw_log=raw)
    try:
        assert link.device is not None and link.baud == 115200
        got = b""
        while len(ZkFramer("status").feed(got)) < 5:
            got += link.read()
        link.write(zk.encode_control("keepalive")[0])
        assert link.frames_out == 1 and link.device.received[-1]["command"] == "keepalive"
    finally:
        link.close()
    assert link.bytes_in == len(got) and raw.getvalue() == got


def test_a_failed_port_is_port_error_naming_it():
    link = ZkLink(Broken(), "/dev/ttyUSB7")
    with pytest.raises(PortError, match=r"^port /dev/ttyUSB7 failed: read failed: Input/output error$"):
        link.read()
    with pytest.raises(PortError, match=r"^port /dev/ttyUSB7 failed: Input/output error$"):
        link.write(b"\xff\x00\x00\x00")
    assert link.frames_out == 0 and link.bytes_in == 0


def test_only_sim_urls_are_the_simulator():
    assert is_simulator("sim://zk?speed=10")
    assert not is_simulator("/dev/ttyUSB0") and not is_simulator("socket://localhost:7000")


class Vanished(Broken):
    """An unplugged USB adapter under pyserial: tcdrain in flush() raises termios.error, which
    prints as a tuple, and reads see pyserial's own words for a device that went away."""

    def read(self, n=1):
        raise serial.SerialException("device reports readiness to read but returned no data (device "
                                     "disconnected or multiple access on port?)")

    def write(self, data):
        return len(data)

    def flush(self):
        import termios

        raise termios.error(5, "Input/output error")


def test_a_vanished_port_is_one_plain_line_without_a_python_tuple():
    link = ZkLink(Vanished(), "/dev/ttyUSB7")
    with pytest.raises(PortError) as e:
        link.write(b"\xff\x00\x00\x00")
    assert str(e.value) == "port /dev/ttyUSB7 failed: Input/output error"
    with pytest.raises(PortError) as e:
        link.read()
    assert str(e.value) == ("port /dev/ttyUSB7 failed: the device went away (it reports data to read but returns "
                            "none: unplugged, or another program reads it)")


@pytest.mark.parametrize("error,said", [
    (OSError(5, "Input/output error"), "Input/output error"),
    (serial.SerialException("Could not configure port: (25, 'Inappropriate ioctl for device')"),
     "Could not configure port: Inappropriate ioctl for device"),
    (serial.SerialException("could not open port 'COM3': PermissionError(13, 'Access is denied.', None, 5)"),
     "could not open port 'COM3': Access is denied."),
    (serial.SerialException("write failed: [Errno 5] Input/output error"), "write failed: Input/output error"),
])
def test_reasons_are_the_os_words(error, said):
    from zkzap.link.port import reason

    assert reason(error) == said


def test_an_open_that_outlasts_its_time_is_given_up_and_its_late_port_closed(monkeypatch):
    """open_within: an open still running after its time is a PortError then; the port it
    opens afterwards is closed, never left open behind the caller's back."""
    import threading

    from zkzap.link import port as port_mod

    release, closed = threading.Event(), threading.Event()

    class Late:
        def close(self):
            closed.set()

    def slow_open(url, baud, **kw):
        release.wait(5)
        return Late()

    monkeypatch.setattr(port_mod, "open_port", slow_open)
    t = time.monotonic()
    with pytest.raises(PortError, match="no answer within 0.2 s"):
        port_mod.open_within(0.2, "socket://192.0.2.1:7", 57600)
    assert time.monotonic() - t < 1.0
    release.set()
    assert closed.wait(2)
    # an open that ends in time gives its port, or its own error
    monkeypatch.setattr(port_mod, "open_port", lambda url, baud, **kw: "port")
    assert port_mod.open_within(1.0, "x", 57600) == "port"

    def failing(url, baud, **kw):
        raise PortError("port x: cannot open: gone")

    monkeypatch.setattr(port_mod, "open_port", failing)
    with pytest.raises(PortError, match="gone"):
        port_mod.open_within(1.0, "x", 57600)
