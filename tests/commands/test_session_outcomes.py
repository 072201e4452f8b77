"""How ZK sessions end, as the command line says it: every end of an engine session is a stated
state, the ECU's reported limits refuse a plan before its first frame, noise is no ECU, a
summary row counts only what it checked, and a silent ECU never passes however short the run."""

from __future__ import annotations

import json
import os
import random
import threading
import tty

import pytest

SIM = "sim://zk?speed=20"


def _sent(cli, capture):
    """The control frames a command sent (its --capture, decoded)."""
    r = cli("zk", "decode", str(capture), "-f", "jsonl")
    return [rec for rec in map(json.loads, r.stdout.splitlines()) if rec["kind"] == "control"]


# --- a stated state at every end -------------------------------------------------------------------

def test_a_one_shot_run_says_the_engine_is_left_running(cli):
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "100", "--yes", "-p", SIM)
    assert r.exit_code == 0, r
    assert "the engine is left running at 100 % throttle (state run): a one-shot command sends no abort" in r.stderr
    r = cli("zk", "send", "control", "--state", "standby", "-p", SIM)
    assert r.exit_code == 0 and "left" not in r.stderr                 # a safe state needs no word


@pytest.mark.parametrize("args,said", [
    ([], "limit violated: sent standby, throttle 0"),
    (["--abort", "none"], "limit violated: --abort none: nothing sent; the engine is left running at 30 % throttle"),
], ids=["abort", "abort-none"])
def test_on_limit_exit_ends_an_engine_session_with_the_abort(cli, tmp_path, args, said):
    capture = tmp_path / "wire.pcapng"
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "60", "-p", SIM, "-f", "jsonl",
            "--limit", "rpm<=30000", "--on-limit", "exit", "--capture", str(capture), *args)
    assert r.exit_code == 5 and said in r.stderr, r
    last = _sent(cli, capture)[-1]
    assert last["state"] == ("standby" if not args else "run")


# --- the ECU's limits, before the first frame --------------------------------------------------------

REFUSED = [
    # (command, simulator options, what the refusal names)
    (["send", "rpm", "150000", "--rpm-factor", "4"], "max_rpm=120000", "rpm: target 150000 rpm is above"),
    (["send", "rpm", "150000", "--rpm-factor", "4", "--for", "5"], "max_rpm=120000", "target 150000 rpm is above"),
    (["send", "mode", "--state", "run", "--rpm-factor", "3", "--for", "5"], "protocol_version=3",
     "mode needs protocol version 4 or later; the ECU reports 3"),
    (["send", "action", "pump-on"], "protocol_version=4", "pump-on needs protocol version 5"),
    (["profile", "{rpm}"], "max_rpm=120000", "rpm.csv:3: target 150000 rpm is above the ECU's max rpm 120000"),
]


@pytest.mark.parametrize("args,options,needle", REFUSED, ids=[" ".join(a[:2]) + (" --for" if "--for" in a else "")
                                                               for a, _, _ in REFUSED])
def test_a_plan_the_ecu_cannot_follow_is_refused_before_the_start(cli, tmp_path, args, options, needle):
    rpm = tmp_path / "rpm.csv"
    rpm.write_text("0,0,run\n20,rpm=90000\n35,rpm=150000\n50,0,standby\n")
    out, summary, capture = tmp_path / "log.csv", tmp_path / "summary.json", tmp_path / "wire.pcapng"
    out.write_text("old\n")
    summary.write_text("{}\n")
    extra = ["-o", str(out), "--summary-json", str(summary)] if "--for" in args or args[0] == "profile" else []
    r = cli("zk", *[a.replace("{rpm}", str(rpm)) for a in args], "-p", f"{SIM}&{options}", "--capture",
            str(capture), *extra)
    assert r.exit_code == 2 and needle in r.stderr and "nothing sent" in r.stderr, r
    assert r.stdout == "" and _sent(cli, capture) == []                 # not even the start frame
    assert out.read_text() == "old\n" and summary.read_text() == "{}\n"


def test_no_wait_reads_nothing_so_an_rpm_target_is_refused(cli):
    r = cli("zk", "send", "rpm", "90000", "--rpm-factor", "3", "--no-wait", "-p", SIM)
    assert r.exit_code == 2 and "its status frames were not read" in r.stderr


# --- noise is no ECU ------------------------------------------------------------------------------

@pytest.fixture
def noise_port():
    """A pty carrying seeded random bytes at about 115200 baud, until the test ends."""
    master, slave = os.openpty()
    tty.setraw(slave)
    stop = threading.Event()

    def talk():
        rng = random.Random(11)
        while not stop.wait(0.01):
            try:
                os.write(master, rng.randbytes(115))
            except OSError:
                return

    t = threading.Thread(target=talk, daemon=True)
    t.start()
    yield os.ttyname(slave)
    stop.set()
    t.join(2)
    os.close(master)
    os.close(slave)


def test_a_line_of_random_bytes_is_no_ecu(cli, noise_port, tmp_path):
    out = tmp_path / "log.jsonl"
    r = cli("zk", "monitor", "-p", noise_port, "--timeout", "1", "-o", str(out))
    assert r.exit_code == 3, r
    assert "bytes came, but not as a stream of status frames" in r.stderr
    assert "'zk detect -p PORT' finds the ECU's baud rate" in r.stderr and not out.exists()


def test_a_sniff_at_the_wrong_baud_rate_ends_as_noise(cli):
    r = cli("sniff", "zk", "-p", "sim://zk?baud=9600&speed=10", "-f", "jsonl")
    assert r.exit_code == 3 and "but not as ZK frames at 115200 baud" in r.stderr, r
    assert r.stdout == ""


# --- summaries count what they checked ----------------------------------------------------------------

def test_check_counts_the_frames_that_carried_each_field(cli):
    r = cli("zk", "check", "-p", SIM, "--count", "50", "--limit", "egt_c<=900", "--limit", "rpm>=0", "-f", "json")
    assert r.exit_code == 0, r
    doc = json.loads(r.stdout)
    rows = {row["check"]: row for row in doc["checks"]}
    ids1 = rows["egt_c<=900"]["checked"]                       # egt_c is in status ID 1 only
    assert doc["frames"] == 50 and rows["rpm>=0"]["checked"] == 50
    assert rows["ECU error code"]["checked"] == ids1 == 5     # one frame in ten, not 50


def test_check_never_passes_with_no_frame(cli):
    r = cli("zk", "check", "-p", "sim://zk?silent_after=0&speed=10", "--duration", "1", "-f", "json")
    assert r.exit_code == 3 and r.stdout == "" and "in the 1.0 s the session ran" in r.stderr, r


# --- one clock -----------------------------------------------------------------------------------

def test_the_logbook_dates_a_fast_run_by_the_real_clock(cli, tmp_path):
    import calendar
    import time

    book = tmp_path / "engine.db"
    r = cli("zk", "send", "control", "--state", "run", "--throttle", "30", "--for", "20", "-p", "sim://zk?speed=10",
            "-f", "jsonl", "--logbook", str(book))
    done = time.time()
    assert r.exit_code == 0, r
    run = json.loads(cli("zk", "logbook", str(book), "-f", "json").stdout)["runs"][0]
    started, ended = (calendar.timegm(time.strptime(run[k], "%Y-%m-%dT%H:%M:%SZ")) for k in ("started", "ended"))
    assert run["duration_s"] >= 20                           # session (model) seconds...
    assert ended - started <= 2 + run["duration_s"] / 10     # ...that took a tenth of it in real time
    assert ended <= done + 1                                 # never in the future
