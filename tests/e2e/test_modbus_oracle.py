"""zkzap against pymodbus, an independent Modbus stack playing a 17Lf: a pymodbus server (RTU
framing over TCP, its datastore the 17Lf's control table) is found by zkzap's scan, read and
written through the library; what zkzap wrote is what pymodbus's own client reads back."""

import asyncio
import socket
import threading
import time
import warnings

import pytest

from zkzap import Bus, ExceptionReply, NoReply
from zkzap.codec.regmap import builtin

MAP = builtin("17lf-modbus")


def _free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


class PymodbusActuators:
    """A pymodbus TCP server with RTU framing: devices ``ids``, each a sparse holding-register
    block with the 17Lf's addresses and defaults (its gaps answer exception 2)."""

    def __init__(self, ids):
        self.ids = set(ids)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            from pymodbus.datastore import ModbusDeviceContext, ModbusServerContext, ModbusSparseDataBlock

            table = {r.address: r.default or 0 for r in MAP.registers}
            table[MAP.by_name["model-number"].address] = 0x1711
            self.context = ModbusServerContext(
                devices={i: ModbusDeviceContext(hr=ModbusSparseDataBlock(dict(table))) for i in ids}, single=False)
        self.port = _free_port()
        self.loop = asyncio.new_event_loop()
        self.server = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        for _ in range(200):
            try:
                socket.create_connection(("127.0.0.1", self.port), 0.2).close()
                break
            except OSError:
                time.sleep(0.05)
        self.url = f"socket://127.0.0.1:{self.port}"

    def _run(self):
        from pymodbus.framer import FramerType
        from pymodbus.server import ModbusTcpServer

        asyncio.set_event_loop(self.loop)

        async def serve():
            self.server = ModbusTcpServer(self.context, framer=FramerType.RTU, address=("127.0.0.1", self.port),
                                          ignore_missing_devices=True, trace_packet=self._silent_when_absent)
            await self.server.serve_forever()

        try:
            self.loop.run_until_complete(serve())
        except Exception:  # noqa: BLE001 - stopped
            pass

    def _silent_when_absent(self, sending, data):
        # a unit that is not on the line never answers (pymodbus would send exception 4)
        return b"" if sending and data and data[0] not in self.ids else data

    def _client(self):
        from pymodbus.client import ModbusTcpClient
        from pymodbus.framer import FramerType

        client = ModbusTcpClient("127.0.0.1", port=self.port, framer=FramerType.RTU, timeout=2, retries=1)
        assert client.connect()
        return client

    def value(self, ident, address):
        """A register as pymodbus's own client reads it from the server's datastore."""
        client = self._client()
        try:
            r = client.read_holding_registers(address, count=1, device_id=ident)
            assert not r.isError(), r
            return r.registers[0]
        finally:
            client.close()

    def set(self, ident, address, value):
        client = self._client()
        try:
            assert not client.write_register(address, value, device_id=ident).isError()
        finally:
            client.close()

    def close(self):
        if self.server is not None:
            asyncio.run_coroutine_threadsafe(self.server.shutdown(), self.loop).result(5)
        self.thread.join(5)


@pytest.fixture
def peer():
    p = PymodbusActuators([3, 7])
    yield p
    p.close()


def test_zkzap_finds_reads_and_writes_a_pymodbus_17lf(peer):
    with Bus(peer.url, protocol="modbus", allow=True) as bus:
        found = list(bus.scan(range(1, 11)))
        assert [(r["id"], r["model"], r["status"]) for r in found] == [(3, 0x1711, "ok"), (7, 0x1711, "ok")]
        peer.set(3, 210, 4321)
        assert bus[3].present_position == 4321
        bus[3].goal_position = 5000
        assert peer.value(3, 205) == 5000
        bus.write(7, {"goal-speed": 300, "goal-current": 400})         # one Write Multiple Registers
        assert (peer.value(7, 208), peer.value(7, 209)) == (300, 400)
        bus.store(7, "speed-limit", 900)                                 # stored: allowed on this bus
        assert peer.value(7, 20) == 900
        with pytest.raises(ExceptionReply) as e:
            bus.link.read_values(3, 212, 1)                              # a gap in the control table
        assert e.value.exception == 2 and e.value.name == "illegal-data-address"
        with pytest.raises(NoReply):
            bus.read(4, "model-number")


def test_the_command_line_drives_the_pymodbus_17lf(peer, sh):
    import json

    r = sh("zap", "scan", "--protocol", "modbus", "--ids", "1-9", "-p", peer.url, "-f", "jsonl")
    assert r.exit_code == 0, r
    assert [json.loads(x)["id"] for x in r.stdout.splitlines()] == [3, 7]
    r = sh("zap", "store", "--protocol", "modbus", "goal-position", "777", "--id", "3", "-p", peer.url, "--verify")
    assert r.exit_code == 0, r
    assert peer.value(3, 205) == 777
    r = sh("zap", "store", "--protocol", "modbus", "speed-limit", "700", "--id", "3", "-p", peer.url)
    assert r.exit_code == 2 and "--yes" in r.stderr and peer.value(3, 20) == 1000    # consent on a real port
    peer.set(7, 211, 432)
    r = sh("zap", "load", "--protocol", "modbus", "present-current", "--id", "7", "-p", peer.url)
    assert r.exit_code == 0 and r.stdout == "432\n"
