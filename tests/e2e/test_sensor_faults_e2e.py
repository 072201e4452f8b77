"""A real stand's sensors, end to end on the simulator over ptys: a load cell that prints a
banner, sends garbage or dies mid-run. Garbage is rejected and counted, never stored; a banner is
no header; a dead sensor goes stale on the session's clock and marks the steps; every summary of
a run counts the same lines; the reader's port is never closed under it."""

from __future__ import annotations

import csv
import io
import json
import os
import threading
import time
import tty

import pytest

SIM = "sim://zk?speed=20"
SCHEDULE = "0,0,run\n24,50\n38,0,standby\n40,0,standby\n"        # model seconds: 12 s of start-up


class Cell:
    """A sensor on a pty: ``lines`` sent in a loop every ``period`` real seconds, after ``banner``,
    for ``life`` real seconds (None: until the test ends)."""

    def __init__(self, lines, period=0.01, banner=(), life=None):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.stop = threading.Event()
        self.sent = 0
        self.lines = lines

        def talk():
            t0 = time.monotonic()
            try:
                for b in banner:
                    os.write(self.master, b.encode() + b"\r\n")
                while not self.stop.is_set():
                    if life is not None and time.monotonic() - t0 > life:
                        return
                    os.write(self.master, self.lines[self.sent % len(self.lines)].encode() + b"\r\n")
                    self.sent += 1
                    time.sleep(period)
            except OSError:
                return

        self.thread = threading.Thread(target=talk, daemon=True)
        self.thread.start()

    def close(self):
        self.stop.set()
        self.thread.join(2)
        os.close(self.master)
        os.close(self.slave)


@pytest.fixture
def cells():
    made = []

    def make(*args, **kw):
        c = Cell(*args, **kw)
        made.append(c)
        return c

    yield make
    for c in made:
        c.close()


def _run(cli, tmp_path, aux, *extra):
    sched = tmp_path / "s.csv"
    sched.write_text(SCHEDULE)
    tel, steps, summary = tmp_path / "tel.csv", tmp_path / "steps.csv", tmp_path / "s.json"
    r = cli("zk", "profile", str(sched), "-p", SIM, "-o", str(tel), "--aux", aux, "--settle", "4",
            "--steps-csv", str(steps), "--summary-json", str(summary), *extra)
    assert r.exit_code == 0, r
    return (list(csv.DictReader(io.StringIO(tel.read_text()))), list(csv.DictReader(io.StringIO(steps.read_text()))),
            json.loads(summary.read_text()), r)


def test_garbage_is_rejected_counted_and_marks_the_step(cli, tmp_path, cells):
    cell = cells(["HX711 load cell v1.2 ready", "thrust=12.3", "thrust=abc", "thrust=12.3", "thrust=-5", "thrust=12.3",
                  "thrust=12.3 thrust=99", "thrust=12.3", "thrust=NaN"])
    rows, (step,), s, r = _run(cli, tmp_path, f"{cell.path}@115200,thrust:kgf:0..100", "--thrust-from", "thrust")
    assert {row["thrust"] for row in rows} <= {"12.3", ""} and "hx711_load_cell_v1_2_ready" not in rows[0]
    assert float(step["thrust_from_kg_mean"]) == 12.3 and step["thrust_from_kg_std"] == "0.0"
    (aux,) = s["aux"]
    chan = aux["channels"][0]
    assert aux["skipped"] >= 1 and chan["unit"] == "kgf" and chan["range"] == [0, 100]
    assert set(chan["rejected"]) == {"not a number", "outside 0..100 kgf", "given twice in one line",
                                     "not a finite number"}
    assert aux["rejected"] == sum(chan["rejected"].values()) and chan["values"] > 0
    assert step["settled"] == "false" and "thrust: " in step["note"] and "rejected in the window" in step["note"]
    assert "[never settled" in r.stderr or "rejected in the window" in r.stderr


def test_a_banner_before_a_csv_header_is_skipped(cli, tmp_path, cells):
    # a banner and the header (again every 20 lines, as some sensors do: the start of a pty's
    # output can be lost before the port opens), then rows
    cell = cells(["HX711 load cell v1.2 ready", "load_n,flow_ml_min"] + ["98.0665,250"] * 20)
    rows, (step,), s, _ = _run(cli, tmp_path, f"{cell.path}@115200", "--thrust-from", "load_n",
                               "--fuel-flow-from", "flow_ml_min")
    assert rows[-1]["load_n"] == "98.0665" and rows[-1]["flow_ml_min"] == "250"
    assert float(step["thrust_from_kg_mean"]) == 10.0 and float(step["fuel_flow_from_l_min_mean"]) == 0.25
    aux = s["aux"][0]
    assert aux["skipped"] >= 2 and aux["format"] == "csv" and aux["rejected"] == 0


