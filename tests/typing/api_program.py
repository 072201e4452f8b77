"""A program that uses the whole documented API, as a user writes it: type checkers must accept
it under ``mypy --strict`` and pyright's strict mode, with the types pinned by ``assert_type``;
the tests also run it against the simulators."""

from __future__ import annotations

import sys
import warnings
from typing import TYPE_CHECKING, Any, Iterator, Optional, Union

import zkzap
from zkzap import (Actuator, BadReply, Bus, CaptureError, CheckFailed, ChecksumError, CrcError, DeviceError, Ecu,
                   EcuLimitError, ExpressionError, FieldValueError, FrameError, GoalClamped, HexError, Identity,
                   InvalidValue, Latency, LimitViolation, Moved, MoveRecord, NoReply, OutputError, PacketError,
                   PortError, ProfileResult, Reading, RegisterRow, ScanRecord, ScheduleError, Status, UsageError,
                   ZkzapError)
from zkzap.api.prestart import EcuLimits, Plan
from zkzap.codec import ZapFramer, ZkFramer, crc8_maxim, format_hex, parse_hex, zap, zap_checksum, zk
from zkzap.errors import close_names, did_you_mean, exit_code
from zkzap.link.zap_bus import Reply
from zkzap.sim import Simulator, start, start_zap, start_zk

if TYPE_CHECKING:
    from typing_extensions import assert_type
else:                                             # at run time it returns its argument
    def assert_type(value, _type):
        return value


def actuators() -> list[int]:
    with start_zap(ids=[1, 2], return_mode=1, turnaround=2.0) as sim, Bus(sim.url, baud=57600) as bus:
        assert_type(sim, Simulator)
        assert_type(bus, Bus)
        url: str = sim.url
        assert url.startswith("sim://") and bus.url == url and bus.baud == 57600 and bus.return_mode == 1

        act = bus[1]
        assert_type(act, Actuator)
        act.goal_speed = 800                          # Store Data, by register name
        assert_type(bus[2].goal_speed, int)
        voltage = act.present_voltage                 # a Reading: a float with its unit
        assert_type(voltage, Reading)
        assert voltage == 12.0 and voltage.unit == "V" and voltage.raw == 120
        current_limit: Reading = act.current_limit
        act.current_limit = current_limit             # a Reading writes back its raw value
        assert_type(bus.load(1, 0x88), int)
        block = bus.load(1, "present-position", 4)
        assert_type(block, Union[int, dict[str, int]])
        assert isinstance(block, dict) and "present-current" in block
        value = bus.read(1, "present-voltage")
        assert_type(value, Union[Reading, int])
        assert act["goal-speed"] == 800 and act.load("goal_speed") == 800 and act.read(0x88) == 800

        reply = bus.echo(1)
        assert_type(reply, Reply)
        assert reply.errors == [] and reply.rtt >= 0
        assert bus.ping(9) is None
        ack: Optional[Reply] = bus.store(1, "goal-speed", 600)
        assert ack is None                            # return mode 1: writes are unconfirmed
        bus.send(2, "goal-position", 1500)
        bus.execute()

        final = bus.move(1, 3000)                     # waits until it stops; the position
        assert_type(final, Moved)
        assert abs(final - 3000) <= 5 and not final.clamped and final.goal == final.requested == 3000
        position: int = final                         # a Moved is the int it always was
        assert position == final.position
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always", GoalClamped)
            clamped = bus.move(1, 4000)               # the actuator holds 3686: said, and warned
        assert clamped.clamped and clamped.goal == 3686 and isinstance(said[0].message, GoalClamped)
        record: MoveRecord = clamped.as_dict()
        assert record["requested"] == 4000 and record["clamped"]
        assert_type(bus.move(2, 1000, wait=False), None)
        assert_type(act.move(2000, speed=900), Moved)
        bus.sync_move({1: 1000, 2: 1000})
        scanned = list(bus.scan(range(0, 4)))
        assert_type(scanned, list[ScanRecord])
        found = [rec["id"] for rec in scanned]
        model: Optional[int] = scanned[0]["model"]
        assert model == 0xA112 and scanned[0]["status"] == "ok" and scanned[0]["baud"] == 57600
        info = bus.identify(1)
        assert_type(info, Identity)
        assert info["status"] == "ok" and info["return_mode"] == 1
        rows = bus[2].dump()
        assert_type(rows, list[RegisterRow])
        registers = {rec["register"]: rec["value"] for rec in rows}
        assert registers["id"] == 2 and all(rec["memory"] in ("NV", "V", "") for rec in rows)
        learned = bus.latencies
        assert_type(learned, dict[int, Latency])
        assert all(v["samples"] >= 1 and v["latency_ms"] >= 0 for v in learned.values())
        assert bus.set_id(2, 7) == 7
        assert bus.detect_return_mode(7) == 1
        try:
            bus.echo(9)
        except NoReply as e:
            assert (e.ident, e.code) == (9, 3)
        return found


