"""Import directions of docs/architecture.md, checked on the source (ast), so they stay true.

- analysis imports no other project package, no Qt, no hardware package; matplotlib only in
  analysis/report.
- sim_backend imports analysis but not rig (it satisfies rig's protocol by shape).
- rig imports nidaqmx only inside its NI driver modules; nothing imports rig.gui but the
  ``gui`` command of rig/cli/main.py, inside its function.
- no package imports benchmarks.
- the acquisition service's client side (rig/service: client, auth, directory, launch) needs the
  standard library only, so the GUI and scripts stay light; aiohttp only in its server.
- no import cycle among the project's modules (imports inside functions included) but the
  known ones listed here, a list that may only shrink.
"""

from __future__ import annotations

import ast
import functools
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@functools.cache
def _tree(path: Path) -> ast.Module:
    """The parsed file, once per session (every test walks the same files)."""
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _imports(path: Path) -> list[tuple[str, int]]:
    tree = _tree(path)
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
    tree = _tree(path)
    return {
        node.lineno
        for fn in ast.walk(tree)
        if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef)
        for node in ast.walk(fn)
        if isinstance(node, ast.Import | ast.ImportFrom)
    }


def test_nothing_imports_the_gui():
    """rig.gui is a leaf: only the ``gui`` command of rig/cli/main.py imports it, inside the
    command's function (so the command line works without Qt)."""
    cli = ROOT / "rig" / "cli" / "main.py"
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


# ------------------------------------------------------------------------ import cycles

PROJECT_PACKAGES = ("analysis", "rig", "sim_backend", "benchmarks")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _type_checking_lines(tree: ast.Module) -> set[int]:
    """Lines of the imports under ``if TYPE_CHECKING:`` (never run)."""
    return {
        node.lineno
        for stmt in ast.walk(tree)
        if isinstance(stmt, ast.If) and "TYPE_CHECKING" in ast.unparse(stmt.test)
        for body_stmt in stmt.body
        for node in ast.walk(body_stmt)
        if isinstance(node, ast.Import | ast.ImportFrom)
    }


@functools.cache
def _import_graph() -> dict[str, set[str]]:
    """Module -> the project's modules it imports, at module level or inside functions;
    ``from package import name`` counts as importing the submodule when ``name`` is one, else
    the package."""
    files = {_module_name(f): f for pkg in PROJECT_PACKAGES for f in _files(pkg)}

    def resolve(name: str) -> str | None:
        while name and name not in files:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for mod, path in files.items():
        tree = _tree(path)
        skip = _type_checking_lines(tree)
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        targets = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import | ast.ImportFrom) and node.lineno in skip:
                continue
            if isinstance(node, ast.Import):
                targets |= {resolve(a.name) for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")
                    anchor = anchor[: len(anchor) - (node.level - 1)]
                    base = ".".join([*anchor, base] if base else anchor)
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    targets.add(sub if sub in files else resolve(base))
        graph[mod] = {t for t in targets if t is not None and t != mod}
    return graph


def _cycles(graph: dict[str, set[str]]) -> set[tuple[str, ...]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: set[tuple[str, ...]] = set()

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.add(tuple(sorted(component)))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(graph)))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_cycle_finder_finds_a_cycle_through_three_modules():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}}
    assert _cycles(graph) == {("a", "b", "c")}


def test_relative_and_function_level_imports_are_in_the_graph():
    graph = _import_graph()
    # relative: analysis/model.py's ``from .fe import ...`` and ``from .matrix_io import ...``
    assert {"analysis.fe", "analysis.matrix_io"} <= graph["analysis.model"]
    # inside a function: augment imports the linear calibration only when it needs it
    assert "analysis.calibration.linear" in graph["analysis.diagnosis.augment"]
    # ``from package import module`` is the module, ``from package import name`` the package
    assert "analysis.elements.base" in graph["analysis.elements.contact"]
    assert "analysis.diagnosis" not in graph["analysis.diagnosis.diagnose"]


def test_no_import_cycle():
    """No group of modules imports each other, directly or around a loop (a function-level
    import counts too)."""
    found = _cycles(_import_graph())
    assert not found, f"import cycles: {sorted(found)}"


# rig's stages, lowest first: a module may import its own stage's modules and lower stages'
# only (docs/architecture.md). The engine layer of rig/run (commands, events, faults, engine,
# acquisition, safety, lock) is below the procedures, which speak its commands; the session and
# the dry run, which turn a plan into a procedure and run it, are above them.
RIG_STAGES: tuple[tuple[str, ...], ...] = (
    ("rig.signals", "rig.backends", "rig.instruments"),
    ("rig.estimation", "rig.config"),
    (
        "rig.run.commands",
        "rig.run.events",
        "rig.run.faults",
        "rig.run.engine",
        "rig.run.acquisition",
        "rig.run.safety",
        "rig.run.lock",
    ),
    ("rig.procedures",),
    ("rig.run.session", "rig.run.dry_run", "rig.run"),
    ("rig.export", "rig.service", "rig.cli", "rig.gui", "rig", "rig.__main__"),
)


def _rig_stage(module: str) -> int | None:
    """Index of the stage that holds ``module`` (its longest matching prefix), None outside rig."""
    best, rank = "", None
    for i, stage in enumerate(RIG_STAGES):
        for prefix in stage:
            hit = module == prefix or module.startswith(prefix + ".")
            if hit and len(prefix) > len(best):
                best, rank = prefix, i
    return rank


def test_every_rig_module_has_a_stage():
    missing = [m for m in _import_graph() if m.startswith("rig") and _rig_stage(m) is None]
    assert not missing, f"rig modules outside every stage of RIG_STAGES: {missing}"


def test_rig_stages_import_downwards():
    wrong = [
        f"{mod} (stage {_rig_stage(mod)}) imports {dep} (stage {_rig_stage(dep)})"
        for mod, deps in sorted(_import_graph().items())
        if mod.startswith("rig")
        for dep in sorted(deps)
        if dep.startswith("rig") and (_rig_stage(dep) or 0) > (_rig_stage(mod) or 0)
    ]
    assert not wrong, "\n".join(wrong)


def test_the_stage_rule_catches_an_upward_import():
    # the engine layer below the procedures, the procedures below the session
    assert _rig_stage("rig.run.engine") < _rig_stage("rig.procedures.stepped_sine")
    assert _rig_stage("rig.procedures.stepped_sine") < _rig_stage("rig.run.session")
    assert _rig_stage("rig.config.plans") < _rig_stage("rig.run.commands")
