"""The documented API as type checkers see it: ``mypy --strict`` and pyright (strict) accept a
program that uses all of it (api_program.py, which also runs) and refuse every wrong call of
wrong_types.py; the lazy exports are declared for them; the Actuator's register attributes are
the register table's."""

from __future__ import annotations

import ast
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
PROGRAMS = ("api_program.py", "wrong_types.py")
EXTRA = "the test extra (pip install '.[test]') installs it"


def refused_lines() -> set:
    with open(os.path.join(HERE, "wrong_types.py"), encoding="utf-8") as f:
        return {n for n, line in enumerate(f, 1) if re.search(r"\S.*#\s*refused:", line)}


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """The two programs, copied where no configuration of this repository applies."""
    d = tmp_path_factory.mktemp("typing")
    for name in PROGRAMS:
        shutil.copy(os.path.join(HERE, name), d / name)
    return d


def _errors_by_file(pairs) -> dict:
    out = {name: set() for name in PROGRAMS}
    for path, line in pairs:
        out.setdefault(os.path.basename(path), set()).add(int(line))
    return out


def test_there_are_enough_wrong_calls():
    assert len(refused_lines()) >= 20


def test_mypy_strict_accepts_the_api_and_refuses_wrong_types(workdir):
    pytest.importorskip("mypy", reason=f"mypy is not installed; {EXTRA}")
    p = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--python-version", "3.10", "--no-color-output",
                        "--cache-dir", str(workdir / ".mypy_cache"), *PROGRAMS],
                       capture_output=True, text=True, cwd=workdir, timeout=300)
    errors = re.findall(r"^(\S+\.py):(\d+): error:", p.stdout, re.M)
    assert p.returncode in (0, 1), p.stdout + p.stderr
    found = _errors_by_file(errors)
    assert found["api_program.py"] == set(), p.stdout
    assert found["wrong_types.py"] == refused_lines(), p.stdout


def _pyright():
    """The pyright command, or None when it cannot run here (not installed, no node)."""
    exe = shutil.which("pyright", path=os.path.dirname(sys.executable)) or shutil.which("pyright")
    if exe is None:
        return None
    try:
        p = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=600)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return exe if p.returncode == 0 else None


@pytest.fixture(scope="module")
def pyright_report(workdir):
    """pyright (strict) over every program of this module at once (one node process analysing the
    library once): ``{file name: [diagnostic, ...]}``."""
    exe = _pyright()
    if exe is None:
        pytest.skip(f"pyright cannot run here (it needs node); {EXTRA}")
    (workdir / "user_script.py").write_text(USER_SCRIPT)
    (workdir / "user_typo.py").write_text(USER_SCRIPT.replace('rec["id"]', 'rec["idd"]'))
    (workdir / "pyrightconfig.json").write_text(json.dumps({"typeCheckingMode": "strict", "pythonVersion": "3.10"}))
    p = subprocess.run([exe, "--outputjson", "--pythonpath", sys.executable, *PROGRAMS, "user_script.py",
                        "user_typo.py"], capture_output=True, text=True, cwd=workdir, timeout=600)
    report = json.loads(p.stdout)
    out = {}
    for d in report["generalDiagnostics"]:
        out.setdefault(os.path.basename(d["file"]), []).append(d)
    return out


def test_pyright_strict_accepts_the_api_and_refuses_wrong_types(pyright_report):
    diagnostics = [d for name in PROGRAMS for d in pyright_report.get(name, [])]
    errors = [(d["file"], d["range"]["start"]["line"] + 1) for d in diagnostics if d["severity"] == "error"]
    found = _errors_by_file(errors)
    messages = "\n".join(f"{d['file']}:{d['range']['start']['line'] + 1}: {d['message']}" for d in diagnostics)
    assert found["api_program.py"] == set(), messages
    assert found["wrong_types.py"] == refused_lines(), messages


