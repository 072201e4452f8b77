"""A shared bus lent to one command: its settings are the command's while it runs, and the
batch's again when it gives the bus back."""

from __future__ import annotations

from zkzap.link.shared import SETTINGS, Borrowed, shared, sharing


class FakeBus:
    """The settings of a ZapBus, a baud rate, and a record of every setting written."""

    def __init__(self):
        object.__setattr__(self, "written", [])
        object.__setattr__(self, "_baud", 57600)
        self.return_mode, self.retries, self.timeout, self.latency, self.allow = 1, 2, None, None, 0
        self.written.clear()

    def __setattr__(self, name, value):
        self.written.append(name)
        object.__setattr__(self, name, value)

    @property
    def baud(self):
        return self._baud

    def set_baud(self, baud):
        self.written.append("baud")
        object.__setattr__(self, "_baud", baud)


def settings(bus):
    return {k: getattr(bus, k) for k in SETTINGS}


def test_a_line_with_the_batchs_settings_writes_none_and_puts_none_back():
    bus = FakeBus()
    with Borrowed(bus, return_mode=1, retries=2, timeout=None, latency=None, allow=0) as b:
        assert b is bus
    assert bus.written == []


def test_a_lines_own_settings_hold_while_it_runs_and_the_batchs_come_back():
    bus = FakeBus()
    before = settings(bus)
    with Borrowed(bus, return_mode=2, retries=0, timeout=0.5, latency=0.04, allow=3):
        assert settings(bus) == {"return_mode": 2, "retries": 0, "timeout": 0.5, "latency": 0.04, "allow": 3}
    assert settings(bus) == before


def test_what_the_command_changes_itself_is_put_back_and_nothing_else():
    bus = FakeBus()
    with Borrowed(bus, return_mode=1, retries=2, timeout=None, latency=None, allow=0):
        bus.return_mode = 0                  # it asked the actuator (detect_return_mode)
        bus.set_baud(115200)                 # a scan at another rate
        bus.written.clear()
    assert bus.return_mode == 1 and bus.baud == 57600
    assert bus.written == ["return_mode", "baud"]


def test_a_set_baud_line_keeps_the_rate_it_set():
    bus = FakeBus()
    Borrowed.keep_baud = True
    try:
        with Borrowed(bus, return_mode=1):
            bus.set_baud(115200)
    finally:
        Borrowed.keep_baud = False
    assert bus.baud == 115200


def test_sharing_lends_the_link_for_the_block_only():
    bus = FakeBus()
    assert shared("zap") is None
    with sharing("zap", bus):
        assert shared("zap") is bus
    assert shared("zap") is None
