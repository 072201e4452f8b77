"""Text inputs (schedules, limits, batch files): one reader, one set of messages."""

import io
import sys

import pytest

from zkzap.api.schedule import Schedule
from zkzap.api.textfile import read_text
from zkzap.errors import UsageError


def test_a_file_a_byte_order_mark_and_stdin(tmp_path, monkeypatch):
    f = tmp_path / "s.csv"
    f.write_bytes(b"\xef\xbb\xbf0,10\n5,20\n")                 # as spreadsheets save CSV
    assert read_text(f, "schedule") == ("0,10\n5,20\n", str(f))
    assert Schedule.load(str(f)).length == 5
    monkeypatch.setattr(sys, "stdin", io.StringIO("load id --id 1\n"))
    assert read_text("-", "batch") == ("load id --id 1\n", "stdin")


@pytest.mark.parametrize("what,expected", [("schedule", "CSV rows"), ("limits", "FIELD OP NUMBER"),
                                           ("batch", "one command per line")])
def test_unreadable_and_not_utf8_name_the_input(tmp_path, what, expected):
    with pytest.raises(UsageError, match=rf"^{what}: cannot read .*missing: No such file"):
        read_text(tmp_path / "missing", what)
    bad = tmp_path / "bad"
    bad.write_bytes(b"# ok\nbad \xff\xfe\x00")
    with pytest.raises(UsageError, match=rf"^{what}: .*bad:2: not UTF-8 text \(byte 0xFF at byte 9\); "
                                         rf"expected {expected}"):
        read_text(bad, what, expected + " ...")
    bad.write_bytes(b"\xff\xfe#\x00 \x00o\x00k\x00")             # as Windows' Notepad saves "Unicode"
    with pytest.raises(UsageError, match=rf"^{what}: .*bad: UTF-16 text .*; save it as UTF-8"):
        read_text(bad, what)
