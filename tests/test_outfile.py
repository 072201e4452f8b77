"""zkzap.outfile, the one output mechanism: whole files replaced atomically only when they are
regular files (onto a symlink's target, keeping the mode), devices and FIFOs written through,
streamed outputs opened by their first record, outputs compared with inputs as files."""

from __future__ import annotations

import io
import os
import stat
import threading

import pytest

from zkzap import checking
from zkzap.errors import OutputError, UsageError
from zkzap.io.writers import make_writer
from zkzap.outfile import LazyOutput, OutFile, refuse_same_files, write_whole


def test_a_whole_file_keeps_the_mode_of_the_file_it_replaces(tmp_path):
    f = tmp_path / "backup.json"
    f.write_text("old")
    os.chmod(f, 0o600)
    write_whole(str(f), "new\n")
    assert f.read_text() == "new\n" and stat.S_IMODE(os.stat(f).st_mode) == 0o600
    new = tmp_path / "fresh.json"
    write_whole(str(new), "x")
    assert stat.S_IMODE(os.stat(new).st_mode) == 0o666 & ~_umask()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["backup.json", "fresh.json"]   # no temporary left


def _umask():
    m = os.umask(0)
    os.umask(m)
    return m


def test_a_whole_file_replaces_a_symlinks_target_not_the_link(tmp_path):
    real = tmp_path / "real.json"
    real.write_text("old")
    os.chmod(real, 0o640)
    link = tmp_path / "link.json"
    link.symlink_to(real)
    write_whole(str(link), "new")
    assert link.is_symlink() and real.read_text() == "new" and stat.S_IMODE(os.stat(real).st_mode) == 0o640


def test_devices_and_fifos_are_written_through(tmp_path):
    write_whole("/dev/null", "x" * 10000)
    with pytest.raises(OutputError) as e:
        write_whole("/dev/full", "x")
    assert e.value.code == 7 and stat.S_ISCHR(os.stat("/dev/full").st_mode)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    got = []
    t = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()))
    t.start()
    write_whole(str(fifo), "through the fifo")
    t.join(5)
    assert got == [b"through the fifo"] and stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_a_failed_whole_write_leaves_the_old_file(tmp_path, monkeypatch):
    f = tmp_path / "summary.json"
    f.write_text("old")
    monkeypatch.setattr(os, "replace", lambda *a: (_ for _ in ()).throw(OSError(28, "No space left on device")))
    with pytest.raises(OutputError, match="No space left"):
        write_whole(str(f), "new")
    assert f.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["summary.json"]


@pytest.mark.parametrize("fmt", ["csv", "json", "jsonl", "influx"])
def test_an_output_that_received_no_record_is_left_as_it_was(tmp_path, fmt):
    f = tmp_path / f"run.{fmt}"
    f.write_bytes(b"old content\n")
    stream = LazyOutput(OutFile(str(f), fmt=fmt, columns=["t", "rpm"]).check())
    w = make_writer(fmt, stream, ["t", "rpm"])
    w.close()
    stream.close()
    assert f.read_bytes() == b"old content\n"                       # a header is not a record
    missing = tmp_path / f"new.{fmt}"
    stream = LazyOutput(OutFile(str(missing), fmt=fmt).check())
    make_writer(fmt, stream, ["t", "rpm"]).close()
    assert not missing.exists()


def test_the_first_record_opens_the_output_with_its_header(tmp_path):
    f = tmp_path / "run.csv"
    f.write_text("old\n")
    stream = LazyOutput(OutFile(str(f), fmt="csv", columns=["t", "rpm"]).check())
    w = make_writer("csv", stream, ["t", "rpm"])
    assert f.read_text() == "old\n"
    w.write({"t": 0.5, "rpm": 100})
    w.close()
    stream.close()
    assert f.read_text() == "t,rpm\n0.5,100\n"


def test_stdout_still_gets_a_header_and_an_empty_array():
    out = io.StringIO()
    make_writer("csv", out, ["t", "rpm"]).close()
    make_writer("json", out, ["t"]).close()
    assert out.getvalue() == "t,rpm\n[]\n"


def test_outputs_are_compared_with_inputs_as_files(tmp_path):
    f = tmp_path / "bus.pcapng"
    f.write_bytes(b"capture")
    link = tmp_path / "link.pcapng"
    link.symlink_to(f)
    hard = tmp_path / "hard.pcapng"
    os.link(f, hard)
    for out, inp in ((f, f), (f, link), (link, f), (hard, f), (tmp_path / "." / "bus.pcapng", f)):
        with pytest.raises(UsageError, match="is also the input"):
            refuse_same_files({"--output": str(out)}, {"FILE": [str(inp)]})
    with pytest.raises(UsageError, match="two outputs need two files"):
        refuse_same_files({"--output": str(link), "--raw-log": str(hard)})
    refuse_same_files({"--output": "/dev/null", "--raw-log": "/dev/null"})          # a device: nothing to lose
    refuse_same_files({"--output": str(tmp_path / "other")}, {"FILE": [str(f)]})


def test_opening_a_file_is_an_effect_a_check_stops_at(tmp_path):
    f = tmp_path / "x.jsonl"
    out = OutFile(str(f)).check()
    with checking.checking() as check:
        out.open()
        pytest.fail("the check went past the effect")
    assert check.effect == ("file", {"path": str(f)}) and not f.exists()
    with checking.checking() as check:
        write_whole(str(f), "x")
    assert check.effect[0] == "file" and not f.exists()


def test_a_capture_is_opened_by_its_first_packet(tmp_path):
    from zkzap.link.pcapng import INBOUND, Writer

    f = tmp_path / "c.pcapng"
    f.write_bytes(b"an older capture")
    w = Writer(str(f))
    i = w.interface("zk", "/dev/ttyUSB0", 115200)
    w.close()
    assert f.read_bytes() == b"an older capture"                     # headers alone are no record
    w = Writer(str(f))
    i = w.interface("zk", "/dev/ttyUSB0", 115200)
    w.packet(i, 1.0, b"\xf1\x00\x00\x00\x00\x4c\xa0", INBOUND)
    w.close()
    assert f.read_bytes()[:4] == b"\x0a\x0d\x0d\x0a"


def test_a_logbook_is_created_by_its_first_run_and_needs_a_file(tmp_path):
    from zkzap.api import logbook

    path = tmp_path / "k100.db"
    logbook.check_writable(str(path))
    assert not path.exists()                                         # checked, not created
    for bad in ("/dev/null", str(tmp_path)):
        with pytest.raises(UsageError):
            logbook.check_writable(bad)
    junk = tmp_path / "junk.db"
    junk.write_text("not a database")
    with pytest.raises(UsageError, match="not a zkzap logbook"):
        logbook.check_writable(str(junk))


def test_a_symlink_is_made_only_over_a_symlink(tmp_path):
    from zkzap.outfile import check_link, make_link

    f = tmp_path / "file"
    f.write_text("keep")
    with pytest.raises(UsageError, match="exists and is not a symlink"):
        check_link(str(f))
    with pytest.raises(UsageError):
        check_link("/dev/null")
    link = tmp_path / "ecu"
    make_link("/dev/pts/99", str(link))
    make_link("/dev/pts/98", str(link))
    assert os.readlink(link) == "/dev/pts/98" and f.read_text() == "keep"
