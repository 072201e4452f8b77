"""SIGKILL (a power cut, the OOM killer, kill -9): no handler runs, nothing is finished or
closed, and still every output format keeps what was written before the last second, readable
(a workbook, assembled only at the end, in the CSV journal beside it; an MDF file unfinalized).

Each case is a real ``zk monitor`` logging the in-process simulator to ``-o`` in one format,
with ``--raw-log`` and ``--capture`` beside it, killed once its capture spans a few seconds.
The capture and the raw log are written as each read returns, so they are what the process had
received when it died: every other output must hold its records up to a second before the
capture's last frame (the same process's clock, so a loaded machine delays both alike).
"""

from __future__ import annotations

import csv
import io
import json
import signal
import subprocess
import time

import pytest

from zkzap.link.pcapng import INBOUND, Reader

from .conftest import clean_env, executable

#: What a killed run may lose at most: the records of its last second.
LOSS_S = 1.0
#: How long the capture spans when the process is killed (seconds).
RUN_S = 3.0


def _iso_s(text):
    import calendar

    head, _, frac = text.rstrip("Z").partition(".")
    return calendar.timegm(time.strptime(head, "%Y-%m-%dT%H:%M:%S")) + float("0." + (frac or "0"))


def _csv(path):
    text = path.read_text()
    assert text.endswith("\n"), "the file ends inside a record"
    rows = list(csv.DictReader(io.StringIO(text)))
    assert rows and all(None not in r for r in rows)
    return [_iso_s(r["time"]) for r in rows]


def _jsonl(path):
    text = path.read_text()
    assert text.endswith("\n")
    return [_iso_s(json.loads(line)["time"]) for line in text.splitlines()]


def _json(path):
    text = path.read_text()
    assert text.startswith("[\n") and not text.rstrip().endswith("]")      # killed: the array is open
    return [_iso_s(r["time"]) for r in json.loads(text + "\n]")]           # ... and a valid prefix


def _influx(path):
    lpp = pytest.importorskip("line_protocol_parser")
    text = path.read_text()
    assert text.endswith("\n")
    return [lpp.parse_line(line + "\n")["time"] / 1e9 for line in text.splitlines()]


def _mcap(path):
    pytest.importorskip("mcap")
    from mcap.exceptions import EndOfFile
    from mcap.reader import NonSeekingReader

    times = []
    with open(path, "rb") as f:
        try:     # as the README says to read a file a killed run left without its footer
            for _schema, _channel, message in NonSeekingReader(f).iter_messages(log_time_order=False):
                times.append(message.log_time / 1e9)
                json.loads(message.data)
        except EndOfFile:
            pass
    return times


def _xlsx(path):
    """A killed run writes no workbook: its rows are in the journal beside it, as CSV."""
    pytest.importorskip("openpyxl")
    assert not path.exists()
    return _csv(path.with_name(path.name + ".partial.csv"))


def _mf4(path):
    """A killed run's MDF file is the unfinalized one beside the name, read (finalized) by asammdf."""
    asammdf = pytest.importorskip("asammdf")
    assert not path.exists()
    (left,) = path.parent.glob(path.name + ".tmp*")
    assert left.read_bytes()[:8] == b"UnFinMF "
    with asammdf.MDF(str(left)) as mdf:
        start = mdf.header.start_time.timestamp()
        t = mdf.get("rpm").timestamps
        assert len(mdf.get("egt_c").samples) == len(t) and list(t) == sorted(t)
        return [start + float(x) for x in t]


FORMATS = {"csv": _csv, "jsonl": _jsonl, "json": _json, "lp": _influx, "mcap": _mcap, "xlsx": _xlsx, "mf4": _mf4}


