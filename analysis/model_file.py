"""The model file (TOML): its record types, parsing with key-path errors, and writing.

The reference example is ``analysis/models/clearance_rig.toml``. Top-level keys:
``title``, ``nodes``, ``sections``, ``materials``, ``members``, ``joints``, ``springs``,
``masses``, ``supports`` (a planar frame) or ``linear_part`` (matrices from another FE code;
``[linear_part.masses]`` adds point masses [kg] to the translational DOFs of a node),
and ``points``, ``parameters``, ``nonlinear``, ``damping``, ``truth`` (simulator only).
Every error names the file, the key path (``members[3].section``) and the problem.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal, NoReturn, TypeVar

from pydantic import Field, PlainSerializer, PlainValidator, Strict

from .fe import DIRECTIONS, FrameSpec, Joint, LumpedMass, Material, Member, Section, Spring
from .fe.values import Coefficient, Finite, finite
from .matrix_io import FORMATS, IMPORT_DIRECTIONS
from .settings import (
    ConfigError,
    Flag,
    Integer,
    KeyPath,
    Number,
    Positive,
    SettingError,
    Text,
    build,
    declare,
    dump,
    settings,
)

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
DAMPING_MODAL = ("default_zeta", "per_mode")
T = TypeVar("T")
_FRAME_ROWS = ("members", "joints", "springs", "masses")
_FRAME_KEYS = ("nodes", "sections", "materials", *_FRAME_ROWS)


class ModelFileError(ConfigError):
    """An invalid model file or model: ``"<source>: <key path>: <problem>"``, with the key path
    as a tuple in :attr:`path` (``("members", 3, "section")``)."""

    def __init__(self, source: str, path: KeyPath, problem: str) -> None:
        super().__init__(source, path, problem)
        if not self.path:  # a problem of the whole file reads "<source>: <problem>"
            ValueError.__init__(self, f"{source}: {problem}")


# Lower and upper bounds may be infinite (no bound), never NaN (checked below).
Bound = Annotated[float, Strict(), Field(allow_inf_nan=True)]


@settings()
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

    name: Text = declare("Name: letters, digits and '_', not 'rigid' or 'free'.")
    value: Number = declare("Current value (in a truth file: the simulated reality).")
    nominal: Number = declare("Value known before any test (the prior's centre).")
    lower: Bound = declare("Lower bound of calibration (-inf: none).", -math.inf)
    upper: Bound = declare("Upper bound of calibration (inf: none).", math.inf)
    calibrate: Flag = declare("Whether calibration adjusts the parameter.", False)
    scaling: Literal["linear", "log"] = declare("Scaling in calibration.", "linear")
    unit: Text = declare("Unit, for people (SI).", "")
    group: Literal["linear", "nonlinear"] = declare(
        "A linear coefficient or a nonlinear element's parameter.", "linear"
    )
    description: Text = declare("What the parameter is, for people.", "")
    prior_rel_std: Positive | None = declare(
        "Prior standard deviation relative to nominal (none: no prior).", None
    )

    def __post_init__(self) -> None:
        if not NAME_RE.match(self.name) or self.name in RESERVED:
            raise SettingError(("name",), f"{self.name!r} is not a valid parameter name")
        for f in ("lower", "upper"):
            if math.isnan(getattr(self, f)):
                raise SettingError((f,), "must be a number, got nan")
        if not self.lower < self.upper:
            raise SettingError(("lower",), f"{self.lower} must be below upper {self.upper}")
        if not self.lower <= self.nominal <= self.upper:
            raise SettingError(
                ("nominal",), f"{self.nominal} is outside [{self.lower}, {self.upper}]"
            )
        if self.scaling == "log" and not (self.lower >= 0 and self.value > 0):
            raise SettingError(("scaling",), "'log' needs lower >= 0 and a positive value")


@settings()
class DofRef:
    """A DOF by measurement point (direction defaults to the point's) or by node and direction.

    A model fills in ``node`` and ``direction`` of point references on construction.
    """

    node: Text | None = declare("Node name.", None)
    direction: Text | None = declare("Direction (the point's if a point is given).", None)
    point: Integer | None = declare("Measurement point number.", None)

    def __post_init__(self) -> None:
        if self.point is None and (self.node is None or self.direction is None):
            raise SettingError((), "give a point, or a node and a direction")

    @property
    def label(self) -> str:
        """``"node/direction"``."""
        return f"{self.node}/{self.direction}"


Coordinate = Annotated[Number, Field(ge=-MAX_COORDINATE_M, le=MAX_COORDINATE_M)]


@settings()
class MeasurementPoint:
    """Measurement point ``number`` at ``node`` measuring ``direction``; ``xy`` in m."""

    number: Annotated[Integer, Field(ge=1)] = declare("Point number.")
    node: Text = declare("Node (empty: the node at xy).")
    direction: Text = declare("Direction measured.")
    xy: tuple[Coordinate, Coordinate] | None = declare(
        "Position [m], checked against the node.", None
    )


@settings()
class NonlinearSpec:
    """A nonlinear element: ``kind`` between DOF ``at`` and ``to`` (``None``: ground).

    ``params`` maps each element parameter to a number or a model parameter name.
    """

    name: Text = declare("Element name, unique in the model.")
    kind: Text = declare("Element kind (the element library's name).")
    at: DofRef = declare("First DOF.")
    to: DofRef | None = declare("Second DOF (none: ground).", None)
    params: dict[str, Coefficient] = Field(
        default_factory=dict, description="Element parameters: numbers or parameter names."
    )
    options: dict[str, Any] = Field(default_factory=dict, description="Element options.")


def _mode_number(value: Any) -> int:
    if isinstance(value, str) and value.isascii() and value.isdigit():
        value = int(value)  # a table key in the file
    elif isinstance(value, numbers.Integral) and not isinstance(value, bool):
        value = int(value)  # a mode number computed with numpy
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise SettingError((), f"mode numbers start at 1, got {value!r}")
    return value


def _rayleigh(value: Any) -> tuple[float, float]:
    if isinstance(value, Mapping):  # the file's {alpha = ..., beta = ...}
        if unknown := sorted(set(value) - {"alpha", "beta"}):
            raise SettingError((unknown[0],), "unknown key; expected alpha or beta")
        named = [(k, value.get(k, 0.0)) for k in ("alpha", "beta")]
    elif isinstance(value, list | tuple) and len(value) == 2:
        named = list(zip(("alpha", "beta"), value, strict=True))
    else:
        raise SettingError((), f"expected a table of alpha and beta, got {value!r}")
    for k, v in named:
        if finite(v, (k,)) < 0:
            raise SettingError((k,), f"must be >= 0, got {v!r}")
    return float(named[0][1]), float(named[1][1])


def _matrix(value: Any) -> tuple[tuple[float, ...], ...] | str:
    if isinstance(value, str):
        if not value.endswith((".npy", ".mtx")):
            raise SettingError((), f"a .npy or .mtx file, got {value!r}")
        return value
    if not isinstance(value, list | tuple):
        raise SettingError((), f"expected an array of rows or a file name, got {value!r}")
    rows = []
    for i, row in enumerate(value):
        if not isinstance(row, list | tuple):
            raise SettingError((i,), f"expected an array, got {row!r}")
        rows.append(tuple(finite(v, (i, j)) for j, v in enumerate(row)))
    if not rows or any(len(row) != len(rows) for row in rows):
        raise SettingError((), "expected a square array of rows")
    return tuple(rows)


Zeta = Annotated[Number, Field(ge=0, lt=1)]
ModeNumber = Annotated[int, PlainValidator(_mode_number)]
Rayleigh = Annotated[
    tuple[float, float],
    PlainValidator(_rayleigh),
    PlainSerializer(lambda ab: {"alpha": ab[0], "beta": ab[1]}),
]
DampingMatrix = Annotated[
    tuple[tuple[float, ...], ...] | str,
    PlainValidator(_matrix),
    PlainSerializer(lambda m: m if isinstance(m, str) else [list(row) for row in m]),
]


@settings()
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

    default_zeta: Zeta = declare("Damping ratio of the modes per_mode does not name.", 0.01)
    per_mode: dict[ModeNumber, Zeta] = Field(
        default_factory=dict, description="Damping ratio of mode n (1-based, by frequency)."
    )
    rayleigh: Rayleigh | None = declare("Rayleigh damping: alpha [1/s] and beta [s].", None)
    matrix: DampingMatrix | None = declare(
        "Viscous damping matrix [N s/m]: rows, or a .npy or .mtx file.", None
    )

    def __post_init__(self) -> None:
        object.__setattr__(self, "per_mode", dict(sorted(self.per_mode.items())))
        if self.rayleigh is not None and self.matrix is not None:
            raise SettingError(("rayleigh",), "give either rayleigh or matrix, not both")

    @property
    def modal(self) -> bool:
        """True for modal damping ratios (neither Rayleigh nor an explicit matrix)."""
        return self.rayleigh is None and self.matrix is None

    def zeta(self, n_modes: int) -> list[float]:
        """Damping ratio of modes 1..n_modes."""
        return [self.per_mode.get(k, self.default_zeta) for k in range(1, n_modes + 1)]


def _format(value: Any) -> str:
    if not isinstance(value, str):
        raise SettingError((), f"expected a string, got {value!r}")
    if value not in FORMATS:
        raise SettingError((), f"unknown format {value!r}; expected one of {FORMATS}")
    return value


def _dof_map(value: Any) -> str | tuple[str, ...]:
    if isinstance(value, str):
        return value
    if not isinstance(value, list | tuple):
        raise SettingError((), f"expected an array, got {type(value).__name__}")
    for label in value:
        if not isinstance(label, str):
            raise SettingError((), f"expected a string, got {label!r}")
    return tuple(value)


MTX_FILES = ("M", "K", "C")


@settings()
class LinearPartSpec:
    """Linear part imported from files: ``format`` and absolute ``files`` (``file`` for one
    archive, ``M``/``K``/``C`` for MatrixMarket) plus a DOF map (file path or labels)."""

    format: Annotated[str, PlainValidator(_format)] = declare(
        f"Format of the matrices: one of {', '.join(FORMATS)}."
    )
    files: dict[str, Text] = Field(
        default_factory=dict, description="The matrix files (the file's 'file' or 'files')."
    )
    dof_map: (
        Annotated[
            str | tuple[str, ...],
            PlainValidator(_dof_map),
            PlainSerializer(lambda m: m if isinstance(m, str) else list(m)),
        ]
        | None
    ) = declare("DOF map: a file name or a list of 'node/direction'.", None)
    masses: dict[str, Finite] = Field(
        default_factory=dict, description="Point masses [kg] at the translational DOFs of nodes."
    )

    def __post_init__(self) -> None:
        if self.format != "mtx":
            if "file" not in self.files:
                raise SettingError(("file",), "missing")
            return
        if unknown := sorted(set(self.files) - set(MTX_FILES)):
            raise SettingError(
                ("files", unknown[0]), f"unknown key; expected one of {sorted(MTX_FILES)}"
            )
        for k in ("M", "K"):
            if k not in self.files:
                raise SettingError(("files", k), "missing")
        if self.dof_map is None:
            raise SettingError(("dof_map",), "missing (a file name or a list of 'node/direction')")


class _Reader:
    """Typed access to the parsed TOML with key-path errors (the tables keyed by name: nodes,
    supports; the records are read through their declared settings, :meth:`build`)."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, path: KeyPath, problem: str) -> NoReturn:
        raise ModelFileError(self.source, path, problem)

    def build(self, cls: type[T], data: Any, path: KeyPath) -> T:
        """The declared settings ``cls`` read from ``data`` at ``path``."""
        return build(cls, data, self.source, at=path, error=ModelFileError)

    def table(self, value: Any, path: KeyPath, allowed: set[str] | None = None) -> dict:
        if not isinstance(value, dict):
            self.fail(path, f"expected a table, got {type(value).__name__}")
        if allowed is not None and (unknown := set(value) - allowed):
            self.fail(
                (*path, sorted(unknown)[0]), f"unknown key; expected one of {sorted(allowed)}"
            )
        return value

    def array(self, value: Any, path: KeyPath) -> list:
        if not isinstance(value, list):
            self.fail(path, f"expected an array, got {type(value).__name__}")
        return value

    def coordinate(self, value: Any, path: KeyPath) -> float:
        try:
            x = finite(value)
        except SettingError as exc:
            self.fail(path, exc.problem)
        if abs(x) > MAX_COORDINATE_M:
            self.fail(path, f"a coordinate [m] within +-{MAX_COORDINATE_M:g}, got {value!r}")
        return x

    def text(self, value: Any, path: KeyPath) -> str:
        if not isinstance(value, str):
            self.fail(path, f"expected a string, got {value!r}")
        return value

    def direction(self, value: Any, path: KeyPath, allowed: tuple[str, ...] = DIRECTIONS) -> str:
        if value not in allowed:
            self.fail(path, f"bad direction {value!r}; expected one of {allowed}")
        return value


def _nodes(r: _Reader, doc: dict) -> dict[str, tuple[float, ...]]:
    nodes = {}
    for name, xy in r.table(doc.get("nodes", {}), ("nodes",)).items():
        if not NODE_RE.match(name):
            r.fail(("nodes", name), "node names use letters, digits, '_', '.', '-'")
        xy = r.array(xy, ("nodes", name))
        if len(xy) != 2:
            r.fail(("nodes", name), f"expected [x, y] in m, got {xy!r}")
        nodes[name] = tuple(r.coordinate(v, ("nodes", name, k)) for k, v in enumerate(xy))
    return nodes


def _rows(r: _Reader, doc: dict, key: str) -> list[tuple[KeyPath, dict]]:
    """The tables of the array ``key`` with their key paths."""
    rows = r.array(doc.get(key, []), (key,))
    return [((key, i), r.table(t, (key, i))) for i, t in enumerate(rows)]


def _records(r: _Reader, doc: dict, key: str, cls: type[T], name: str) -> tuple[T, ...]:
    """The records of the array ``key``; a record without a name is called ``<name><index>``."""
    return tuple(r.build(cls, {"name": f"{name}{p[1]}", **t}, p) for p, t in _rows(r, doc, key))


def _frame(r: _Reader, doc: dict) -> FrameSpec:
    sections, materials = (
        {n: r.build(cls, t, (key, n)) for n, t in r.table(doc.get(key, {}), (key,)).items()}
        for key, cls in (("sections", Section), ("materials", Material))
    )
    supports = {}
    for node, dirs in r.table(doc.get("supports", {}), ("supports",)).items():
        dirs = list(DIRECTIONS) if dirs == "all" else r.array(dirs, ("supports", node))
        supports[node] = tuple(r.direction(d, ("supports", node, k)) for k, d in enumerate(dirs))
    return FrameSpec(
        nodes=_nodes(r, doc),
        sections=sections,
        materials=materials,
        members=_records(r, doc, "members", Member, "m"),
        joints=_records(r, doc, "joints", Joint, "joint"),
        springs=_records(r, doc, "springs", Spring, "spring"),
        masses=_records(r, doc, "masses", LumpedMass, "mass"),
        supports=supports,
    )


def _parameter(r: _Reader, name: str, t: dict, group: str | None) -> Parameter:
    """The file's shorthands: ``value`` and ``nominal`` default to each other, ``group`` to
    the use of the parameter, ``lower`` to 0 under ``log`` scaling."""
    p = ("parameters", name)
    if "name" in t:
        r.fail((*p, "name"), "unknown key (the table's name is the parameter's)")
    if "value" not in t and "nominal" not in t:
        r.fail(p, "give a value or a nominal value")
    data = {"name": name, "group": group or "linear", **t}
    data.setdefault("value", t.get("nominal"))
    data.setdefault("nominal", t.get("value"))
    if t.get("scaling") == "log":
        data.setdefault("lower", 0.0)
    return r.build(Parameter, data, p)


def _nonlinear(r: _Reader, t: dict, path: KeyPath, dirs: tuple[str, ...]) -> NonlinearSpec:
    spec = r.build(NonlinearSpec, t, path)
    for key, ref in (("at", spec.at), ("to", spec.to)):
        if ref is None:
            continue
        if ref.direction is not None:
            r.direction(ref.direction, (*path, key, "direction"), dirs)
        if ref.point is not None and ref.node is not None:
            r.fail((*path, key), "give either a point or a node, not both")
    return spec


def _points(r: _Reader, doc: dict, dirs: tuple[str, ...]) -> dict[int, MeasurementPoint]:
    points = {}
    for key, t in r.table(doc.get("points", {}), ("points",)).items():
        p = ("points", key)
        if not (key.isascii() and key.isdigit()) or int(key) < 1:
            r.fail(p, "point numbers are positive integers")
        if "node" not in r.table(t, p) and t.get("xy") is None:
            r.fail(p, "give a node or xy")
        if "number" in t:
            r.fail((*p, "number"), "unknown key (the table's name is the point's number)")
        point = r.build(MeasurementPoint, {"node": "", **t, "number": int(key)}, p)
        r.direction(point.direction, (*p, "direction"), dirs)
        points[point.number] = point
    return dict(sorted(points.items()))


def _linear_part(r: _Reader, t: dict, base: Path) -> LinearPartSpec:
    """The file's ``file`` is ``files = {file = ...}`` of an archive; relative file names are
    found beside the model file."""
    data = {k: v for k, v in t.items() if k != "file"}
    if t.get("format") != "mtx":
        data["files"] = {"file": t["file"]} if "file" in t else {}
    try:
        spec = r.build(LinearPartSpec, data, ("linear_part",))
    except ModelFileError as exc:
        if exc.path[:3] == ("linear_part", "files", "file"):  # the file's key is 'file'
            r.fail(("linear_part", "file"), exc.problem)
        raise
    dof_map = spec.dof_map
    return dataclasses.replace(
        spec,
        files={k: str((base / v).resolve()) for k, v in spec.files.items()},
        dof_map=str((base / dof_map).resolve()) if isinstance(dof_map, str) else dof_map,
    )


def _damping(r: _Reader, t: dict, base: Path) -> DampingSpec:
    if ("rayleigh" in t or "matrix" in t) and (modal := [k for k in t if k in DAMPING_MODAL]):
        other = "rayleigh" if "rayleigh" in t else "matrix"
        r.fail(
            ("damping", modal[0]), f"modal damping ratios and damping.{other} exclude each other"
        )
    data = dict(t)
    matrix = data.get("matrix")
    if isinstance(matrix, str) and matrix.endswith((".npy", ".mtx")):
        data["matrix"] = str((base / matrix).resolve())
    return r.build(DampingSpec, data, ("damping",))


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
    r.table(doc, (), _TOP_KEYS)
    if "truth" in doc and not allow_truth:
        r.fail(
            ("truth",),
            "this model file holds the simulated truth; only the simulator may "
            "load it (load_model(..., allow_truth=True))",
        )
    linear = "linear_part" in doc
    if linear and (frame_keys := [k for k in (*_FRAME_KEYS, "supports") if k in doc]):
        r.fail((frame_keys[0],), "a model with [linear_part] cannot also define a frame")
    if not linear and "members" not in doc:
        r.fail(("members",), "missing (or give a [linear_part])")
    base = Path(source).parent if source != "<string>" else Path.cwd()
    dirs = IMPORT_DIRECTIONS if linear else DIRECTIONS
    groups = _groups(doc)
    parameters = {
        n: _parameter(r, n, r.table(t, ("parameters", n)), groups.get(n))
        for n, t in r.table(doc.get("parameters", {}), ("parameters",)).items()
    }
    damping = _damping(r, r.table(doc.get("damping", {}), ("damping",)), base)
    nonlinear = tuple(_nonlinear(r, t, p, dirs) for p, t in _rows(r, doc, "nonlinear"))
    return {
        "title": r.text(doc.get("title", ""), ("title",)),
        "parameters": parameters,
        "frame": None if linear else _frame(r, doc),
        "linear_part": _linear_part(r, r.table(doc["linear_part"], ("linear_part",)), base)
        if linear
        else None,
        "points": _points(r, doc, dirs),
        "nonlinear": nonlinear,
        "damping": damping,
        "truth": r.table(doc["truth"], ("truth",)) if "truth" in doc else None,
        "source": source,
    }


# -- writing -----------------------------------------------------------------------------------
# Every record is written as its declared dump (the file keys come from the declarations), less
# what a reader supplies when a key is absent: unset optionals and declared defaults (infinite
# bounds among them). What remains here is what the declarations cannot say.


def _record(value: Any, exclude: set[str] | None = None) -> dict[str, Any]:
    return dump(value, exclude_defaults=True, exclude=exclude)


def _section(s: Section) -> dict[str, Any]:
    """A section of a given shape without its area and second moment, computed on reading."""
    return _record(s, None if s.shape == "general" else {"area_m2", "inertia_m4"})


def _frame_doc(f: FrameSpec) -> dict:
    doc = {
        "nodes": {n: list(xy) for n, xy in f.nodes.items()},
        "sections": {n: _section(s) for n, s in f.sections.items()},
        "materials": {n: _record(m) for n, m in f.materials.items()},
        **{key: [_record(r) for r in getattr(f, key)] for key in _FRAME_ROWS},
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
    """A point reference as the point (its direction only where it is not the point's)."""
    if ref.point is None:
        return _record(ref)
    same = ref.direction == points[ref.point].direction
    return _record(DofRef(point=ref.point, direction=None if same else ref.direction))


def _linear_part_doc(lp: LinearPartSpec, base: Path | None) -> dict:
    """The file names relative to ``base``; an archive's one file under the file's ``file``."""
    t = _record(lp)
    files = {k: _relative(v, base) for k, v in t.pop("files").items()}
    t = {"format": t.pop("format")} | (files if lp.format != "mtx" else {"files": files}) | t
    if isinstance(lp.dof_map, str):
        t["dof_map"] = _relative(lp.dof_map, base)
    return t


def to_document(model: Any, base: Path | None = None) -> dict:
    """The TOML document (a dict for ``tomli_w``) of a model.

    Parameters
    ----------
    model : Model
    base : Path, optional
        Directory the file is written to; linear-part and damping-matrix files are written
        relative to it when they lie below it, else as absolute paths.
    """
    doc: dict[str, Any] = {"title": model.title} if model.title else {}
    if model.frame is not None:
        doc |= _frame_doc(model.frame)
    else:
        doc["linear_part"] = _linear_part_doc(model.linear_part, base)
    doc["points"] = {str(n): _record(p, {"number"}) for n, p in model.points.items()}
    # a group left out is "linear", as the reader assumes for a parameter no element uses
    doc["parameters"] = {n: _record(p, {"name"}) for n, p in model.parameters.items()}
    doc["nonlinear"] = [
        _record(s)
        | {
            k: _dofref_doc(r, model.points)
            for k, r in (("at", s.at), ("to", s.to))
            if r is not None
        }
        for s in model.nonlinear
    ]
    doc["damping"] = _record(model.damping)
    if isinstance(model.damping.matrix, str):
        doc["damping"]["matrix"] = _relative(model.damping.matrix, base)
    if model.truth is not None:
        doc["truth"] = model.truth
    return {k: v for k, v in doc.items() if v != [] and v != {}}
