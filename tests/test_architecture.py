"""Import directions of ARCHITECTURE.md, checked on the source (ast), so they stay true.

- analysis imports no other project package, no Qt, no hardware package; matplotlib only in
  analysis/report.
- sim_backend imports analysis but not rig (it satisfies rig's protocol by shape).
- rig imports nidaqmx only inside its NI driver modules; nothing imports rig.gui.
- no package imports benchmarks.
"""

from __future__ import annotations

import ast
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


def test_nothing_imports_the_gui():
    bad = [
        f"{f.relative_to(ROOT)}:{line}"
        for pkg in ("analysis", "rig", "sim_backend", "benchmarks")
        for f in _files(pkg)
        if "gui" not in f.relative_to(ROOT).parts
        for name, line in _imports(f)
        if name.startswith("rig.gui")
    ]
    assert not bad, bad
