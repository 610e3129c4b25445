"""The model file (TOML): its record types, parsing with key-path errors, and writing.

The reference example is ``analysis/models/clearance_rig.toml``. Top-level keys:
``title``, ``nodes``, ``sections``, ``materials``, ``members``, ``joints``, ``springs``,
``masses``, ``supports`` (a planar frame) or ``linear_part`` (matrices from another FE code;
``[linear_part.masses]`` adds point masses [kg] to the translational DOFs of a node),
and ``points``, ``parameters``, ``nonlinear``, ``damping``, ``truth`` (simulator only).
Every error names the file, the key path (``members[3].section``) and the problem.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .fe import DIRECTIONS, FrameSpec, Joint, LumpedMass, Material, Member, Section, Spring
from .matrix_io import FORMATS, IMPORT_DIRECTIONS

__all__ = [
    "DampingSpec",
    "DofRef",
    "LinearPartSpec",
    "MeasurementPoint",
    "ModelFileError",
    "NonlinearSpec",
    "Parameter",
    "parse_document",
]

NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
NODE_RE = re.compile(r"^[A-Za-z0-9_.\-]+$")
RESERVED = ("rigid", "free")
MAX_COORDINATE_M = 1e4
"""Largest coordinate accepted [m] (a structure on a test rig; larger values are typos)."""
_TOP_KEYS = {
    "title",
    "nodes",
    "sections",
    "materials",
    "members",
    "joints",
    "springs",
    "masses",
    "supports",
    "points",
    "parameters",
    "nonlinear",
    "damping",
    "linear_part",
    "truth",
}
_FILE_KEYS = {
    "b_m": "b",
    "h_m": "h",
    "outer_m": "outer",
    "wall_m": "wall",
    "area_m2": "A",
    "inertia_m4": "I",
    "max_element_length_m": "max_element_length",
}
DAMPING_MODAL = ("default_zeta", "per_mode")
_FRAME_KEYS = ("nodes", "sections", "materials", "members", "joints", "springs", "masses")


class ModelFileError(ValueError):
    """An invalid model file or model: ``"<source>: <key path>: <problem>"``."""

    def __init__(self, source: str, path: str, problem: str) -> None:
        self.source, self.path, self.problem = source, path, problem
        super().__init__(f"{source}: {path}: {problem}" if path else f"{source}: {problem}")


@dataclass(frozen=True)
class Parameter:
    """A model parameter: a linear coefficient (group ``"linear"``) or an element parameter.

    ``lower``/``upper`` bound calibration; ``value`` may leave them (a warning is the
    caller's business) but must be finite, and positive under ``log`` scaling.

    ``prior_rel_std`` is what is known of the parameter before any test: a standard deviation
    about ``nominal``, relative to it (0.05: 5 %; under ``log`` scaling the standard deviation
    of ``ln p``). A calibration that cannot determine the parameter holds it at ``nominal``
    with this uncertainty and carries it into everything it reports; ``None``: no prior is
    known (the parameter must be determined by the test or reported as not determined).
    """

    name: str
    value: float
    nominal: float
    lower: float = -math.inf
    upper: float = math.inf
    calibrate: bool = False
    scaling: str = "linear"
    unit: str = ""
    group: str = "linear"
    description: str = ""
    prior_rel_std: float | None = None

    def __post_init__(self) -> None:
        if not NAME_RE.match(self.name) or self.name in RESERVED:
            raise ValueError(f"name: {self.name!r} is not a valid parameter name")
        for f in ("value", "nominal", "lower", "upper"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, int | float) or math.isnan(v):
                raise ValueError(f"{f}: must be a number, got {v!r}")
            object.__setattr__(self, f, float(v))
        for f in ("value", "nominal"):
            if not math.isfinite(getattr(self, f)):
                raise ValueError(f"{f}: must be finite, got {getattr(self, f)!r}")
        if not self.lower < self.upper:
            raise ValueError(f"lower: {self.lower} must be below upper {self.upper}")
        if not self.lower <= self.nominal <= self.upper:
            raise ValueError(f"nominal: {self.nominal} is outside [{self.lower}, {self.upper}]")
        if self.scaling not in ("linear", "log"):
            raise ValueError(f"scaling: must be 'linear' or 'log', got {self.scaling!r}")
        if self.scaling == "log" and not (self.lower >= 0 and self.value > 0):
            raise ValueError("scaling: 'log' needs lower >= 0 and a positive value")
        if self.group not in ("linear", "nonlinear"):
            raise ValueError(f"group: must be 'linear' or 'nonlinear', got {self.group!r}")
        if not isinstance(self.calibrate, bool):
            raise ValueError(f"calibrate: must be true or false, got {self.calibrate!r}")
        prior = self.prior_rel_std
        if prior is not None:
            if isinstance(prior, bool) or not isinstance(prior, int | float):
                raise ValueError(f"prior_rel_std: must be a number, got {prior!r}")
            if not (math.isfinite(prior) and prior > 0):
                raise ValueError(f"prior_rel_std: must be finite and > 0, got {prior!r}")
            object.__setattr__(self, "prior_rel_std", float(prior))


@dataclass(frozen=True)
class DofRef:
    """A DOF by measurement point (direction defaults to the point's) or by node and direction.

    A model fills in ``node`` and ``direction`` of point references on construction.
    """

    node: str | None = None
    direction: str | None = None
    point: int | None = None

    def __post_init__(self) -> None:
        if self.point is None and (self.node is None or self.direction is None):
            raise ValueError("give a point, or a node and a direction")

    @property
    def label(self) -> str:
        """``"node/direction"``."""
        return f"{self.node}/{self.direction}"


@dataclass(frozen=True)
class MeasurementPoint:
    """Measurement point ``number`` at ``node`` measuring ``direction``; ``xy`` in m."""

    number: int
    node: str
    direction: str
    xy: tuple[float, float] | None = None


@dataclass(frozen=True)
class NonlinearSpec:
    """A nonlinear element: ``kind`` between DOF ``at`` and ``to`` (``None``: ground).

    ``params`` maps each element parameter to a number or a model parameter name.
    """

    name: str
    kind: str
    at: DofRef
    to: DofRef | None = None
    params: dict[str, float | str] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class DampingSpec:
    """Damping of the linear part: one of three forms.

    - modal ratios: ``default_zeta`` and ``per_mode`` (1-based, ascending frequency);
    - Rayleigh damping ``C = alpha M + beta K``: ``rayleigh = (alpha [1/s], beta [s])``;
    - an explicit viscous damping matrix over the model's free DOFs (in the order of
      ``Model.assemble().dofs``): ``matrix``, rows of numbers or the absolute path of a
      ``.npy`` or MatrixMarket ``.mtx`` file [N s/m].

    With ``rayleigh`` or ``matrix`` the modal ratios are not used (the linear part is then
    solved directly from ``K - w^2 M + i w C``).
    """

    default_zeta: float = 0.01
    per_mode: dict[int, float] = field(default_factory=dict)
    rayleigh: tuple[float, float] | None = None
    matrix: tuple[tuple[float, ...], ...] | str | None = None

    def __post_init__(self) -> None:
        if not 0 <= self.default_zeta < 1:
            raise ValueError(f"default_zeta: must be in [0, 1), got {self.default_zeta!r}")
        for mode, zeta in self.per_mode.items():
            if not (isinstance(mode, int) and mode >= 1):
                raise ValueError(f"per_mode: mode numbers start at 1, got {mode!r}")
            if not 0 <= zeta < 1:
                raise ValueError(f"per_mode.{mode}: must be in [0, 1), got {zeta!r}")
        object.__setattr__(self, "per_mode", dict(sorted(self.per_mode.items())))
        if self.rayleigh is not None:
            alpha, beta = (float(v) for v in self.rayleigh)
            if not (alpha >= 0 and beta >= 0 and math.isfinite(alpha + beta)):
                raise ValueError(
                    f"rayleigh: alpha and beta must be finite and >= 0, got {self.rayleigh!r}"
                )
            object.__setattr__(self, "rayleigh", (alpha, beta))
        if self.rayleigh is not None and self.matrix is not None:
            raise ValueError("rayleigh: give either rayleigh or matrix, not both")
        if isinstance(self.matrix, list | tuple):
            rows = tuple(tuple(float(v) for v in row) for row in self.matrix)
            if not rows or any(len(row) != len(rows) for row in rows):
                raise ValueError("matrix: expected a square array of rows")
            object.__setattr__(self, "matrix", rows)

    @property
    def modal(self) -> bool:
        """True for modal damping ratios (neither Rayleigh nor an explicit matrix)."""
        return self.rayleigh is None and self.matrix is None

    def zeta(self, n_modes: int) -> list[float]:
        """Damping ratio of modes 1..n_modes."""
        return [self.per_mode.get(k, self.default_zeta) for k in range(1, n_modes + 1)]


@dataclass(frozen=True)
class LinearPartSpec:
    """Linear part imported from files: ``format`` and absolute ``files`` (``file`` for one
    archive, ``M``/``K``/``C`` for MatrixMarket) plus a DOF map (file path or labels)."""

    format: str
    files: dict[str, str]
    dof_map: str | tuple[str, ...] | None = None
    masses: dict[str, float] = field(default_factory=dict)


class _Reader:
    """Typed access to the parsed TOML with key-path errors."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, path: str, problem: str) -> None:
        raise ModelFileError(self.source, path, problem)

    def table(self, value: Any, path: str, allowed: set[str] | None = None) -> dict:
        if not isinstance(value, dict):
            self.fail(path, f"expected a table, got {type(value).__name__}")
        if allowed is not None and (unknown := set(value) - allowed):
            self.fail(
                f"{path}.{sorted(unknown)[0]}" if path else sorted(unknown)[0],
                f"unknown key; expected one of {sorted(allowed)}",
            )
        return value

    def array(self, value: Any, path: str) -> list:
        if not isinstance(value, list):
            self.fail(path, f"expected an array, got {type(value).__name__}")
        return value

    def need(self, t: dict, key: str, path: str) -> Any:
        if key not in t:
            self.fail(f"{path}.{key}", "missing")
        return t[key]

    def number(self, value: Any, path: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(path, f"expected a number, got {value!r}")
        return float(value)

    def finite(self, value: Any, path: str) -> float:
        x = self.number(value, path)
        if not math.isfinite(x):
            self.fail(path, f"expected a finite number, got {value!r}")
        return x

    def coordinate(self, value: Any, path: str) -> float:
        x = self.finite(value, path)
        if abs(x) > MAX_COORDINATE_M:
            self.fail(path, f"a coordinate [m] within +-{MAX_COORDINATE_M:g}, got {value!r}")
        return x

    def text(self, value: Any, path: str) -> str:
        if not isinstance(value, str):
            self.fail(path, f"expected a string, got {value!r}")
        return value

    def coef(self, value: Any, path: str) -> float | str:
        return value if isinstance(value, str) else self.finite(value, path)

    def direction(self, value: Any, path: str, allowed: tuple[str, ...] = DIRECTIONS) -> str:
        if value not in allowed:
            self.fail(path, f"bad direction {value!r}; expected one of {allowed}")
        return value

    def build(self, cls: type, path: str, **kwargs: Any) -> Any:
        """``cls(**kwargs)``; a ``"field: problem"`` error becomes ``"path.key: problem"``."""
        try:
            return cls(**kwargs)
        except ValueError as exc:
            name, sep, problem = str(exc).partition(": ")
            if sep and name.isidentifier():
                self.fail(f"{path}.{_FILE_KEYS.get(name, name)}", problem)
            self.fail(path, str(exc))


def _section(r: _Reader, t: dict, path: str) -> Section:
    r.table(t, path, {"shape", "b", "h", "outer", "wall", "A", "I"})
    shape = r.text(t.get("shape", "general"), f"{path}.shape")
    keys = {"b": "b_m", "h": "h_m", "outer": "outer_m", "wall": "wall_m"}
    keys |= {"A": "area_m2", "I": "inertia_m4"}
    kw = {keys[k]: r.finite(v, f"{path}.{k}") for k, v in t.items() if k != "shape"}
    return r.build(Section, path, shape=shape, **kw)


def _member(r: _Reader, t: dict, path: str, i: int) -> Member:
    allowed = {"name", "nodes", "section", "material", "elements", "max_element_length"}
    r.table(t, path, allowed | {"nsm", "group"})
    nodes = r.array(r.need(t, "nodes", path), f"{path}.nodes")
    elements = t.get("elements")
    if elements is not None and (isinstance(elements, bool) or not isinstance(elements, int)):
        r.fail(f"{path}.elements", f"expected an integer, got {elements!r}")
    max_len = t.get("max_element_length")
    max_len = None if max_len is None else r.finite(max_len, f"{path}.max_element_length")
    return r.build(
        Member,
        path,
        name=r.text(t.get("name", f"m{i}"), f"{path}.name"),
        nodes=tuple(r.text(n, f"{path}.nodes") for n in nodes),
        section=r.text(r.need(t, "section", path), f"{path}.section"),
        material=r.text(r.need(t, "material", path), f"{path}.material"),
        elements=elements,
        max_element_length_m=max_len,
        nsm_kg_per_m=r.coef(t.get("nsm", 0.0), f"{path}.nsm"),
        group=r.text(t.get("group", "frame"), f"{path}.group"),
    )


def _joint(r: _Reader, t: dict, path: str, i: int) -> Joint:
    r.table(t, path, {"name", "nodes", *DIRECTIONS})
    conn = {}
    for d in DIRECTIONS:
        v = t.get(d, "rigid")
        if isinstance(v, dict):
            v = r.need(r.table(v, f"{path}.{d}", {"k"}), "k", f"{path}.{d}")
        conn[d] = r.coef(v, f"{path}.{d}")
    nodes = r.array(r.need(t, "nodes", path), f"{path}.nodes")
    if len(nodes) != 2:
        r.fail(f"{path}.nodes", f"need two nodes, got {nodes!r}")
    name = r.text(t.get("name", f"joint{i}"), f"{path}.name")
    return Joint(name=name, nodes=tuple(r.text(n, f"{path}.nodes") for n in nodes), **conn)


def _frame(r: _Reader, doc: dict) -> FrameSpec:
    nodes = {}
    for name, xy in r.table(doc.get("nodes", {}), "nodes").items():
        if not NODE_RE.match(name):
            r.fail(f"nodes.{name}", "node names use letters, digits, '_', '.', '-'")
        xy = r.array(xy, f"nodes.{name}")
        if len(xy) != 2:
            r.fail(f"nodes.{name}", f"expected [x, y] in m, got {xy!r}")
        nodes[name] = tuple(r.coordinate(v, f"nodes.{name}[{k}]") for k, v in enumerate(xy))
    sections = {
        n: _section(r, r.table(t, f"sections.{n}"), f"sections.{n}")
        for n, t in r.table(doc.get("sections", {}), "sections").items()
    }
    materials = {}
    for n, t in r.table(doc.get("materials", {}), "materials").items():
        p = f"materials.{n}"
        r.table(t, p, {"E", "rho"})
        E, rho = (r.coef(r.need(t, k, p), f"{p}.{k}") for k in ("E", "rho"))
        materials[n] = Material(E=E, rho=rho)
    members = tuple(
        _member(r, r.table(t, f"members[{i}]"), f"members[{i}]", i)
        for i, t in enumerate(r.array(doc.get("members", []), "members"))
    )
    joints = tuple(
        _joint(r, r.table(t, f"joints[{i}]"), f"joints[{i}]", i)
        for i, t in enumerate(r.array(doc.get("joints", []), "joints"))
    )
    springs = []
    for i, t in enumerate(r.array(doc.get("springs", []), "springs")):
        p = f"springs[{i}]"
        r.table(t, p, {"name", "node", "direction", "k", "to"})
        to = t.get("to")
        springs.append(
            Spring(
                name=r.text(t.get("name", f"spring{i}"), f"{p}.name"),
                node=r.text(r.need(t, "node", p), f"{p}.node"),
                direction=r.direction(r.need(t, "direction", p), f"{p}.direction"),
                k=r.coef(r.need(t, "k", p), f"{p}.k"),
                to=None if to is None else r.text(to, f"{p}.to"),
            )
        )
    masses = []
    for i, t in enumerate(r.array(doc.get("masses", []), "masses")):
        p = f"masses[{i}]"
        r.table(t, p, {"name", "node", "m", "J", "group"})
        masses.append(
            LumpedMass(
                name=r.text(t.get("name", f"mass{i}"), f"{p}.name"),
                node=r.text(r.need(t, "node", p), f"{p}.node"),
                m_kg=r.coef(r.need(t, "m", p), f"{p}.m"),
                J_kgm2=r.coef(t.get("J", 0.0), f"{p}.J"),
                group=r.text(t.get("group", "lumped"), f"{p}.group"),
            )
        )
    supports = {}
    for node, dirs in r.table(doc.get("supports", {}), "supports").items():
        dirs = list(DIRECTIONS) if dirs == "all" else r.array(dirs, f"supports.{node}")
        supports[node] = tuple(r.direction(d, f"supports.{node}[{k}]") for k, d in enumerate(dirs))
    return FrameSpec(
        nodes=nodes,
        sections=sections,
        materials=materials,
        members=members,
        joints=joints,
        springs=tuple(springs),
        masses=tuple(masses),
        supports=supports,
    )


def _parameter(r: _Reader, name: str, t: dict, group: str | None) -> Parameter:
    p = f"parameters.{name}"
    keys = {"value", "nominal", "lower", "upper", "calibrate", "scaling", "unit", "group"}
    r.table(t, p, keys | {"description", "prior_rel_std"})
    if "value" not in t and "nominal" not in t:
        r.fail(p, "give a value or a nominal value")
    value = r.number(t.get("value", t.get("nominal")), f"{p}.value")
    kw = {"value": value, "nominal": r.number(t.get("nominal", value), f"{p}.nominal")}
    for k in ("lower", "upper"):
        if k in t:
            kw[k] = r.number(t[k], f"{p}.{k}")
    for k in ("scaling", "unit", "group", "description"):
        if k in t:
            kw[k] = r.text(t[k], f"{p}.{k}")
    if "prior_rel_std" in t:
        kw["prior_rel_std"] = r.number(t["prior_rel_std"], f"{p}.prior_rel_std")
    kw.setdefault("group", group or "linear")
    if kw.get("scaling") == "log":
        kw.setdefault("lower", 0.0)
    return r.build(Parameter, p, name=name, calibrate=t.get("calibrate", False), **kw)


def _dofref(r: _Reader, t: Any, path: str, directions: tuple[str, ...]) -> DofRef:
    r.table(t, path, {"point", "node", "direction"})
    point = t.get("point")
    if point is not None and (isinstance(point, bool) or not isinstance(point, int)):
        r.fail(f"{path}.point", f"expected a point number, got {point!r}")
    direction = t.get("direction")
    if direction is not None:
        r.direction(direction, f"{path}.direction", directions)
    node = None if "node" not in t else r.text(t["node"], f"{path}.node")
    if point is not None and node is not None:
        r.fail(path, "give either a point or a node, not both")
    return r.build(DofRef, path, node=node, direction=direction, point=point)


def _nonlinear(r: _Reader, t: dict, path: str, dirs: tuple[str, ...]) -> NonlinearSpec:
    r.table(t, path, {"name", "kind", "at", "to", "params", "options"})
    params = r.table(t.get("params", {}), f"{path}.params")
    return NonlinearSpec(
        name=r.text(r.need(t, "name", path), f"{path}.name"),
        kind=r.text(r.need(t, "kind", path), f"{path}.kind"),
        at=_dofref(r, r.need(t, "at", path), f"{path}.at", dirs),
        to=None if "to" not in t else _dofref(r, t["to"], f"{path}.to", dirs),
        params={k: r.coef(v, f"{path}.params.{k}") for k, v in params.items()},
        options=dict(r.table(t.get("options", {}), f"{path}.options")),
    )


def _points(r: _Reader, doc: dict, dirs: tuple[str, ...]) -> dict[int, MeasurementPoint]:
    points = {}
    for key, t in r.table(doc.get("points", {}), "points").items():
        p = f"points.{key}"
        if not (key.isascii() and key.isdigit()) or int(key) < 1:
            r.fail(p, "point numbers are positive integers")
        r.table(t, p, {"node", "direction", "xy"})
        xy = t.get("xy")
        if xy is not None:
            xy = r.array(xy, f"{p}.xy")
            if len(xy) != 2:
                r.fail(f"{p}.xy", f"expected [x, y] in m, got {xy!r}")
            xy = tuple(r.coordinate(v, f"{p}.xy[{k}]") for k, v in enumerate(xy))
        if "node" not in t and xy is None:
            r.fail(p, "give a node or xy")
        node = r.text(t.get("node", ""), f"{p}.node")
        direction = r.direction(r.need(t, "direction", p), f"{p}.direction", dirs)
        points[int(key)] = MeasurementPoint(int(key), node, direction, xy)
    return dict(sorted(points.items()))


def _linear_part(r: _Reader, t: dict, base: Path) -> LinearPartSpec:
    r.table(t, "linear_part", {"format", "file", "files", "dof_map", "masses"})
    fmt = r.text(r.need(t, "format", "linear_part"), "linear_part.format")
    if fmt not in FORMATS:
        r.fail("linear_part.format", f"unknown format {fmt!r}; expected one of {FORMATS}")
    if fmt == "mtx":
        files = r.table(r.need(t, "files", "linear_part"), "linear_part.files", {"M", "K", "C"})
        for k in ("M", "K"):
            r.need(files, k, "linear_part.files")
    else:
        files = {"file": r.need(t, "file", "linear_part")}
    files = {k: str((base / r.text(v, f"linear_part.{k}")).resolve()) for k, v in files.items()}
    dof_map = t.get("dof_map")
    if isinstance(dof_map, str):
        dof_map = str((base / dof_map).resolve())
    elif dof_map is not None:
        dof_map = tuple(
            r.text(s, "linear_part.dof_map") for s in r.array(dof_map, "linear_part.dof_map")
        )
    elif fmt == "mtx":
        r.fail("linear_part.dof_map", "missing (a file name or a list of 'node/direction')")
    masses = r.table(t.get("masses", {}), "linear_part.masses")
    masses = {n: r.finite(m, f"linear_part.masses.{n}") for n, m in masses.items()}
    return LinearPartSpec(format=fmt, files=files, dof_map=dof_map, masses=masses)


def _damping(r: _Reader, t: dict, base: Path) -> DampingSpec:
    r.table(t, "damping", {"default_zeta", "per_mode", "rayleigh", "matrix"})
    per_mode = r.table(t.get("per_mode", {}), "damping.per_mode")
    for k in per_mode:
        if not (k.isascii() and k.isdigit()):
            r.fail(f"damping.per_mode.{k}", "mode numbers are positive integers")
    if ("rayleigh" in t or "matrix" in t) and (modal := [k for k in t if k in DAMPING_MODAL]):
        other = "rayleigh" if "rayleigh" in t else "matrix"
        r.fail(
            f"damping.{modal[0]}", f"modal damping ratios and damping.{other} exclude each other"
        )
    rayleigh = None
    if "rayleigh" in t:
        ray = r.table(t["rayleigh"], "damping.rayleigh", {"alpha", "beta"})
        rayleigh = tuple(
            r.finite(ray.get(k, 0.0), f"damping.rayleigh.{k}") for k in ("alpha", "beta")
        )
        for k, v in zip(("alpha", "beta"), rayleigh, strict=True):
            if v < 0:
                r.fail(f"damping.rayleigh.{k}", f"must be >= 0, got {v!r}")
    matrix = t.get("matrix")
    if isinstance(matrix, str):
        if not matrix.endswith((".npy", ".mtx")):
            r.fail("damping.matrix", f"a .npy or .mtx file, got {matrix!r}")
        matrix = str((base / matrix).resolve())
    elif matrix is not None:
        rows = r.array(matrix, "damping.matrix")
        matrix = tuple(
            tuple(
                r.finite(v, f"damping.matrix[{i}][{j}]")
                for j, v in enumerate(r.array(row, f"damping.matrix[{i}]"))
            )
            for i, row in enumerate(rows)
        )
    return r.build(
        DampingSpec,
        "damping",
        default_zeta=r.finite(t.get("default_zeta", 0.01), "damping.default_zeta"),
        per_mode={int(k): r.finite(v, f"damping.per_mode.{k}") for k, v in per_mode.items()},
        rayleigh=rayleigh,
        matrix=matrix,
    )


def _groups(doc: dict) -> dict[str, str]:
    """``"nonlinear"`` for parameter names used by nonlinear elements (the default group of a
    parameter without an explicit ``group``; all others default to ``"linear"``)."""
    used = {}
    specs = doc.get("nonlinear", [])
    for t in specs if isinstance(specs, list) else ():
        params = t.get("params", {}) if isinstance(t, dict) else {}
        for v in params.values() if isinstance(params, dict) else ():
            if isinstance(v, str):
                used[v] = "nonlinear"
    return used


def parse_document(doc: dict, source: str, *, allow_truth: bool = False) -> dict[str, Any]:
    """Check a parsed TOML document and return the fields of a :class:`~analysis.model.Model`.

    Parameters
    ----------
    doc : dict
        The output of ``tomllib.loads``.
    source : str
        File path (relative linear-part files are found beside it) or ``"<string>"``.
    allow_truth : bool
        Accept a ``[truth]`` table (simulator use only).

    Raises
    ------
    ModelFileError
    """
    r = _Reader(source)
    r.table(doc, "", _TOP_KEYS)
    if "truth" in doc and not allow_truth:
        r.fail(
            "truth",
            "this model file holds the simulated truth; only the simulator may "
            "load it (load_model(..., allow_truth=True))",
        )
    linear = "linear_part" in doc
    if linear and (frame_keys := [k for k in (*_FRAME_KEYS, "supports") if k in doc]):
        r.fail(frame_keys[0], "a model with [linear_part] cannot also define a frame")
    if not linear and "members" not in doc:
        r.fail("members", "missing (or give a [linear_part])")
    base = Path(source).parent if source != "<string>" else Path.cwd()
    dirs = IMPORT_DIRECTIONS if linear else DIRECTIONS
    groups = _groups(doc)
    parameters = {
        n: _parameter(r, n, r.table(t, f"parameters.{n}"), groups.get(n))
        for n, t in r.table(doc.get("parameters", {}), "parameters").items()
    }
    damping = _damping(r, r.table(doc.get("damping", {}), "damping"), base)
    nonlinear = tuple(
        _nonlinear(r, r.table(t, f"nonlinear[{i}]"), f"nonlinear[{i}]", dirs)
        for i, t in enumerate(r.array(doc.get("nonlinear", []), "nonlinear"))
    )
    return {
        "title": r.text(doc.get("title", ""), "title"),
        "parameters": parameters,
        "frame": None if linear else _frame(r, doc),
        "linear_part": _linear_part(r, r.table(doc["linear_part"], "linear_part"), base)
        if linear
        else None,
        "points": _points(r, doc, dirs),
        "nonlinear": nonlinear,
        "damping": damping,
        "truth": r.table(doc["truth"], "truth") if "truth" in doc else None,
        "source": source,
    }


# -- writing -----------------------------------------------------------------------------------
def _section_doc(s: Section) -> dict:
    if s.shape == "rect":
        return {"shape": "rect", "b": s.b_m, "h": s.h_m}
    if s.shape == "rect_tube":
        return {"shape": "rect_tube", "outer": s.outer_m, "wall": s.wall_m}
    return {"A": s.area_m2, "I": s.inertia_m4}


def _frame_doc(f: FrameSpec) -> dict:
    members = []
    for m in f.members:
        t = {"name": m.name, "nodes": list(m.nodes), "section": m.section, "material": m.material}
        if m.elements is not None:
            t["elements"] = m.elements
        else:
            t["max_element_length"] = m.max_element_length_m
        if m.nsm_kg_per_m != 0.0:
            t["nsm"] = m.nsm_kg_per_m
        members.append(t | {"group": m.group})
    doc = {
        "nodes": {n: list(xy) for n, xy in f.nodes.items()},
        "sections": {n: _section_doc(s) for n, s in f.sections.items()},
        "materials": {n: {"E": m.E, "rho": m.rho} for n, m in f.materials.items()},
        "members": members,
        "joints": [
            {"name": j.name, "nodes": list(j.nodes), "x": j.x, "y": j.y, "rz": j.rz}
            for j in f.joints
        ],
        "springs": [
            {"name": s.name, "node": s.node, "direction": s.direction, "k": s.k}
            | ({"to": s.to} if s.to is not None else {})
            for s in f.springs
        ],
        "masses": [
            {"name": m.name, "node": m.node, "m": m.m_kg, "J": m.J_kgm2, "group": m.group}
            for m in f.masses
        ],
        "supports": {n: list(d) for n, d in f.supports.items()},
    }
    return {k: v for k, v in doc.items() if v}


def _relative(path: str, base: Path | None) -> str:
    if base is None:
        return path
    try:
        return Path(path).relative_to(base.resolve()).as_posix()
    except ValueError:
        return path


def _dofref_doc(ref: DofRef, points: dict[int, MeasurementPoint]) -> dict:
    if ref.point is None:
        return {"node": ref.node, "direction": ref.direction}
    t: dict[str, Any] = {"point": ref.point}
    if ref.direction != points[ref.point].direction:
        t["direction"] = ref.direction
    return t


def _parameter_doc(p: Parameter) -> dict:
    t: dict[str, Any] = {"value": p.value, "nominal": p.nominal}
    t |= {k: getattr(p, k) for k in ("lower", "upper") if math.isfinite(getattr(p, k))}
    t |= {"calibrate": p.calibrate, "scaling": p.scaling, "unit": p.unit, "group": p.group}
    t |= {"prior_rel_std": p.prior_rel_std} if p.prior_rel_std is not None else {}
    return t | ({"description": p.description} if p.description else {})


def to_document(model: Any, base: Path | None = None) -> dict:
    """The TOML document (a dict for ``tomli_w``) of a model.

    Parameters
    ----------
    model : Model
    base : Path, optional
        Directory the file is written to; linear-part files are written relative to it
        when they lie below it, else as absolute paths.
    """
    doc: dict[str, Any] = {"title": model.title} if model.title else {}
    if model.frame is not None:
        doc |= _frame_doc(model.frame)
    else:
        lp = model.linear_part
        t: dict[str, Any] = {"format": lp.format}
        files = {k: _relative(v, base) for k, v in lp.files.items()}
        t |= {"file": files["file"]} if lp.format != "mtx" else {"files": files}
        if isinstance(lp.dof_map, str):
            t["dof_map"] = _relative(lp.dof_map, base)
        elif lp.dof_map is not None:
            t["dof_map"] = list(lp.dof_map)
        if lp.masses:
            t["masses"] = dict(lp.masses)
        doc["linear_part"] = t
    doc["points"] = {
        str(n): {"node": p.node, "direction": p.direction}
        | ({"xy": list(p.xy)} if p.xy is not None else {})
        for n, p in model.points.items()
    }
    doc["parameters"] = {n: _parameter_doc(p) for n, p in model.parameters.items()}
    doc["nonlinear"] = [
        {"name": s.name, "kind": s.kind, "at": _dofref_doc(s.at, model.points)}
        | ({"to": _dofref_doc(s.to, model.points)} if s.to is not None else {})
        | {"params": dict(s.params), "options": dict(s.options)}
        for s in model.nonlinear
    ]
    d = model.damping
    if d.rayleigh is not None:
        doc["damping"] = {"rayleigh": {"alpha": d.rayleigh[0], "beta": d.rayleigh[1]}}
    elif isinstance(d.matrix, str):
        doc["damping"] = {"matrix": _relative(d.matrix, base)}
    elif d.matrix is not None:
        doc["damping"] = {"matrix": [list(row) for row in d.matrix]}
    else:
        doc["damping"] = {"default_zeta": d.default_zeta}
    if d.per_mode:
        doc["damping"]["per_mode"] = {str(k): v for k, v in d.per_mode.items()}
    if model.truth is not None:
        doc["truth"] = model.truth
    return {k: v for k, v in doc.items() if v != [] and v != {}}
