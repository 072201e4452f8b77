"""zap/zk batch in-process: records, the shared port's settings, results; hints and exit-status help."""

from __future__ import annotations

import json

import pytest

from zkzap.commands.batch import parse_result
from zkzap.commands.hints import with_hint
from zkzap.errors import CheckFailed, NoReply, UsageError, exit_status_help


def records(text):
    return [json.loads(line) for line in text.splitlines()]


def test_a_scan_gives_the_port_back_at_the_batch_baud(cli):
    r = cli("zap", "batch", "-", "--sim", "--sim-ids", "1", input="scan --ids 1 --baud all\nload id --id 1\n")
    assert r.exit_code == 0, r.stderr
    recs = records(r.stdout)
    assert recs[0]["result"]["id"] == 1 and recs[1]["result"] == 1


def test_set_baud_keeps_the_new_rate_for_the_lines_after(cli):
    r = cli("zap", "batch", "-", "--sim", "--sim-ids", "1",
            input="set-baud 115200 --id 1\nload baud-rate --id 1\n")
    assert r.exit_code == 0, r.stderr
    assert records(r.stdout)[1]["result"] == 16


def test_the_batch_port_is_checked_once_not_on_every_line(cli, monkeypatch):
    # a port-name hint (macOS's /dev/tty.*, here for any port) is said once, by the batch
    from zkzap.link import adapters

    monkeypatch.setattr(adapters, "outgoing_port_hint", lambda device, platform=None: f"{device}: a hint")
    r = cli("zap", "batch", "-", "-p", "sim://zap?ids=1", input="load id --id 1\n" * 3)
    assert r.exit_code == 0, r.stderr
    assert r.stderr.count("a hint") == 1 and [rec["result"] for rec in records(r.stdout)] == [1, 1, 1]
    for line in (("load", "id"), ("store", "goal-position", "100")):            # and once by a command
        r = cli("zap", *line, "--id", "1", "-p", "sim://zap?ids=1")
        assert r.exit_code == 0 and r.stderr.count("a hint") == 1, r.stderr


def test_line_options_override_the_batch_defaults(cli):
    r = cli("zap", "batch", "-", "--sim", "--sim-ids", "1", "--return-mode", "2",
            input="store goal-speed 300 --id 1 -v\nload goal-speed --id 1 --return-mode 1\n")
    assert r.exit_code == 0, r.stderr
    assert "acknowledged" in r.stderr and records(r.stdout)[1]["result"] == 300


def test_empty_batch_and_comments(cli):
    r = cli("zap", "batch", "-", "--sim", input="# nothing\n\n")
    assert (r.exit_code, r.stdout) == (0, "")


def test_unreadable_file(cli, tmp_path):
    r = cli("zap", "batch", str(tmp_path / "missing.txt"), "--sim")
    assert r.exit_code == 2 and "cannot read" in r.stderr


@pytest.mark.parametrize("text,value", [("", None), ("2047\n", 2047), ("12.0\n", 12.0),
                                        ('{"a":1}\n{"a":2}\n', [{"a": 1}, {"a": 2}]),
                                        ('[\n{"a":1}\n]\n', [{"a": 1}]), ("model-number=1\nid=2\n",
                                                                         "model-number=1\nid=2")])
def test_results_are_parsed(text, value):
    assert parse_result(text) == value


def test_hints_come_from_facts():
    e = NoReply("no reply from ID 3", protocol="zap", ident=3, baud=57600, tries=3, mode_dependent=True)
    assert with_hint(e).endswith("power and wiring; or the actuator's feedback-return-mode does not answer this "
                                 "(try 'zap echo')")
    assert with_hint(CheckFailed("ID 2 is already taken", taken=True)).endswith("or pass --force")
    assert with_hint(CheckFailed("x", after_change="baud")) == "x; try 'zap scan --baud all'"
    assert with_hint(UsageError("no port", no_port="zap")).startswith("no port: give -p PORT")
    assert with_hint(NoReply("silent", protocol="zk")) == "silent"


def test_exit_status_help_from_the_table():
    assert exit_status_help().startswith("Exit status: 0 success; 1 check failed")
    text = exit_status_help({143: "SIGTERM", 0: "done", 130: "Ctrl-C"}, tail=" End.")
    assert text == "Exit status: 0 done; 130 Ctrl-C; 143 SIGTERM. End."
    with pytest.raises(ValueError, match="42"):
        exit_status_help({42: "the answer"})


