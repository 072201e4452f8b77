"""Calls with wrong types: type checkers must refuse every line marked ``# refused`` (and
nothing else). Never run."""

from __future__ import annotations

from zkzap import Bus, Ecu, Reading
from zkzap.codec import zap, zk
from zkzap.sim import start_zap, start_zk


def wrong(url: str) -> None:
    bus = Bus(url, baud="57600")                       # refused: baud is an int
    bus.move("1", 3000)                                # refused: an ID is an int
    bus.move(1, 3000.5)                                # refused: a position is an int
    bus.move(1, 3000, wait="yes")                      # refused: wait is a bool
    bus[1].goal_positon = 2000                         # refused: no such register
    bus[1].present_position = 5                        # refused: read-only
    voltage: int = bus[1].present_voltage              # refused: a Reading, not an int
    position: str = bus.move(1, 2000)                  # refused: the final position is an int
    bus.store(1, "goal-speed", "800")                  # refused: a raw value is an int
    bus.sync_move([1, 2])                              # refused: a mapping of ID -> value
    Bus(url, return_mode="two")                        # refused: 0, 1, 2 or "auto"
    Bus(url, timeout="1")                              # refused: seconds are a float
    Ecu(url, baud=None)                                # refused: baud is an int
    Ecu(url, abort="later")                            # refused: standby, stop or none
    Ecu(url, stop_bits=3)                              # refused: 1 or 2
    ecu = Ecu(url)
    ecu.hold("control", "30")                          # refused: seconds are a float
    ecu.run_profile(42)                                # refused: a schedule, text, a path or rows
    frame: str = ecu.frame("keepalive")                # refused: a ControlFrame
    ecu.send("keepalive", listen="no")                 # refused: listen is a bool
    ecu.check([ecu.frame("keepalive")])                # refused: a Plan, not frames
    start_zap(ids="1,2", turnaround="2")               # refused: milliseconds are a float
    start_zap(transport="serial")                      # refused: inprocess, pty or tcp
    start_zk(speed="10")                               # refused: speed is a float
    start_zk(protocol_versoin=4)                       # refused: no such argument
    zk.ControlFrame.build("control").frame.upper(1)    # refused: bytes.upper takes no argument
    zap.Command(zap.echo(1)).expects_reply("1")        # refused: a return mode is an int
    reading: Reading = bus.load(1, "present-voltage")  # refused: Load Data gives raw ints
    for rec in bus.scan(range(4)):
        print(rec["idd"])                              # refused: a scan record has no key idd
        firmware: str = rec["firmware"]                # refused: an Optional[int]
    print(bus.identify(1)["modle"])                    # refused: no key modle
    print(bus[1].dump()[0]["registr"])                 # refused: no key registr
    print(bus.latencies[1]["latency"])                 # refused: latency_ms
    print(bus.move(1, 100).requsted)                   # refused: a Moved has requested
