"""ZK frame sources: a raw log replays as the live session received it (fast or in real time),
to its end, with a frame held for look-ahead at the end of the log."""

import pytest

from zkzap.api.session import Session
from zkzap.api.telemetry import Telemetry
from zkzap.errors import UsageError
from zkzap.link.zk_port import ZkLink
from zkzap.link.zk_sources import LiveSource, ReplaySource


def test_raw_log_and_replay_give_the_same_records(tmp_path):
    raw = tmp_path / "run.bin"
    with open(raw, "wb") as f:
        link = ZkLink.open("sim://zk?speed=20&corrupt_every=7", 115200)
        src = LiveSource(link)
        live = []
        s = Session(src, Telemetry(wall0=src.wall0), live.append, count=60)
        link.raw_log = f
        s.run()
        link.close()
    assert raw.stat().st_size >= 60 * 7

    def replay(fast):
        src = ReplaySource(str(raw), fast=fast)
        t = Telemetry(wall0=src.wall0)
        out = []
        outcome = Session(src, t, out.append, count=60).run()
        src.close()
        return outcome, out, src

    strip = ("time", "t", "stale", "stale_ids")
    outcome, fast, src = replay(True)
    assert outcome.reason == "count"
    assert [{k: v for k, v in r.items() if k not in strip} for r in fast] == \
        [{k: v for k, v in r.items() if k not in strip} for r in live]
    assert [r["t"] for r in fast[:3]] == [0.0, 0.05, 0.1]                # rebuilt from the 20 Hz rate
    assert src.framer.bad > 0                                          # the corrupted frames were kept
    outcome, _, _ = replay(True)
    src = ReplaySource(str(raw))
    t = Telemetry(wall0=src.wall0)
    out = []
    Session(src, t, out.append, count=8).run()                         # real time: 8 frames at 20 Hz
    assert 0.3 <= src.now() <= 1.0
    src.close()


def test_replay_to_the_end_and_missing_file(tmp_path):
    raw = tmp_path / "short.bin"
    from zkzap.sim.zk_ecu import ZkEcu

    ecu = ZkEcu()
    raw.write_bytes(ecu.poll(0.99) + b"\x00\xF1\x02")                   # 20 frames and a torn one
    src = ReplaySource(str(raw), fast=True)
    out = []
    outcome = Session(src, Telemetry(), out.append).run()
    assert outcome.reason == "end" and len(out) == 20
    with pytest.raises(UsageError, match="replay: cannot read"):
        ReplaySource(str(tmp_path / "none.bin"))


def test_replay_keeps_a_frame_held_for_look_ahead_at_the_end(tmp_path):
    """After damage, a framer holds a valid frame until what follows confirms it; at the end of
    a replay that frame comes out of flush() and must not be lost."""
    from zkzap.codec import zk as zkc
    from zkzap.codec.framing import ZkFramer

    good = zkc.status_frame(1, b"\x00\x00\x00\x00\x4c")
    data = good + bytes.fromhex("4cf2f24c4c") + good    # damage with rival heads before the last frame
    framer = ZkFramer("status")
    assert framer.feed(data) == [good]         # the last frame waits for confirmation ...
    assert framer.flush() == [good]            # ... and comes out at the end
    expected = [good, good]
    log = tmp_path / "raw.bin"
    log.write_bytes(data)
    src = ReplaySource(str(log), fast=True)
    got = []
    while True:
        due = src.poll()
        if due is None:
            break
        got += [f for _, f in due]
    assert got == expected
