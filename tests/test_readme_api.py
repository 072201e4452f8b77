"""The README's Python API examples run as written, against the simulators."""

from __future__ import annotations

import os
import re

import pytest

README = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "README.md")


def examples():
    text = open(README, encoding="utf-8").read()
    return re.findall(r"<!-- api-example -->\n```python\n(.*?)```", text, re.S)


def test_there_are_examples():
    assert len(examples()) >= 4


@pytest.mark.parametrize("index", range(len(examples())))
def test_example_runs(index):
    code = examples()[index]
    exec(compile(code, f"README.md example {index + 1}", "exec"), {"__name__": "readme_example"})
