"""The API reference builds with pdoc without a warning; every public name of the library's API
modules has a docstring; the committed protocol reference is current."""

from __future__ import annotations

import inspect
import os
import warnings

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

API_MODULES = ("zkzap", "zkzap.api.zap", "zkzap.api.zk", "zkzap.errors", "zkzap.sim",
               "zkzap.sim.launch", "zkzap.pytest_plugin", "zkzap.link.shared", "zkzap.link.zk_port",
               "zkzap.link.zk_sources", "zkzap.api.telemetry", "zkzap.api.session", "zkzap.api.schedule",
               "zkzap.signals")


def test_pdoc_builds_without_warnings(tmp_path):
    pytest.importorskip("pdoc", reason="the docs extra (pip install '.[docs]') is not installed")
    from zkzap.docs import api

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        written = api.generate(str(tmp_path / "api"))
    assert [str(w.message) for w in caught] == []
    names = {os.path.relpath(p, tmp_path / "api") for p in written}
    for page in ("zkzap.html", "zkzap/api/zap.html", "zkzap/api/zk.html", "zkzap/sim/launch.html",
                 "zkzap/errors.html", "zkzap/codec/zk.html", "zkzap/pytest_plugin.html"):
        assert page in names
    text = (tmp_path / "api" / "zkzap" / "api" / "zap.html").read_text()
    assert "present_voltage" in text and "set_baud" in text


def _public(module):
    import importlib

    mod = importlib.import_module(module)
    names = getattr(mod, "__all__", None) or [n for n in vars(mod) if not n.startswith("_")]
    for name in names:
        obj = getattr(mod, name)
        if inspect.ismodule(obj) or not (inspect.isclass(obj) or inspect.isfunction(obj)):
            continue
        if getattr(obj, "__module__", "").split(".")[0] != "zkzap":
            continue
        yield f"{module}.{name}", obj
        if inspect.isclass(obj):
            for attr, member in vars(obj).items():
                if attr.startswith("_") or not (inspect.isfunction(member) or isinstance(member, property)):
                    continue
                yield f"{module}.{name}.{attr}", member


@pytest.mark.parametrize("module", API_MODULES)
def test_every_public_name_has_a_docstring(module):
    missing = [name for name, obj in _public(module) if not (inspect.getdoc(obj) or "").strip()]
    assert missing == []


def test_typed_frames_are_documented():
    from zkzap.codec import zap, zk

    for cls in (zk.ControlFrame, zap.Command):
        for attr, member in vars(cls).items():
            if not attr.startswith("_") and (inspect.isfunction(member) or isinstance(member, property)):
                assert inspect.getdoc(member), f"{cls.__name__}.{attr}"


def test_py_typed_is_shipped():
    assert os.path.exists(os.path.join(REPO, "cli", "zkzap", "py.typed"))


def test_committed_protocol_reference_is_current():
    from zkzap.docs import protocol

    with open(os.path.join(REPO, "docs", "protocol.md"), encoding="utf-8") as f:
        committed = f.read()
    assert committed == protocol.render(os.path.join(REPO, "README.md")), \
        "docs/protocol.md differs from the tables; regenerate it with: python -m zkzap.docs all"
    for heading in ("### Control commands", "### Status frames", "### Registers", "### Instructions",
                    "## Decisions where the specifications are open"):
        assert heading in committed