@pytest.fixture(scope="module")
def killed(tmp_path_factory):
    """Every format's run, started together and each killed once its capture spans RUN_S."""
    d = tmp_path_factory.mktemp("kill")
    procs = {}
    for fmt in FORMATS:
        args = [executable("zk"), "monitor", "-p", "sim://zk?speed=1", "-o", str(d / f"out.{fmt}"),
                "--raw-log", str(d / f"{fmt}.bin"), "--capture", str(d / f"{fmt}.pcapng"), "--timeout", "30"]
        procs[fmt] = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.PIPE, env=clean_env())
    deadline = time.monotonic() + 90
    try:
        pending = dict(procs)
        while pending and time.monotonic() < deadline:
            for fmt, p in list(pending.items()):
                assert p.poll() is None, f"{fmt}: exited {p.returncode}: {p.stderr.read().decode()}"
                span = _span(d / f"{fmt}.pcapng")
                if span is not None and span >= RUN_S:
                    p.send_signal(signal.SIGKILL)
                    p.wait(10)
                    del pending[fmt]
            time.sleep(0.05)
        assert not pending, f"never spanned {RUN_S} s: {sorted(pending)}"
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait(10)
            p.stderr.close()
    return d


def _span(path):
    """Seconds between the first and last chunk of a capture being written (None: none yet)."""
    try:
        ts = [k.ts for k in Reader(str(path))]
    except Exception:  # noqa: BLE001 - not even the header yet
        return None
    return ts[-1] - ts[0] if ts else None


def _received(d, fmt):
    with Reader(str(d / f"{fmt}.pcapng"), "zk") as r:
        pkts = [k for k in r if k.direction == INBOUND]
    assert not r.truncated                     # every block on disk is whole
    return pkts


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_a_killed_run_keeps_its_records_up_to_the_last_second(killed, fmt):
    pkts = _received(killed, fmt)
    times = FORMATS[fmt](killed / f"out.{fmt}")
    assert len(times) >= 20, "records"
    assert pkts[-1].ts - times[-1] <= LOSS_S, f"{fmt}: lost {pkts[-1].ts - times[-1]:.2f} s of records"


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_a_killed_runs_raw_log_and_capture_kept_every_byte_received(killed, fmt):
    pkts = _received(killed, fmt)
    received = b"".join(k.data for k in pkts)
    raw = (killed / f"{fmt}.bin").read_bytes()
    # the capture is written inside the read, the raw log right after it: at most the last chunk apart
    assert received.startswith(raw) and len(received) - len(raw) <= len(pkts[-1].data)


def test_a_killed_workbook_run_leaves_no_openpyxl_file_and_the_next_run_clears_its_directory(tmp_path):
    """openpyxl keeps each sheet in a temporary file it removes only at a normal exit: zkzap puts
    them in a directory of the run's own, which the next workbook run removes once its process is
    gone; nothing of openpyxl's lies in the temporary directory itself."""
    pytest.importorskip("openpyxl")
    temp = tmp_path / "tmp"
    temp.mkdir()
    env = clean_env(TMPDIR=str(temp))
    out = tmp_path / "run.xlsx"
    partial = tmp_path / "run.xlsx.partial.csv"
    p = subprocess.Popen([executable("zk"), "monitor", "-p", "sim://zk?speed=1", "-o", str(out), "--timeout", "30"],
                         stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    try:
        deadline = time.monotonic() + 60
        while not (partial.exists() and partial.read_text().count("\n") >= 5):
            assert p.poll() is None, p.stderr.read().decode()
            assert time.monotonic() < deadline, "no rows written"
            time.sleep(0.05)
        (private,) = [x for x in temp.iterdir()]
        assert private.name.startswith(f"zkzap-xlsx-{p.pid}-") and any(private.glob("openpyxl.*"))
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait(10)
        p.stderr.close()
    assert not list(temp.glob("openpyxl.*")) and [x.name for x in temp.iterdir()] == [private.name]
    partial.unlink()                                      # the killed run's rows, taken care of
    done = subprocess.run([executable("zk"), "monitor", "-p", "sim://zk?speed=5", "-o", str(out), "--duration", "1"],
                          stdin=subprocess.DEVNULL, capture_output=True, env=env, timeout=60)
    assert done.returncode == 0, done.stderr
    assert out.exists() and not partial.exists()
    assert list(temp.iterdir()) == []                     # the killed run's directory, and its own, removed
