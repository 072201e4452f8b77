"""The ZK console records through its stand session's one sink: every status record the
console's sessions receive (monitoring and control, one after the other) is in the -o file
exactly once, as many as the frames decoded, beside the trip records the sessions mark; the
pages see the same records. In-process (no page, no server): the console's worker on the
simulator, the file written by the command line's own writer."""

from __future__ import annotations

import collections
import json

import pytest

from zkzap.api.stand import StandSession
from zkzap.api.zk import Ecu
from zkzap.errors import UsageError

from webpage import until

pytest.importorskip("aiohttp")


def test_every_record_is_written_once_through_the_sessions_one_sink(tmp_path):
    from zkzap.commands.zk.monitor import session_output
    from zkzap.web.zk_console import ZkConsole

    out = tmp_path / "run.jsonl"
    record = session_output(None, str(out), False, None, None, "test", None, controls=True, view=False)
    record.path = str(out)
    session = StandSession(None)
    session.record(record, f"--output {out}", wait=False)
    with pytest.raises(UsageError, match="one output"):     # one sink: a second output is refused
        session.record(record, "again")
    console = ZkConsole(Ecu("sim://zk?speed=20", silence=2.0), session=session)
    console.start(None)
    try:
        until(lambda: console.tel.frames >= 20, "status frames")
        console.request(None, "test", {"op": "start", "mode": "throttle", "throttle": 0, "req": 1})
        until(lambda: console.command is not None, "the control session")
        until(lambda: console.tel.frames >= 60, "frames under control")
        console.request(None, "test", {"op": "abort", "req": 2})
        until(lambda: console.command is None and console.ended is not None, "the abort's end")
        until(lambda: console.tel.frames >= 100, "frames after the abort")
    finally:
        console.close()
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    status = [r for r in recs if r.get("kind") == "status"]
    events = [r for r in recs if r.get("kind") != "status"]
    # each frame decoded is one record in the file, none twice
    assert len(status) == console.tel.frames
    dup = [k for k, n in collections.Counter((r["t"], r["id"], r["frame"]) for r in status).items() if n > 1]
    assert dup == []
    assert [r["t"] for r in status] == sorted(r["t"] for r in status)
    # the pages got the same records (their plots' history)
    assert len(console.history) == len(status)
    # the abort is marked once, through the same sink
    assert [r["kind"] for r in events] == ["trip"]
    assert "abort from test" in events[0]["trip"]
