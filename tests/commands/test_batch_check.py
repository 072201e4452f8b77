"""A batch is checked whole before anything is sent: every line's command runs every check it
makes at run time (zkzap.checking), not a dry run of it. A bad line anywhere: exit 2 naming
FILE:LINE, nothing sent (a recording port sees no connection, a --capture no file), no file
created or changed. Options that only mean something at run time work in a batch."""

from __future__ import annotations

import json

import pytest

from cmdtree import RecordingPort


@pytest.fixture
def port():
    p = RecordingPort()
    yield p
    p.close()


BAD_SECOND_LINES = [
    # (protocol, the first line: it would send; the second: refused only at run time before)
    ("zk", "send control --state run --throttle 60", "monitor --count 2 --ids 99", "ids: 99 is out of range"),
    ("zk", "send control --state run --throttle 60", "monitor --count 2 --limit rpm<=nan", "'nan' is not a finite"),
    ("zk", "send keepalive", "monitor --count 2 --limits /nonexistent/engine.limits", "limits: cannot read"),
    ("zk", "send keepalive", "monitor --count 2 -o /nonexistent/dir/run.csv", "no such directory"),
    ("zk", "send keepalive", "send control --state stop --for 1 --summary-json /nonexistent/s.json",
     "summary-json: cannot open"),
    ("zk", "send keepalive", "profile /nonexistent/stand.csv", "cannot read"),
    ("zap", "store long-stroke-limit 3000 --id 1", "watch present-position --ids 1 --count 1 --until bogus==1",
     "unknown field 'bogus'"),
    ("zap", "store long-stroke-limit 3000 --id 1", "apply /nonexistent/fleet.json", "cannot read"),
    ("zap", "store long-stroke-limit 3000 --id 1", "diff /nonexistent/fleet.json bus", "cannot read"),
    ("zap", "store long-stroke-limit 3000 --id 1", "store id 5 --id 1", "needs permission IDENTITY"),
    ("zap", "store long-stroke-limit 3000 --id 1", "store alarm-led 30 --id 1", "alarm-led: 30 is not allowed"),
    ("zap", "store goal-position 100 --id 1", "backup --ids 1 -o /nonexistent/dir/fleet.json", "no such directory"),
]


@pytest.mark.parametrize("proto,first,second,needle", BAD_SECOND_LINES, ids=[s for _, _, s, _ in BAD_SECOND_LINES])
def test_a_bad_line_anywhere_means_nothing_is_sent(cli, port, tmp_path, proto, first, second, needle):
    r = cli(proto, "batch", "-p", port.url, "--yes", input=f"{first}\n{second}\n")
    assert r.exit_code == 2 and r.stdout == "", r
    assert "stdin:2:" in r.stderr and needle in r.stderr, r
    assert port.seen() == (0, b"")


def test_a_refused_batch_writes_no_capture_and_creates_no_file(cli, tmp_path):
    cap, book = tmp_path / "run.pcapng", tmp_path / "k100.db"
    text = f"send control --state stop --for 0.2 --logbook {book}\nmonitor --count 1 --ids 99\n"
    r = cli("zk", "batch", "-p", "sim://zk?speed=20", "--capture", str(cap), input=text)
    assert r.exit_code == 2 and not cap.exists() and not book.exists(), r


def test_a_line_may_read_what_an_earlier_line_writes(cli, tmp_path):
    fleet = tmp_path / "fleet.json"
    text = f"backup --ids 1,2 -o {fleet}\napply {fleet} --plan\napply {tmp_path / 'other.json'}\n"
    r = cli("zap", "batch", "--sim", "--sim-ids", "1,2", input=text)
    assert r.exit_code == 2 and "stdin:3: apply" in r.stderr and not fleet.exists(), r   # checked whole
    r = cli("zap", "batch", "--sim", "--sim-ids", "1,2", input="\n".join(text.splitlines()[:2]) + "\n")
    assert r.exit_code == 0, r
    assert [json.loads(line)["exit"] for line in r.stdout.splitlines()] == [0, 0]


def test_run_time_options_work_in_a_batch(cli, tmp_path):
    summary, book = tmp_path / "s.json", tmp_path / "k100.db"
    line = (f"send control --state run --throttle 20 --for 1 --limit egt_c<=900 --on-limit abort "
            f"--summary-json {summary} --logbook {book}")
    r = cli("zk", "batch", "-p", "sim://zk?speed=20", input=line + "\n")
    assert r.exit_code == 0, r
    rec = json.loads(r.stdout.splitlines()[0])
    assert rec["exit"] == 0
    limits = json.loads(summary.read_text())["limits"]
    assert len(limits) == 1 and limits[0]["verdict"] in ("ok", "unchecked")     # tested as a limit
    assert "logbook" in r.stderr and book.stat().st_size > 0


def test_the_check_records_what_each_line_needs_consent_for(cli):
    from zkzap.sim import start_zap

    text = "store goal-position 100 --id 1\nstore short-stroke-limit 50 --id 1\nraw system-write 01 --id 1\n"
    with start_zap(ids=[1], transport="pty") as sim:              # a device path: consent is asked
        r = cli("zap", "batch", "-p", sim.url, input=text)
    assert r.exit_code == 2 and r.stdout == ""
    assert "stdin:2 store short-stroke-limit 50 --id 1 (short-stroke-limit)" in r.stderr
    assert "stdin:3 raw system-write 01 --id 1" in r.stderr and "stdin:1" not in r.stderr


@pytest.mark.parametrize("text,code", [
    ("load present-position --id 1\nexit\n", 0),
    ("load present-position --id 9 --retries 0\nload present-position --id 1\nexit\n", 3),  # the last failure
    ("load present-position --id 9 --retries 0\nexit 0\n", 0),                            # exit N: N
    ("exit 4\nload present-position --id 9\n", 4),
    ("exit four\n", 2),
    ("load present-position --id 1\n", 0),
])
def test_the_shell_exits_with_what_was_asked(cli, text, code):
    r = cli("shell", "zap", "--sim", "--sim-ids", "1", input=text)
    assert r.exit_code == code, r