#: A user's ten lines: every record the mightyZAP API returns is typed (pyright strict: 0 errors).
USER_SCRIPT = """\
from zkzap import Bus

with Bus("sim://zap?ids=1,2") as bus:
    for rec in bus.scan(range(4)):
        print(rec["id"], rec["model"], rec["status"], rec["errors"])
    rows = bus[1].dump()
    print(rows[0]["register"], rows[0]["value"], rows[0]["memory"])
    print(bus.identify(1)["firmware"], bus.move(1, 4000).clamped)
    for ident, lat in bus.latencies.items():
        print(ident, lat["latency_ms"], lat["late"])
"""


def _pyright_errors(report, name) -> list:
    return [(d["range"]["start"]["line"] + 1, d["message"]) for d in report.get(name, []) if d["severity"] == "error"]


def test_pyright_strict_types_a_users_ten_lines_and_refuses_a_key_typo(pyright_report):
    assert len(USER_SCRIPT.splitlines()) == 10
    assert _pyright_errors(pyright_report, "user_script.py") == []
    errors = _pyright_errors(pyright_report, "user_typo.py")
    assert {line for line, _ in errors} == {5}, errors
    assert any('"idd" is not a defined key in "ScanRecord"' in text for _, text in errors), errors


def test_the_user_script_runs(capsys):
    from zkzap import GoalClamped

    with pytest.warns(GoalClamped, match="goal 4000 clamped to 3686"):
        exec(compile(USER_SCRIPT, "user_script.py", "exec"), {})
    assert capsys.readouterr().out.startswith("1 41234 ok []")


def test_the_api_program_runs():
    spec = importlib.util.spec_from_file_location("api_program", os.path.join(HERE, "api_program.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main() == 0


def _type_checking_imports(path) -> dict:
    """``{name: module}`` of the ``from .X import N as N`` lines under ``if TYPE_CHECKING:``."""
    tree = ast.parse(open(path, encoding="utf-8").read())
    out = {}
    for node in tree.body:
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            for stmt in node.body:
                if isinstance(stmt, ast.ImportFrom) and stmt.level == 1:
                    for alias in stmt.names:
                        if alias.asname == alias.name:
                            out[alias.name] = stmt.module
    return out


def test_type_checkers_see_every_lazy_export_of_zkzap():
    import zkzap

    declared = _type_checking_imports(os.path.join(REPO, "cli", "zkzap", "__init__.py"))
    assert {name: f"zkzap.{mod}" for name, mod in declared.items()} == zkzap._LAZY
    assert set(zkzap.__all__) == {"__version__", *zkzap._LAZY}


def test_type_checkers_see_the_simulator_and_codec_exports():
    import zkzap.codec
    import zkzap.sim

    sim = _type_checking_imports(os.path.join(REPO, "cli", "zkzap", "sim", "__init__.py"))
    assert set(sim) == set(zkzap.sim._LAUNCH) and set(sim.values()) == {"launch"}
    codec = _type_checking_imports(os.path.join(REPO, "cli", "zkzap", "codec", "__init__.py"))
    assert {name: mod for name, mod in codec.items()} == zkzap.codec._WHERE
    assert set(zkzap.codec.__all__) == set(codec)


def _library_errors():
    """Every ZkzapError subclass defined in the library's modules (commands and generators
    excepted: they are the application)."""
    import pkgutil

    import zkzap
    from zkzap.errors import ZkzapError

    for info in pkgutil.walk_packages(zkzap.__path__, "zkzap."):
        if info.name.startswith(("zkzap.commands", "zkzap.docs", "zkzap.__main__", "zkzap.io.bridges")):
            continue
        try:
            module = importlib.import_module(info.name)
        except ImportError:                          # an optional extra (mcap) that is not installed
            continue
        for obj in vars(module).values():
            if isinstance(obj, type) and issubclass(obj, ZkzapError) and obj.__module__ == info.name:
                yield obj


def test_every_library_error_is_exported_from_zkzap():
    import zkzap

    missing = sorted(f"{cls.__module__}.{cls.__name__}" for cls in set(_library_errors())
                     if getattr(zkzap, cls.__name__, None) is not cls)
    assert missing == []


def test_the_register_stub_is_current():
    from zkzap.docs import stubs

    with open(os.path.join(REPO, stubs.PATH), encoding="utf-8") as f:
        assert f.read() == stubs.render(), "regenerate it with: python -m zkzap.docs all"
