"""Structured documents from untrusted text (fleet files, state files, summaries): every format,
whatever the text holds, gives a value or one DocumentError ``FILE:LINE: what``."""

from __future__ import annotations

import pytest

from zkzap.api import documents
from zkzap.api.documents import DocumentError
from zkzap.api.textfile import read_text
from zkzap.errors import MissingExtra, UsageError

BIG = "9" * 5000

#: (format, text, the message expected, from its start)
REFUSED = [
    ("json", '{"a": 1,\n "b": {"c": 1, "c": 2}}', "f:2: key 'c' is given twice"),
    ("json", '{"a": {"x": 1}, "b": {"x": 1}, "a": 3}', "f:1: key 'a' is given twice"),
    ("json", '{"a": "x\\"y", "a\\"": 1, "a": 2}', "f:1: key 'a' is given twice"),
    ("json", "[" * 5000, "f:1: nested more than 100 levels deep"),
    ("json", '{"a":\n' + BIG + "}", "f:2: an integer of 5000 digits; at most 4300"),
    ("json", '{"a": NaN}', "f:1: NaN is not a finite number (JSON has no NaN)"),
    ("json", '{"a": -Infinity}', "f:1: -Infinity is not a finite number"),
    ("json", '{"a":\n\n 1e400}', "f:3: 1e400 is not a finite number"),
    ("json", '{"a": 1,}', "f:1: not valid JSON: Expecting property name enclosed in double quotes (column 9)"),
    ("toml", "a = 1\na = 2\n", "f:2: not valid TOML: cannot overwrite a value (column 6)"),
    ("toml", "a = " + "[" * 3000, "f:1: nested more than 100 levels deep"),
    ("toml", "x = 1\na = " + BIG + "\n", "f:2: an integer of more than 4300 digits"),
    ("toml", "a = [1,\n2,\n x]", "f:3: not valid TOML: invalid value (column 2)"),
    ("yaml", "a: 1\nb:\n  c: 1\n  c: 2\n", "f:4: key 'c' is given twice"),
    ("yaml", "a:\n" + "".join("  " * i + "- \n" for i in range(150)), "f:101: nested more than 100 levels deep"),
    ("yaml", "[" * 3000, "f:1: nested more than 100 levels deep"),
    ("yaml", "a:\n  b: " + BIG + "\n", "f:2: an integer of 5000 characters; at most 4300 digits"),
    ("yaml", "a: b: c\n", "f:1: mapping values are not allowed here"),
    ("yaml", "a: !!python/object/apply:os.system ['true']\n", "f:1: could not determine a constructor for the tag"),
    ("yaml", "a: 1\n---\nb: 2\n", "f:2: expected a single document in the stream"),
    ("yaml", "a: \x01\n", "f:1: character U+0001 is not allowed in YAML"),
]


@pytest.mark.parametrize("fmt,text,said", REFUSED, ids=[f"{f}-{i}" for i, (f, _, _) in enumerate(REFUSED)])
def test_a_document_that_cannot_be_read_is_one_line_naming_file_and_line(fmt, text, said):
    if fmt == "yaml":
        pytest.importorskip("yaml")
    with pytest.raises(DocumentError) as e:
        documents.loads(text, fmt, "f")
    assert str(e.value).startswith(said), str(e.value)
    assert "\n" not in str(e.value) and e.value.code == 2


def test_what_is_valid_reads_as_every_format_means_it():
    assert documents.loads('{"a": [1, 2.5, "x", null, true]}', "json", "f") == {"a": [1, 2.5, "x", None, True]}
    assert documents.loads('{"a": NaN}', "json", "f", finite=False)["a"] != documents.loads(
        '{"a": NaN}', "json", "f", finite=False)["a"]                    # a summary may hold NaN
    assert documents.loads("[a]\nb = 0x10\n", "toml", "f") == {"a": {"b": 16}}
    pytest.importorskip("yaml")
    text = "base: &b {speed-limit: 600}\none:\n  <<: *b\n  speed-limit: 700\ntwo: *b\n"
    assert documents.loads(text, "yaml", "f") == {"base": {"speed-limit": 600}, "one": {"speed-limit": 700},
                                                  "two": {"speed-limit": 600}}           # a merge key overrides


def test_yaml_without_pyyaml_names_the_extra(monkeypatch):
    import builtins

    real = builtins.__import__

    def no_yaml(name, *args, **kwargs):
        if name == "yaml" or name.startswith("yaml."):
            raise ImportError(name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(documents, "_loader", None)
    monkeypatch.setattr(builtins, "__import__", no_yaml)
    with pytest.raises(MissingExtra) as e:
        documents.loads("a: 1\n", "yaml", "fleet.yaml")
    assert str(e.value) == ("fleet.yaml: YAML: needs the yaml (PyYAML) library; install it with "
                            "pip install 'zkzap[yaml]'")
    assert e.value.code == 2 and e.value.extra == "yaml"


@pytest.mark.parametrize("data,said", [
    (b"\xef\xbb\xbf{}", None),                                                     # a UTF-8 BOM: dropped
    (b"\xff\xfe{\x00}\x00", "fleet: {p}: UTF-16 text (it starts with a UTF-16 byte order mark); save it as UTF-8"),
    (b"\x00\x00\xfe\xff", "fleet: {p}: UTF-32 text"),
    (b'{\n"a": "\xe9t\xe9"}', "fleet: {p}:2: not UTF-8 text (byte 0xE9 at byte 8)"),
])
def test_encodings(tmp_path, data, said):
    p = tmp_path / "f.json"
    p.write_bytes(data)
    if said is None:
        assert documents.read(str(p), "fleet") == ({}, str(p))
        return
    with pytest.raises(UsageError) as e:
        documents.read(str(p), "fleet")
    assert str(e.value).startswith(said.format(p=p)), str(e.value)


def test_a_file_larger_than_any_document_is_refused_without_reading_it_whole(tmp_path):
    with pytest.raises(UsageError, match=r"^schedule: /dev/zero: more than 0.0625 MiB: too large for a schedule file"):
        read_text("/dev/zero", "schedule", limit=1 << 16)
