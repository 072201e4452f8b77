"""Every public name of the library's API modules has a docstring and complete annotations
(the manual's API reference renders both); the committed protocol reference is current."""

from __future__ import annotations

import inspect
import os
import re

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

API_MODULES = ("zkzap", "zkzap.api.zap", "zkzap.api.zk", "zkzap.errors", "zkzap.sim",
               "zkzap.sim.launch", "zkzap.pytest_plugin", "zkzap.link.shared", "zkzap.link.zk_port",
               "zkzap.link.zk_sources", "zkzap.api.telemetry", "zkzap.api.session", "zkzap.api.schedule",
               "zkzap.signals")


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
    assert committed == protocol.render(), \
        "docs/protocol.md differs from the tables; regenerate it with: python -m zkzap.docs all"
    for heading in ("### Control commands", "### Status frames", "### Registers", "### Instructions"):
        assert heading in committed


def documented_modules() -> list:
    """The modules the manual's API reference renders (its ``::: module`` lines), with the
    members a page restricts them to (None: all public ones)."""
    out = []
    folder = os.path.join(REPO, "docs", "reference", "api")
    for name in sorted(os.listdir(folder)):
        text = open(os.path.join(folder, name), encoding="utf-8").read()
        for m in re.finditer(r"^::: ([\w.]+)\n((?:    .*\n)*)", text, re.M):
            members = re.search(r"members: \[([^\]]*)\]", m.group(2))
            out.append((m.group(1), [x.strip() for x in members.group(1).split(",")] if members else None))
    return out


#: Special methods whose annotations type checkers read like any other's.
TYPED_DUNDERS = ("__init__", "__new__", "__enter__", "__exit__", "__getitem__", "__setitem__", "__call__",
                 "__iter__", "__next__", "__len__", "__contains__", "__eq__", "__getattr__")


def _callables(path, members):
    """(name, function) of every public function and method under the object at ``path``."""
    import importlib

    module_name, obj = path, None
    while True:
        try:
            obj = importlib.import_module(module_name)
            break
        except ImportError:
            module_name = module_name.rpartition(".")[0]
    for attr in path[len(module_name):].strip(".").split(".") if path != module_name else ():
        obj = getattr(obj, attr)
    if inspect.isclass(obj):
        items, only = [(path, obj)], members
    else:
        names = members or getattr(obj, "__all__", None) or [n for n in vars(obj) if not n.startswith("_")]
        items, only = [(f"{path}.{n}", getattr(obj, n)) for n in names], None
        if not members and not hasattr(obj, "__all__"):      # what the module defines, not what it imports
            items = [(n, i) for n, i in items if getattr(i, "__module__", module_name) == module_name]
    for name, item in items:
        if inspect.isfunction(item):
            yield name, item
        elif inspect.isclass(item) and item.__module__.startswith("zkzap"):
            for attr, member in vars(item).items():
                if (attr.startswith("_") and attr not in TYPED_DUNDERS) or (only and attr not in only
                                                                            and attr != "__init__"):
                    continue
                if isinstance(member, (staticmethod, classmethod)):
                    member = member.__func__
                if isinstance(member, property):
                    member = member.fget
                if inspect.isfunction(member):
                    yield f"{name}.{attr}", member


def test_the_reference_renders_the_api_modules():
    paths = {p for p, _ in documented_modules()}
    for module in ("zkzap.api.zap", "zkzap.api.zk", "zkzap.sim.launch", "zkzap.errors", "zkzap.codec.zk",
                   "zkzap.codec.zap", "zkzap.pytest_plugin"):
        assert module in paths


def test_every_documented_function_and_method_is_fully_annotated():
    missing = []
    for path, members in documented_modules():
        for name, fn in _callables(path, members):
            sig = inspect.signature(fn)
            gaps = [p for p in sig.parameters if p not in ("self", "cls") and
                    sig.parameters[p].annotation is inspect.Parameter.empty]
            if sig.return_annotation is inspect.Signature.empty:
                gaps.append("return")
            if gaps:
                missing.append(f"{name}: {', '.join(gaps)}")
    assert missing == []
