"""-o run.xlsx: a workbook with the records (a units row under the header, numbers as numbers,
time as a date-time), the steps and the summary of a profile run on the simulator."""

from __future__ import annotations

import datetime

import pytest

openpyxl = pytest.importorskip("openpyxl")


def test_profile_workbook_has_records_steps_and_summary(cli, tmp_path):
    sched = tmp_path / "s.csv"
    sched.write_text("0,0,run\n24,40\n32,0,standby\n34,0,standby\n")       # model seconds: 12 s of start-up
    book = tmp_path / "run.xlsx"
    r = cli("zk", "profile", str(sched), "-p", "sim://zk?speed=20", "-o", str(book), "--settle", "2",
            "--limit", "egt_c<=900")
    assert r.exit_code == 0, r
    wb = openpyxl.load_workbook(book)
    assert wb.sheetnames == ["records", "steps", "summary"]
    rows = list(wb["records"].iter_rows(values_only=True))
    header, units, first = rows[0], rows[1], rows[2]
    col = {k: i for i, k in enumerate(header)}
    assert units[col["t"]] == "s" and units[col["egt_c"]] == "°C" and units[col["thrust_kg"]] == "kgf"
    assert isinstance(first[col["time"]], datetime.datetime) and isinstance(first[col["t"]], (int, float))   # t = 0 reads back as 0
    assert isinstance(first[col["rpm"]], int) and isinstance(first[col["stale"]], bool)
    assert "limit" in col and len(rows) > 100                                # snapshot rows, as in CSV
    assert max(row[col["rpm"]] for row in rows[2:]) > 80000
    steps = list(wb["steps"].iter_rows(values_only=True))
    from zkzap.api.steady import columns

    assert list(steps[0]) == columns() and steps[1][columns().index("tsfc_g_kn_s")] == "g/(kN·s)"
    # a number (xlsx keeps no int/float distinction: a mean of 86100.0 reads back as 86100)
    means = [row[columns().index("rpm_mean")] for row in steps[2:]]
    assert any(isinstance(m, (int, float)) and not isinstance(m, bool) and m > 50000 for m in means), means
    summary = {row[0]: row[1] for row in wb["summary"].iter_rows(values_only=True) if row and row[0]}
    assert summary["outcome"] == "duration" and summary["frames"] > 100 and "limits:" in summary


def test_monitor_workbook_and_a_failed_start_leaves_the_old_file(cli, tmp_path):
    book = tmp_path / "m.xlsx"
    r = cli("zk", "monitor", "-p", "sim://zk?speed=20", "--count", "12", "-o", str(book))
    assert r.exit_code == 0, r
    wb = openpyxl.load_workbook(book)
    assert wb["records"].max_row == 2 + 12 and wb["summary"]["A2"].value == "command"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.xlsx"]       # the journal is gone
    before = book.read_bytes()
    r = cli("zk", "monitor", "-p", "sim://zk?silent_after=0", "--timeout", "0.1", "-o", str(book))
    assert r.exit_code == 3 and book.read_bytes() == before


def test_a_killed_runs_journal_is_never_overwritten(cli, tmp_path):
    book = tmp_path / "m.xlsx"
    journal = tmp_path / "m.xlsx.partial.csv"
    journal.write_text("time,t\n")                   # what a run killed with SIGKILL leaves
    r = cli("zk", "monitor", "-p", "sim://zk?speed=20", "--count", "3", "-o", str(book))
    assert r.exit_code == 2 and "m.xlsx.partial.csv holds the rows of a run killed" in r.stderr
    assert journal.read_text() == "time,t\n" and not book.exists() and r.stdout == ""


def test_a_workbook_keeps_its_header_in_view_its_milliseconds_and_every_unit(cli, tmp_path):
    openpyxl = pytest.importorskip("openpyxl")
    cell = tmp_path / "cell.log"
    cell.write_text("thrust_n=98.0665\n" * 5)
    book = tmp_path / "run.xlsx"
    r = cli("zk", "monitor", "--sim", "--duration", "2", "-o", str(book), "--aux", f"{cell},thrust_n:N",
            "--ambient-temp", "20")
    assert r.exit_code == 0, r
    ws = openpyxl.load_workbook(book)["records"]
    assert ws.freeze_panes == "A3"
    header = [c.value for c in ws[1]]
    units = dict(zip(header, [c.value for c in ws[2]]))
    assert units["thrust_n"] == "N" and units["rpm_corrected"] == "rpm" and units["thrust_corrected_kg"] == "kgf"
    assert ws.cell(row=3, column=header.index("time") + 1).number_format == "yyyy-mm-dd hh:mm:ss.000"