def test_a_zk_batch_acknowledges_a_trip_and_a_start_is_refused_while_it_is_latched(cli):
    run = "send control --state run --throttle {} --for {} --ids 1 -f jsonl"
    text = "\n".join([run.format(40, 20) + " --limit 'egt_c<=500'",   # trips: latched
                      run.format(0, 0.5),                              # refused, with the reason
                      "alarms",
                      "ack 99",                                        # no such alarm: exit 2
                      "ack --by 'bench 2'",
                      "ack",                                           # nothing latched any more
                      run.format(0, 0.5)]) + "\n"                     # allowed: at rest and cool, setpoint 0
    r = cli("zk", "batch", "-", "-p", "sim://zk?speed=20", "--keep-going", input=text)
    recs = records(r.stdout)
    assert [x["exit"] for x in recs] == [5, 5, 0, 2, 0, 0, 0], r.stderr
    assert recs[1]["error"].startswith("start refused: alarm latched: limit egt_c<=500 violated: egt_c=")
    assert "acknowledge it first" in recs[1]["error"] and recs[1]["result"] is None   # nothing sent or recorded
    listed = recs[2]["result"]
    assert listed["alarms"][0]["latched"] and listed["start"].startswith("start refused: alarm latched")
    assert "no alarm 99 in the list" in recs[3]["error"]
    (acked,) = recs[4]["result"]
    assert acked["acked_by"] == "bench 2" and acked["acked_at"].endswith("Z") and "egt_c<=500" in acked["text"]
    assert recs[5]["result"] == [] and "stdin:6: note: ack: no alarm is latched" in r.stderr
    assert "stdin:5: note: bench 2 acknowledged 1 alarm: limit egt_c<=500 violated" in r.stderr
    assert r.exit_code == 5                                            # the first failure's


@pytest.mark.parametrize("line,said", [("ack x", "ack: 'x' is no alarm number"), ("ack --by", "ack: --by needs"),
                                       ("alarms 3", "alarms: takes no argument")])
def test_a_bad_stand_line_is_refused_before_anything_is_sent(cli, line, said):
    r = cli("zk", "batch", "-", "-p", "sim://zk", input=f"send keepalive\n{line}\n")
    assert r.exit_code == 2 and f"stdin:2: {said}" in r.stderr and r.stdout == "", r.stderr


def test_a_lines_large_output_is_streamed_into_its_record_not_kept(cli, monkeypatch):
    from zkzap.commands import batch

    monkeypatch.setattr(batch, "STREAM_AFTER", 4096)
    kept = []
    write = batch._LineOutput.write

    def spy(self, text):
        n = write(self, text)
        kept.append(self.tell())            # what the line's output holds in memory
        return n

    monkeypatch.setattr(batch._LineOutput, "write", spy)
    r = cli("zk", "batch", "-", "-p", "sim://zk?speed=50",
            input="monitor --count 600 -f jsonl\nsend keepalive\nfields -f csv\nmonitor --count 2 --ids 1\n")
    assert r.exit_code == 0, r.stderr
    recs = records(r.stdout)                                # every record is one whole JSON line
    assert [x["line"] for x in recs] == [1, 2, 3, 4] and [x["exit"] for x in recs] == [0, 0, 0, 0]
    assert len(recs[0]["result"]) == 600 and all(x["kind"] == "status" for x in recs[0]["result"])
    assert len(r.stdout.splitlines()[0]) > 20 * 4096        # streamed: far more than was ever kept
    assert max(kept) <= 4096 + 1000                         # at most the limit and one write
    assert recs[1]["result"] is None                        # a small output: as before
    csv = recs[2]["result"]                                 # streamed text: a line each, as a string
    assert csv[0].startswith("kind,id,frame,") and all(isinstance(x, str) for x in csv) and len(csv) > 20
    assert len(recs[3]["result"]) == 2


def test_a_lines_messages_are_said_as_they_come_and_only_its_last_error_is_kept():
    import io

    from zkzap.commands import batch

    class Records:
        flushed = 0
        failed = None

        def flush(self):
            self.flushed += 1

        class lane:
            @staticmethod
            def drain():
                return True

    records, stderr = Records(), io.StringIO()
    err = batch._LineMessages(records, stderr)
    err.start(batch.Line("run.txt:3", 3, "monitor", ["monitor"]))
    for i in range(1000):
        err.write(f"zk: note: {i}\n")
    assert stderr.getvalue().count("run.txt:3: zk: note:") == 1000 and records.flushed == 1
    assert err.getvalue() == ""                                  # nothing kept
    err.write("zk: error: first\nzk: error: sec")
    err.write("ond\n")
    err.write("zk: note: cut")
    assert err.finish() == "error: second" and stderr.getvalue().endswith("run.txt:3: zk: note: cut\n")
