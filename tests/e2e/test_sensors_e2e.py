"""External sensors and the ECU's requests, end to end on the simulator: a simulated load cell on
a pty whose readings become record fields and the steps' TSFC and corrections; a silent one
found before anything is sent; an ECU that asks for the air pressure, answered from a number and
from a barometer file."""

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


@pytest.fixture
def load_cell():
    """A load cell on a pty: 'thrust_n=98.0665 t_c=25' twenty times a second, CSV-free."""
    master, slave = os.openpty()
    tty.setraw(slave)
    stop = threading.Event()

    def talk():
        while not stop.is_set():
            try:
                os.write(master, b"thrust_n=98.0665 t_c=25.0 status=OK\r\n")
            except OSError:
                return
            time.sleep(0.05)

    t = threading.Thread(target=talk, daemon=True)
    t.start()
    yield os.ttyname(slave) + "@115200"
    stop.set()
    t.join(2)
    os.close(master)
    os.close(slave)


def test_a_load_cell_on_a_pty_feeds_records_tsfc_and_corrections(cli, tmp_path, load_cell):
    sched = tmp_path / "s.csv"
    sched.write_text("0,0,run\n24,50\n38,0,standby\n40,0,standby\n")          # model seconds: 12 s of start-up
    tel, steps, summary = tmp_path / "tel.csv", tmp_path / "steps.csv", tmp_path / "s.json"
    r = cli("zk", "profile", str(sched), "-p", SIM, "-o", str(tel), "--aux", load_cell, "--thrust-from", "thrust_n",
            "--ambient-temp", "t_c", "--settle", "4", "--steps-csv", str(steps), "--summary-json", str(summary))
    assert r.exit_code == 0, r
    rows = list(csv.DictReader(io.StringIO(tel.read_text())))
    assert rows[-1]["thrust_n"] == "98.0665" and rows[-1]["t_c"] == "25.0"
    assert rows[-1]["status"] == ""                         # text is no value: rejected, never stored
    assert "rpm_corrected" in rows[0]
    (step,) = list(csv.DictReader(io.StringIO(steps.read_text())))
    assert step["target"] == "50 %" and float(step["thrust_from_kg_mean"]) == 10.0
    flow = float(step["fuel_flow_l_min_mean"])
    # TSFC over the load cell's 10 kgf, not the ECU's thrust: flow x 0.8 / 60 kg/s over 98.0665 N
    assert float(step["tsfc_g_kn_s"]) == pytest.approx(flow * 0.8 / 60 * 1e6 / 98.0665, abs=0.01)
    theta = (25 + 273.15) / 288.15
    assert float(step["theta"]) == round(theta, 5) and float(step["ambient_pressure_hpa"]) == 1013   # the ECU's
    assert float(step["rpm_corrected"]) == pytest.approx(float(step["rpm_mean"]) / theta ** 0.5, abs=0.1)
    assert float(step["thrust_corrected_kg"]) == pytest.approx(10.0 / (1013 / 1013.25), abs=1e-4)
    s = json.loads(summary.read_text())
    aux = s["aux"][0]
    assert aux["fields"] == ["thrust_n", "t_c", "status"] and aux["readings"] > 10 and aux["skipped"] == 0
    assert aux["rejected"] == aux["readings"] and aux["channels"][2]["rejected"] == {"not a number": aux["readings"]}


def test_a_silent_sensor_is_exit_3_before_anything_is_sent(cli, tmp_path):
    import select

    master, slave = os.openpty()                      # an ECU's line that shows what was written
    tty.setraw(slave)
    path = os.ttyname(slave)

    def written():
        return os.read(master, 4096) if select.select([master], [], [], 0.1)[0] else b""
    quiet = tmp_path / "cell.log"
    quiet.write_text("")
    r = cli("zk", "send", "control", "--state", "run", "--for", "5", "-p", path, "--yes", "--aux", str(quiet),
            "--timeout", "0.3")
    assert r.exit_code == 3 and f"aux: no reading from {quiet} within 0.3 s (no line;" in r.stderr, r
    assert written() == b"" and r.stdout == ""
    os.close(master)
    os.close(slave)
    r = cli("zk", "monitor", "--sim", "--aux", str(quiet), "--thrust-from", "load_n")
    assert r.exit_code == 2 and "thrust-from: applies with --ambient-temp" in r.stderr


def test_the_ecus_request_for_air_pressure_is_answered_at_a_modest_rate(cli, tmp_path):
    summary, log = tmp_path / "s.json", tmp_path / "m.jsonl"
    r = cli("zk", "monitor", "-p", SIM + "&esr=1&esr_again=0", "--duration", "10", "--air-pressure", "995",
            "-o", str(log), "--summary-json", str(summary))
    assert r.exit_code == 0, r
    answers = json.loads(summary.read_text())["air_pressure_answers"]
    times = [f["t"] for f in answers["frames"]]
    assert answers["sent"] >= 3 and answers["asked"] > answers["sent"]                 # an ECU that keeps asking
    recs = [json.loads(line) for line in log.read_text().splitlines()]
    asks = [rec["t"] for rec in recs if rec["id"] == 8 and rec["esr"]]
    # the rule, judged on the requests as they were read (a loaded machine reads them late and in
    # bunches): each answer is a request's; never two closer than 0.5 s, nor more than one a second
    # on average; and a request a second after the last answer is always answered
    assert set(times) <= set(asks)
    assert all(b - a >= 0.5 - 0.002 for a, b in zip(times, times[1:]))
    assert all(t >= times[0] + n * 1.0 - 0.1 - 0.002 for n, t in enumerate(times))
    for t in asks:
        before = [a for a in times if a < t]
        assert t in times or not before or t - before[-1] < 1.0 + 0.002, (t, times)
    from zkzap.codec import zk

    assert {f["frame"] for f in answers["frames"]} == {zk.encode_control("pressure", pressure_hpa=995)[0].hex(" ").upper()}
    assert [rec["pressure_pa"] for rec in recs if rec["id"] == 3][-1] == 99500         # the ECU took it
    assert "answering 995 hPa from --air-pressure" in r.stderr


def test_an_aux_barometer_answers_the_request(cli, tmp_path):
    baro = tmp_path / "baro.csv"
    baro.write_text("baro_pa,temp_c\n99012,18.5\n")
    summary = tmp_path / "s.json"
    r = cli("zk", "monitor", "-p", SIM + "&esr=1", "--duration", "4", "--aux", str(baro), "--air-pressure",
            "baro_pa", "--summary-json", str(summary), "-f", "jsonl", "--ids", "3")
    assert r.exit_code == 0, r
    answers = json.loads(summary.read_text())["air_pressure_answers"]
    # once, or again when the ECU asked before the answer had reached it (a loaded machine)
    assert answers["sent"] >= 1 and {f["pressure_hpa"] for f in answers["frames"]} == {990}
    assert json.loads(r.stdout.splitlines()[-1])["pressure_pa"] == 99000
