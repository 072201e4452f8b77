"""The library's bus detection (zkzap.api.detect.detect_bus, what 'zap detect' renders): the
protocol and baud rate the actuators speak, stopping at the first that answers unless asked for
every one; a silent bus is the named NoReply with the rates tried. On the simulated buses'
virtual clock (a whole scan of both protocols' IDs at each rate takes no real time)."""

from __future__ import annotations

import pytest

from zkzap.api.detect import detect_bus
from zkzap.errors import NoReply
from zkzap.sim import start_zap


def test_a_17lf_is_found_at_its_rate_and_protocol_after_the_others_stay_silent():
    with start_zap(ids=[4, 6], protocol="modbus", baud=19200, virtual=True) as sim:
        assert list(detect_bus(sim.url, bauds=[57600, 19200, 9600])) == [
            {"protocol": "modbus", "baud": 19200, "ids": [4, 6], "found": 2}]


def test_the_first_answer_ends_it_unless_every_combination_is_asked_for():
    tried = []

    with start_zap(ids=[2], baud=57600, virtual=True) as sim:
        from zkzap.link.zap_bus import open_bus

        def opener(baud, protocol):
            tried.append((baud, protocol))
            return open_bus(sim.url, baud, protocol=protocol)

        assert list(detect_bus(bauds=[57600, 9600], opener=opener)) == [
            {"protocol": "ir", "baud": 57600, "ids": [2], "found": 1}]
        assert tried == [(57600, "ir")]
        tried.clear()
        assert list(detect_bus(bauds=[57600, 9600], every=True, opener=opener)) == [
            {"protocol": "ir", "baud": 57600, "ids": [2], "found": 1}]
        assert tried == [(57600, "ir"), (57600, "modbus"), (9600, "ir"), (9600, "modbus")]


def test_a_silent_bus_is_no_reply_naming_the_rates_tried():
    with start_zap(ids=[1], baud=9600, virtual=True) as sim:
        with pytest.raises(NoReply, match=r"nothing answered on the IR protocol or Modbus RTU at 115200 baud"):
            list(detect_bus(sim.url, bauds=[115200]))