def engine() -> ProfileResult:
    with start_zk(speed=10, protocol_version=6) as sim, Ecu(sim.url, baud=115200, abort="standby") as ecu:
        assert_type(ecu, Ecu)
        first = next(ecu.status())
        assert_type(first, Status)
        assert first.kind == "status" and first["id"] >= 1
        records: Iterator[Status] = ecu.hold("control", 0.5, rate=20, state="run", throttle_pct=30)
        for rec in records:
            if rec.id == 1:
                state: str = rec.engine_state_name
                assert state
        cf = ecu.frame("control", state="standby", throttle_pct=0)
        assert_type(cf, zk.ControlFrame)
        assert ecu.send(cf) == cf
        assert ecu.protocol_version == 6 and ecu.health["crc_errors"] == 0
        assert isinstance(ecu.stale_ids(), list) and "rpm" in ecu.snapshot
        for _ in ecu.keepalive(0.1):
            pass
        sent: list[bytes] = ecu.abort()
        assert sent
        result = ecu.run_profile([(0, 20, "run"), (1, 40), (2, 0, "standby")])
        assert_type(result, ProfileResult)
        assert result.ok and result.summary["frames"] > 0 and result.outcome.exit_code == 0
        return result


def limits() -> None:
    """The pre-start check: a target above the max rpm the ECU reports is refused, nothing sent."""
    with start_zk(speed=10, max_rpm=120000) as sim, Ecu(sim.url, stop_bits=1) as ecu:
        target = ecu.frame("rpm", target_rpm=150000, rpm_factor=4)
        assert_type(target.since, int)
        assert target.rpm_value == 3750 and target.leaves(4) == "holding a target of 150,000 rpm (RPM mode)"
        plan = Plan([target], rpm_factor=4, what="rpm")
        assert plan.needs_ecu
        try:
            ecu.check(plan)
        except EcuLimitError as e:                    # a usage error: exit status 2
            assert e.code == 2 and e.max_rpm == 120000
        known: Optional[EcuLimits] = ecu.limits
        assert known is not None and known.max_rpm == 120000 and known.version == 6
        try:
            ecu.send("rpm", target_rpm=150000, rpm_factor=4)
        except UsageError:
            pass
        assert ecu.sent == 0


def codec() -> None:
    cf = zk.ControlFrame.build("control", sw="run", throttle_pct=50)
    assert_type(cf, zk.ControlFrame)
    assert cf.frame.hex(" ").upper() == "FF 1D F4 70"
    assert cf.hazard == "state run can start the engine" and cf.controls_engine and cf.hazardous
    record: dict[str, Any] = cf.decode()
    assert record["throttle_pct"] == 50.0
    frame, notes = zk.encode_control("control", sw="run", throttle_pct=50.04)
    assert frame == cf.frame and notes
    status = zk.encode_status(1, egt_c=26)
    assert zk.check_frame(status) == "status" and zk.decode_status(status)["egt_c"] == 26
    decoder = zk.ZkDecoder(protocol_version=6)
    assert decoder.decode(cf.frame)["state"] == "run"

    cmd = zap.Command(zap.store(1, "long-stroke-limit", 3000))
    assert cmd.stored_writes == ["long-stroke-limit"] and not cmd.expects_reply(1)
    assert zap.Command(zap.symmetric_store("goal-position", {1: 10, 2: 20})[0]).target_ids() == [1, 2]
    reg: zap.Register = zap.register("goal_position")
    assert reg.address == 0x86 and zap.check_id("broadcast") == zap.BROADCAST
    packet = zap.packet(0, 0x00, b"\xff\x07")
    assert zap.decode_packet(packet)["kind"] == "feedback"

    assert crc8_maxim(b"123456789") == 0xA1 and zap_checksum(b"\x00\x02\xf1") == 0x0C
    assert format_hex(parse_hex("ff 1d f4 70")) == "FF 1D F4 70"
    zk_frames = ZkFramer(accept="status").feed(status + cf.frame)
    zap_frames = ZapFramer().feed(packet)
    assert_type(zk_frames, list[bytes])
    assert zk_frames == [status] and zap_frames == [packet]


def errors() -> None:
    caught: list[type[ZkzapError]] = []
    for bad in (lambda: zap.register("goal-sped"), lambda: parse_hex("zz"),
                lambda: zk.check_frame(b"\xff\x14\x64\xd4"), lambda: zap.check_packet(b"\xff\xff\xff\x00\x02\xf1\x00")):
        try:
            bad()
        except ZkzapError as e:
            caught.append(type(e))
            assert e.code in (1, 2) and exit_code(e) == e.code
    assert caught == [FieldValueError, HexError, CrcError, ChecksumError]
    try:
        zap.register("speed-limt")
    except InvalidValue as e:                         # also a ValueError
        assert e.suggestions == ["speed-limit"] and isinstance(e, ValueError)
    assert close_names("goal-sped", ["goal-speed", "goal-position"]) == ["goal-speed"]
    assert did_you_mean("stnadby", ["stop", "standby"]) == "; did you mean standby?"
    for cls in (UsageError, CheckFailed, PortError, DeviceError, BadReply, OutputError, FrameError, PacketError,
                ExpressionError, LimitViolation, ScheduleError, EcuLimitError, CaptureError):
        assert issubclass(cls, ZkzapError)


def simulators() -> None:
    with start("zap", ids=[3]) as sim:
        assert sim.kind == "zap"
    with start_zap(ids=[1, (2, 115200)], faults=["2:silent", (1, "delay", 5.0, None)], transport="inprocess"):
        pass


def main() -> int:
    assert zkzap.__version__
    assert actuators() == [1, 2]
    assert engine().records > 0
    limits()
    codec()
    errors()
    simulators()
    return 0


if __name__ == "__main__":
    sys.exit(main())
