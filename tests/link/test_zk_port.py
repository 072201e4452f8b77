"""The port to a ZK ECU: bytes in (counted, kept in the raw log), frames out (counted), a failed
port as PortError naming the port, and sim:// recognised as the simulator."""

import io

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
