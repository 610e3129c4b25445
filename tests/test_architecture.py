"""Import directions of docs/architecture.md, checked on the source (ast), so they stay true.

- analysis imports no other project package, no Qt, no hardware package; matplotlib only in
  analysis/report.
- sim_backend imports analysis but not rig (it satisfies rig's protocol by shape).
- rig imports nidaqmx only inside its NI driver modules; nothing imports rig.gui but the
  ``gui`` command of rig/cli.py, inside its function.
- no package imports benchmarks.
- the acquisition service's client side (rig/service: client, auth, directory, launch) needs the
  standard library only, so the GUI and scripts stay light; aiohttp only in its server.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _imports(path: Path) -> list[tuple[str, int]]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append((node.module, node.lineno))
    return out


def _files(package: str):
    return sorted((ROOT / package).rglob("*.py"))


def _top(name: str) -> str:
    return name.split(".")[0]


@pytest.mark.parametrize(
    "package, forbidden",
    [
        (
            "analysis",
            {"rig", "sim_backend", "benchmarks", "PySide6", "pyqtgraph", "nidaqmx", "serial"},
        ),
        ("sim_backend", {"rig", "benchmarks", "PySide6", "pyqtgraph", "nidaqmx"}),
        ("rig", {"benchmarks", "sim_backend"}),
    ],
)
def test_package_import_directions(package, forbidden):
    bad = []
    for f in _files(package):
        for name, line in _imports(f):
            if _top(name) in forbidden:
                bad.append(f"{f.relative_to(ROOT)}:{line} imports {name}")
    assert not bad, "\n".join(bad)


def test_matplotlib_only_in_analysis_report():
    bad = [
        f"{f.relative_to(ROOT)}:{line}"
        for f in _files("analysis")
        if "report" not in f.relative_to(ROOT / "analysis").parts
        for name, line in _imports(f)
        if _top(name) == "matplotlib"
    ]
    assert not bad, bad


def test_nidaqmx_only_in_the_ni_driver():
    bad = [
        f"{f.relative_to(ROOT)}:{line}"
        for f in _files("rig")
        if not f.name.startswith("ni")
        for name, line in _imports(f)
        if _top(name) == "nidaqmx"
    ]
    assert not bad, bad


def _function_imports(path: Path) -> set[int]:
    """Lines of the imports made inside functions (run only when the function is called)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    return {
        node.lineno
        for fn in ast.walk(tree)
        if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef)
        for node in ast.walk(fn)
        if isinstance(node, ast.Import | ast.ImportFrom)
    }


def test_nothing_imports_the_gui():
    """rig.gui is a leaf: only the ``gui`` command of rig/cli.py imports it, inside the
    command's function (so the command line works without Qt)."""
    cli = ROOT / "rig" / "cli.py"
    bad = [
        f"{f.relative_to(ROOT)}:{line}"
        for pkg in ("analysis", "rig", "sim_backend", "benchmarks")
        for f in _files(pkg)
        if "gui" not in f.relative_to(ROOT).parts
        for name, line in _imports(f)
        if name.startswith("rig.gui") and not (f == cli and line in _function_imports(cli))
    ]
    assert not bad, bad


SERVICE_CLIENT_SIDE = ("__init__.py", "client.py", "auth.py", "directory.py", "launch.py")


def test_service_client_side_needs_only_the_standard_library():
    bad = [
        f"rig/service/{name}:{line} imports {mod}"
        for name in SERVICE_CLIENT_SIDE
        for mod, line in _imports(ROOT / "rig" / "service" / name)
        if _top(mod) not in sys.stdlib_module_names and not mod.startswith("rig.service.")
    ]
    assert not bad, bad


def test_the_http_server_stack_only_in_the_service_server():
    bad = [
        f"{f.relative_to(ROOT)}:{line}"
        for pkg in ("analysis", "rig", "sim_backend")
        for f in _files(pkg)
        if f.relative_to(ROOT).as_posix() != "rig/service/server.py"
        for name, line in _imports(f)
        if _top(name) == "aiohttp"
    ]
    assert not bad, bad
