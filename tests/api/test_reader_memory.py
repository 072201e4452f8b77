"""Every reader of a whole document keeps its memory a small constant times the input, whatever
the text holds (a 20 MiB string, deep nesting after it, a key given twice at the end): peak RSS
measured in a fresh interpreter, so one reader's garbage is not another's baseline."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

MIB = 1 << 20
SIZE = 20 * MIB
DEEP = "[" * 2000 + "]" * 2000

#: name -> (file suffix, the text, the reader's call, the start of the error it gives)
CASES = {
    "json-string": (".json", '{"a": "' + "x" * SIZE + '", "a": 1}', "doc", "key 'a' is given twice"),
    "json-escapes": (".json", '{"a": "' + "\\n" * (SIZE // 2) + '", "b": 1, "a": 2}', "doc",
                     "key 'a' is given twice"),
    "json-deep": (".json", '{"a": "' + "x" * SIZE + '", "b": ' + DEEP + "}", "doc",
                  "nested more than 100 levels deep"),
    "toml-deep": (".toml", "a = '" + "x" * SIZE + "'\nb = " + DEEP + "\n", "doc",
                  "nested more than 100 levels deep"),
    "yaml-large": (".yaml", 'a: "' + "x" * SIZE + '"\n', "doc", "more than 4 MiB"),
    "schedule": (".csv", "0,50,run\n" + "1," + "9" * SIZE + ",run\n", "schedule", "not a CSV row"),
}

SCRIPT = """
import json, resource, sys
path, how = sys.argv[1], sys.argv[2]
from zkzap.api import documents, schedule
from zkzap.errors import UsageError
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
try:
    if how == "doc":
        documents.read(path, "fleet", documents.SUFFIXES[path[path.rindex("."):]])
    else:
        schedule.Schedule.load(path)
    message = ""
except UsageError as e:
    message = str(e)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"kib": peak - base, "message": message}))
"""


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_20_mib_document_is_read_in_a_few_times_its_size(tmp_path, name):
    suffix, text, how, message = CASES[name]
    path = tmp_path / f"doc{suffix}"
    path.write_text(text)
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(path), how], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert message in got["message"]
    assert got["message"] and "\n" not in got["message"] and len(got["message"]) < 200
    grown = got["kib"] * 1024
    # the text (bytes, then str) and the longest string's value: about 3 times the file
    assert grown < 4 * len(text), f"{name}: {grown / MIB:.0f} MiB for a {len(text) / MIB:.0f} MiB file"