def test_a_sensor_that_dies_goes_stale_in_session_time(cli, tmp_path):
    # a FIFO: its writer's open waits for the reader's, so the sensor's life starts with the
    # session's sensors however loaded the machine; it stays open, silent, once it dies
    fifo = tmp_path / "cell"
    os.mkfifo(fifo)
    done = threading.Event()

    def talk():
        with open(fifo, "w") as f:
            t0 = time.monotonic()
            while time.monotonic() - t0 < 0.3:                      # about 6 model seconds at speed 20
                f.write("thrust_n=98.0665\n")
                f.flush()
                time.sleep(0.01)
            done.wait(60)

    writer = threading.Thread(target=talk, daemon=True)
    writer.start()
    try:
        rows, (step,), s, r = _run(cli, tmp_path, f"{fifo},thrust_n:N,stale=2", "--thrust-from", "thrust_n")
        # the run ended with its schedule, while the silent sensor still held its FIFO open
        assert writer.is_alive()
    finally:
        done.set()
        writer.join(5)
    late = [row for row in rows if float(row["t"]) > 12]
    assert late and all(row["thrust_n"] == "" for row in late)     # blank 2 model seconds after the last line
    assert step["thrust_from_kg_mean"] == "" and step["tsfc_g_kn_s"] == "" and step["settled"] == "false"
    assert "thrust_n stale" in step["note"] and "no valid thrust_n in the window" in step["note"]
    chan = s["aux"][0]["channels"][0]
    # stale from 2 s after its last line (within the first 6 model seconds) to the session's end
    assert s["duration_s"] - 8 <= chan["stale_time_s"] <= s["duration_s"] - 2
    assert "nothing from" in r.stderr


def test_every_summary_counts_the_same_lines_and_the_port_closes_cleanly(cli, tmp_path, cells):
    openpyxl = pytest.importorskip("openpyxl")
    cell = cells(["thrust_n=98.0665 t_c=25"])
    sched = tmp_path / "s.csv"
    sched.write_text(SCHEDULE)
    book, summary = tmp_path / "run.xlsx", tmp_path / "s.json"
    r = cli("zk", "profile", str(sched), "-p", SIM, "-o", str(book), "--aux", f"{cell.path}@115200",
            "--thrust-from", "thrust_n", "--settle", "4", "--summary-json", str(summary))
    assert r.exit_code == 0, r
    (aux,) = json.loads(summary.read_text())["aux"]
    assert aux["error"] is None and "NoneType" not in r.stderr
    sheet = openpyxl.load_workbook(book, read_only=True)["summary"]
    cells_ = [list(row) for row in sheet.iter_rows(values_only=True)]
    head = next(i for i, row in enumerate(cells_) if row and row[0] == "sensor")
    got = dict(zip(cells_[head], cells_[head + 1]))
    assert (got["lines"], got["readings"], got["skipped"], got["rejected"]) == \
        (aux["lines"], aux["readings"], aux["skipped"], aux["rejected"])


def test_tare_and_calibrate_write_the_file_and_a_run_records_what_it_used(cli, tmp_path, cells):
    import subprocess
    import sys

    tomllib = pytest.importorskip("tomllib")
    cell = cells(["raw=101.5"])
    stand = tmp_path / "stand.toml"
    stand.write_text(f'# the stand\n[[sensor]]\nname = "load cell"\nsource = "{cell.path}@115200"\n\n'
                     '[[sensor.channel]]\nname = "thrust_n"\nkey = "raw"\nunit = "N"\nrange = [-50, 2000]\n')
    r = cli("zk", "sensor", "tare", str(stand), "--average", "0.3")
    assert r.exit_code == 0 and "thrust_n tare 101.5 N raw" in r.stderr, r
    assert "# the stand" in stand.read_text()                                  # the file is kept, comments too
    exe = os.path.join(os.path.dirname(sys.executable), "zk")
    p = subprocess.Popen([exe, "sensor", "calibrate", str(stand), "--point", "0", "--point", "98.0665",
                          "--average", "0.3"], stdin=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for load in ("101.5", "1101.5"):
        cell_lines = [f"raw={load}"]
        while "press Enter" not in p.stderr.readline():
            pass
        cell.lines = cell_lines
        time.sleep(0.1)                                    # the lines on their way
        p.stdin.write("\n")
        p.stdin.flush()
    _, err = p.communicate(timeout=30)
    assert p.returncode == 0, err
    cal = tomllib.loads(stand.read_text())["sensor"][0]["channel"][0]["calibration"]
    assert cal["tare"] == 101.5 and cal["points"] == [[0.0, 0.0], [1000.0, 98.0665]] and cal["date"].endswith("Z")
    assert cal["measured"] == [[101.5, 0.0], [1101.5, 98.0665]]
    cell.lines = ["raw=601.5"]                                      # half the reference load
    rows, (step,), s, _ = _run(cli, tmp_path, str(stand), "--thrust-from", "thrust_n")
    assert rows[-1]["thrust_n"] == "49.03325" and float(step["thrust_from_kg_mean"]) == 5.0
    (chan,) = s["aux"][0]["channels"]
    assert chan["calibration"] == cal and s["aux"][0]["declared_in"] == str(stand)
