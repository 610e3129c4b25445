"""The structural model: load a model file, change parameters, assemble M and K.

>>> from analysis.model import load_model
>>> model = load_model()                       # the reference rig
>>> asm = model.with_values({"E_beam": 201e9}).assemble()
>>> asm.K.shape == asm.dK["E_beam"].shape
True

A :class:`Model` is immutable; every ``with_*`` method returns a new model. Models derived
by ``with_values``, ``with_damping`` or ``with_nonlinear`` share the meshed structure and a
small cache of assemblies keyed by the linear parameter values.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import pickle
import re
import tomllib
import warnings
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from .fe import FrameSpec, LinearStructure, LumpedMass, SpecError, build_structure
from .matrix_io import LinearPart, import_linear
from .model_file import (
    DampingSpec,
    DofRef,
    LinearPartSpec,
    MeasurementPoint,
    ModelFileError,
    NonlinearSpec,
    Parameter,
    parse_document,
    to_document,
)
from .settings import KeyPath, dotted

__all__ = [
    "REFERENCE_RIG",
    "Assembly",
    "DampingSpec",
    "DofRef",
    "MeasurementPoint",
    "Model",
    "ModelFileError",
    "NonlinearSpec",
    "Parameter",
    "ParameterBoundsWarning",
    "load_model",
]

log = logging.getLogger(__name__)


class ParameterBoundsWarning(UserWarning):
    """A model file gives a parameter a value outside its calibration bounds."""


REFERENCE_RIG = Path(__file__).parent / "models" / "clearance_rig.toml"
_CACHE_SIZE = 16


@dataclass(frozen=True)
class Assembly:
    """Mass and stiffness over the free DOFs at one set of parameter values.

    Attributes
    ----------
    M, K : ndarray, shape (n, n), float64, read-only
        Mass [kg, kg m^2] and stiffness [N/m, N m/rad] after ties and supports.
    dofs : tuple of (node, direction), length n
        Label of each free DOF (a tied DOF carries the first node of its joint).
    dM, dK : dict of str to ndarray, shape (n, n), read-only
        Exact derivatives with respect to every linear-group parameter (zeros where a
        parameter does not enter), per parameter unit.
    C : ndarray, shape (n, n), N s/m, or None
        Viscous damping, only for an imported linear part that provides it.
    node_xy : dict of str to (float, float)
        Node coordinates [m] where known.
    """

    M: np.ndarray
    K: np.ndarray
    dofs: tuple[tuple[str, str], ...]
    dM: dict[str, np.ndarray]
    dK: dict[str, np.ndarray]
    C: np.ndarray | None = None
    node_xy: dict[str, tuple[float, float]] = field(default_factory=dict)
    _index: Mapping[tuple[str, str], int] = field(default_factory=dict, repr=False)
    _points: Mapping[int, MeasurementPoint] = field(default_factory=dict, repr=False)
    _masses: Mapping[str, float] = field(default_factory=dict, repr=False)
    _group_mass: Any = field(default=None, repr=False, compare=False)

    @property
    def n_dofs(self) -> int:
        """Number of free DOFs."""
        return len(self.dofs)

    def dof_index(self, node: str, direction: str) -> int:
        """Index of the free DOF ``(node, direction)`` (tied DOFs map to the shared one)."""
        try:
            return self._index[(node, direction)]
        except KeyError:
            raise KeyError(f"no free DOF {node}/{direction} (unknown or supported)") from None

    def point_dof(self, point: int, direction: str | None = None) -> int:
        """Index of measurement point ``point``'s DOF (default: the point's own direction)."""
        if point not in self._points:
            raise KeyError(f"unknown measurement point {point}; known: {sorted(self._points)}")
        p = self._points[point]
        return self.dof_index(p.node, direction or p.direction)

    def mass_report(self) -> dict[str, float]:
        """Translational mass [kg] by group, with ``"sensors"`` and ``"total"``."""
        return dict(self._masses)

    def group_mass_matrix(self, groups: str | Sequence[str]) -> np.ndarray:
        """Mass matrix (shape (n, n), kg) of the given mass groups only (frame models).

        Groups are the member ``group`` names and lumped-mass groups (``"sensors"`` for
        sensor masses); e.g. the kinetic energy share of the beam in mode ``phi`` is
        ``phi @ group_mass_matrix(["beam", "clamp"]) @ phi / (phi @ M @ phi)``.
        """
        if self._group_mass is None:
            raise ValueError("group mass matrices need a frame model (not an imported part)")
        return self._group_mass({groups} if isinstance(groups, str) else set(groups))

    def normal_modes(self, n_modes: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Undamped natural frequencies and mass-normalised modes.

        Returns
        -------
        frequency_hz : ndarray, shape (m,), Hz
            Ascending; tiny negative eigenvalues of rigid-body modes give 0.
        phi : ndarray, shape (n, m)
            ``phi.T @ M @ phi = I``.
        """
        import scipy.linalg as sla

        sub = None if n_modes is None else (0, min(n_modes, self.n_dofs) - 1)
        lam, phi = sla.eigh(self.K, self.M, subset_by_index=sub)
        return np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi), phi


def _key_of(spec: NonlinearSpec, i: int, name: str) -> KeyPath:
    """Where ``nonlinear[i]`` gives the element parameter or option ``name`` (the element as
    a whole if it gives neither: a missing parameter)."""
    for key in ("params", "options"):
        if name in getattr(spec, key):
            return ("nonlinear", i, key, name)
    return ("nonlinear", i)


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@functools.lru_cache(maxsize=8)
def _structure_of(frame: bytes) -> LinearStructure:
    """The structure of a pickled frame. A stepped-sine predictor or a linear calibration adds
    its file's sensor masses to the model it is given (a new frame) each time it is made, and
    a diagnosis makes hundreds of them from a few models: equal frames pickle to equal bytes
    and share one structure (its forms are read-only)."""
    return build_structure(pickle.loads(frame))  # noqa: S301 -- bytes pickled in this process


class _Shared:
    """Structure and assemblies shared by models that differ only in values or elements."""

    def __init__(self) -> None:
        self.structure: LinearStructure | None = None
        self.part: LinearPart | None = None
        self.assemblies: OrderedDict[tuple, Assembly] = OrderedDict()


@dataclass(frozen=True)
class Model:
    """A planar frame (or imported linear part) with measurement points, parameters, modal
    damping and nonlinear elements. Construct with :func:`load_model` or
    :meth:`Model.from_toml_text`; all fields are validated on construction.

    Attributes
    ----------
    parameters : dict of str to Parameter
    points : dict of int to MeasurementPoint
    nonlinear : tuple of NonlinearSpec
    damping : DampingSpec
    frame : FrameSpec or None
    linear_part : LinearPartSpec or None
    truth : dict or None
        The simulator's truth table (only with ``allow_truth=True``).
    title : str
    source : str
        File the model was read from, or ``"<string>"``.
    """

    parameters: dict[str, Parameter]
    points: dict[int, MeasurementPoint]
    nonlinear: tuple[NonlinearSpec, ...] = ()
    damping: DampingSpec = field(default_factory=DampingSpec)
    frame: FrameSpec | None = None
    linear_part: LinearPartSpec | None = None
    truth: dict | None = None
    title: str = ""
    source: str = field(default="<string>", compare=False)
    _shared: _Shared = field(default_factory=_Shared, compare=False, repr=False)

    def __post_init__(self) -> None:
        try:
            self._validate()
        except SpecError as exc:
            raise ModelFileError(self.source, exc.path, exc.problem) from None

    # -- construction and validation -----------------------------------------------------
    @classmethod
    def from_toml_text(
        cls, text: str, source: str = "<string>", *, allow_truth: bool = False
    ) -> Model:
        """Parse a model file's text (``source`` names it in errors; see :func:`load_model`)."""
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ModelFileError(source, (), f"invalid TOML: {exc}") from None
        try:
            model = cls(**parse_document(doc, source, allow_truth=allow_truth))
        except (ArithmeticError, np.linalg.LinAlgError) as exc:
            raise ModelFileError(
                source,
                (),
                f"the model cannot be built ({type(exc).__name__}: {exc}); check "
                "for extreme values (coordinates, sections, materials, springs)",
            ) from None
        model.check_elements()
        if not model.damping.modal:
            model.damping_matrices()  # a wrong size or an unreadable file is told on loading
        model.warn_out_of_bounds()
        return model

    def check_elements(self) -> None:
        """Build every nonlinear element once at the current values, so that an unknown kind, an
        unknown or missing element parameter, a bad option or a value the element refuses (a
        negative ``k_c``) is reported when the file is loaded, not at the first simulation.

        Raises
        ------
        ModelFileError
            Naming ``nonlinear[i].kind``, ``nonlinear[i].params.<name>`` (and the model
            parameter it refers to) or ``nonlinear[i]``.
        """
        values = self.values()
        for i, spec in enumerate(self.nonlinear):
            try:
                self.build_elements_of((spec,))
            except ModelFileError as exc:
                # the element was built alone, as nonlinear[0]: name its index in the model
                path, problem = ("nonlinear", i, *exc.path[2:]), exc.problem
                if path[2:3] == ("params",) and isinstance(ref := spec.params[str(path[3])], str):
                    problem = f"{problem} (parameters.{ref}.value = {values[ref]!r})"
                raise ModelFileError(self.source, path, problem) from None

    def warn_out_of_bounds(self) -> list[str]:
        """Warn (:class:`ParameterBoundsWarning`) for every parameter whose value lies outside
        its ``lower``/``upper`` bounds: allowed (a calibrated value may be given), but said.

        Returns
        -------
        list of str
            The warnings issued.
        """
        out = []
        for name, p in self.parameters.items():
            if not p.lower <= p.value <= p.upper:
                text = (
                    f"{self.source}: parameters.{name}.value: {p.value!r} is outside its bounds "
                    f"[{p.lower!r}, {p.upper!r}]"
                )
                warnings.warn(text, ParameterBoundsWarning, stacklevel=3)
                log.warning("%s", text)
                out.append(text)
        return out

    def _validate(self) -> None:
        object.__setattr__(self, "parameters", dict(self.parameters))
        if (self.frame is None) == (self.linear_part is None):
            raise SpecError((), "a model needs exactly one of a frame and a linear part")
        for name, p in self.parameters.items():
            if name != p.name:
                raise SpecError(("parameters", name), f"holds parameter {p.name!r}")
        if self.frame is not None:
            self._check_coefficients()
        index, node_xy = self._dof_map()
        nodes = {n for n, _ in index}
        object.__setattr__(
            self,
            "points",
            {n: self._point(p, index, nodes, node_xy) for n, p in sorted(self.points.items())},
        )
        names = [s.name for s in self.nonlinear]
        if dup := {n for n in names if names.count(n) > 1}:
            raise SpecError(("nonlinear",), f"duplicate element name(s) {sorted(dup)}")
        object.__setattr__(
            self,
            "nonlinear",
            tuple(self._check_spec(i, s, index) for i, s in enumerate(self.nonlinear)),
        )

    def _use(self, path: KeyPath, name: str, group: str) -> Parameter:
        if name not in self.parameters:
            raise SpecError(path, f"unknown parameter {name!r}")
        p = self.parameters[name]
        if p.group != group:
            raise SpecError(path, f"parameter {name!r} is in group {p.group!r}, not {group!r}")
        return p

    def _check_coefficients(self) -> None:
        for path, coef, positive in self.frame.coefficient_uses():
            if isinstance(coef, str):
                p = self._use(path, coef, "linear")
                if p.value < 0 or (positive and p.value == 0):
                    raise SpecError(
                        ("parameters", coef, "value"),
                        f"{p.value!r} used by {dotted(path)} must be "
                        f"{'> 0' if positive else '>= 0'}",
                    )

    def _dof_map(self) -> tuple[Mapping, Mapping]:
        if self.frame is not None:
            if self._shared.structure is None:
                self._shared.structure = _structure_of(pickle.dumps(self.frame))
            return self._shared.structure.index, self._shared.structure.node_xy
        if self._shared.part is None:
            self._shared.part = _load_part(self.linear_part)
        part = self._shared.part
        for node, m in self.linear_part.masses.items():
            if not any(n == node for n, _ in part.dofs):
                raise SpecError(("linear_part", "masses", node), "unknown node")
            if not (math.isfinite(m) and m >= 0):
                raise SpecError(("linear_part", "masses", node), f"must be >= 0, got {m!r}")
        return {d: i for i, d in enumerate(part.dofs)}, part.node_xy

    def _point(
        self, p: MeasurementPoint, index: Mapping, nodes: set, node_xy: Mapping
    ) -> MeasurementPoint:
        path = ("points", str(p.number))  # a table key in the file
        node = p.node
        if not node:
            hits = [n for n, xy in node_xy.items() if math.dist(xy, p.xy) <= 1e-6]
            if not hits:
                raise SpecError((*path, "xy"), f"{list(p.xy)} lies on no node")
            if len(hits) > 1:
                raise SpecError((*path, "xy"), f"coincident nodes {hits} here; name the node")
            node = hits[0]
        elif node not in nodes and node not in node_xy:
            raise SpecError((*path, "node"), f"unknown node {node!r}")
        xy = node_xy.get(node)
        if p.xy is not None and xy is not None and math.dist(xy, p.xy) > 1e-6:
            raise SpecError((*path, "xy"), f"{list(p.xy)} is not at node {node!r} {list(xy)}")
        if (node, p.direction) not in index:
            raise SpecError(path, f"DOF {node}/{p.direction} is not a free DOF of the model")
        xy = xy if xy is not None else p.xy
        return dataclasses.replace(p, node=node, xy=None if xy is None else tuple(xy))

    def _ref(self, path: KeyPath, ref: DofRef, index: Mapping) -> DofRef:
        node, direction = ref.node, ref.direction
        if ref.point is not None:
            if ref.point not in self.points:
                raise SpecError((*path, "point"), f"unknown measurement point {ref.point}")
            node, direction = (
                self.points[ref.point].node,
                direction or self.points[ref.point].direction,
            )
        if (node, direction) not in index:
            raise SpecError(path, f"DOF {node}/{direction} is not a free DOF of the model")
        return DofRef(node=node, direction=direction, point=ref.point)

    def _check_spec(self, i: int, spec: NonlinearSpec, index: Mapping) -> NonlinearSpec:
        path = ("nonlinear", i)
        at = self._ref((*path, "at"), spec.at, index)
        to = None if spec.to is None else self._ref((*path, "to"), spec.to, index)
        for k, v in spec.params.items():
            if isinstance(v, str):  # numbers were checked by NonlinearSpec's declaration
                self._use((*path, "params", k), v, "nonlinear")
        return dataclasses.replace(
            spec, at=at, to=to, params=dict(spec.params), options=dict(spec.options)
        )

    @property
    def structure(self) -> LinearStructure | None:
        """The meshed frame (affine M and K forms, element counts), or None for a linear part."""
        return self._shared.structure

    # -- parameters ----------------------------------------------------------------------
    def values(self) -> dict[str, float]:
        """Current value of every parameter."""
        return {n: p.value for n, p in self.parameters.items()}

    def parameter_names(self, group: str | None = None, calibrate: bool | None = None) -> list[str]:
        """Names of the parameters, optionally of one group and/or calibration flag."""
        return [
            n
            for n, p in self.parameters.items()
            if (group is None or p.group == group)
            and (calibrate is None or p.calibrate == calibrate)
        ]

    def with_values(self, values: Mapping[str, float]) -> Model:
        """Copy with some parameter values replaced; unknown names raise ``ValueError``."""
        unknown = sorted(set(values) - set(self.parameters))
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}; known: {sorted(self.parameters)}")
        params = dict(self.parameters)
        for n, v in values.items():
            try:
                params[n] = dataclasses.replace(params[n], value=float(v))
            except ValueError as exc:
                raise ValueError(f"parameter {n!r}: {exc}") from None
        return dataclasses.replace(self, parameters=params, _shared=self._shared)

    # -- nonlinear elements and damping --------------------------------------------------
    def with_nonlinear(
        self, spec: NonlinearSpec, new_parameters: Sequence[Parameter] = ()
    ) -> Model:
        """Copy with element ``spec`` added (or replacing the element of the same name).

        ``new_parameters`` are added to the model (a name already defined differently raises
        ``ValueError``); those used by ``spec`` are put in group ``"nonlinear"``.
        """
        params = dict(self.parameters)
        used = {v for v in spec.params.values() if isinstance(v, str)}
        for p in new_parameters:
            if p.name in used:
                p = dataclasses.replace(p, group="nonlinear")
            if p.name in params and params[p.name] != p:
                raise ValueError(f"parameter {p.name!r} already exists with another definition")
            params[p.name] = p
        specs = [s for s in self.nonlinear if s.name != spec.name]
        position = next((i for i, s in enumerate(self.nonlinear) if s.name == spec.name), None)
        specs.insert(len(specs) if position is None else position, spec)
        return dataclasses.replace(
            self, parameters=params, nonlinear=tuple(specs), _shared=self._shared
        )

    def without_nonlinear(self, name: str) -> Model:
        """Copy without the element ``name`` (its parameters stay)."""
        if name not in {s.name for s in self.nonlinear}:
            raise ValueError(f"no nonlinear element {name!r}")
        specs = tuple(s for s in self.nonlinear if s.name != name)
        return dataclasses.replace(self, nonlinear=specs, _shared=self._shared)

    def build_elements(self) -> list[tuple[NonlinearSpec, Any]]:
        """Element objects with parameters resolved from the current values.

        Raises
        ------
        ModelFileError
            Naming ``nonlinear[i]`` for an unknown kind or bad parameters or options.
        """
        return self.build_elements_of(self.nonlinear)

    def build_elements_of(self, specs) -> list[tuple[NonlinearSpec, Any]]:
        """:meth:`build_elements` for the given specs (errors name their index in ``specs``)."""
        import analysis.elements  # noqa: F401  (importing the library fills the registry)

        from .elements import ELEMENT_TYPES, make_element
        from .elements.base import ElementParameterError

        values = self.values()
        out = []
        for i, spec in enumerate(specs):
            if spec.kind not in ELEMENT_TYPES:
                raise ModelFileError(
                    self.source,
                    ("nonlinear", i, "kind"),
                    f"unknown element kind {spec.kind!r}; known: {sorted(ELEMENT_TYPES)}",
                )
            kw = {k: values[v] if isinstance(v, str) else v for k, v in spec.params.items()}
            try:
                out.append((spec, make_element(spec.kind, **kw, **spec.options)))
            except ElementParameterError as exc:
                raise ModelFileError(
                    self.source, _key_of(spec, i, exc.parameter), str(exc)
                ) from None
            except (TypeError, ValueError) as exc:
                raise ModelFileError(self.source, ("nonlinear", i), str(exc)) from None
        return out

    def with_damping(self, damping: DampingSpec) -> Model:
        """Copy with another modal damping."""
        return dataclasses.replace(self, damping=damping, _shared=self._shared)

    # -- masses --------------------------------------------------------------------------
    def add_masses(self, masses: Mapping[int, float]) -> Model:
        """Copy with sensor masses [kg] at measurement points (translational x and y).

        They form the mass group ``"sensors"``.
        """
        for n, m in masses.items():
            if n not in self.points:
                raise ValueError(f"unknown measurement point {n}; known: {sorted(self.points)}")
            if not (math.isfinite(m) and m >= 0):
                raise ValueError(f"sensor mass at point {n}: must be >= 0 kg, got {m!r}")
        if self.linear_part is not None:
            added = dict(self.linear_part.masses)
            for n, m in masses.items():
                added[self.points[n].node] = added.get(self.points[n].node, 0.0) + float(m)
            lp = dataclasses.replace(self.linear_part, masses=added)
            shared = _Shared()
            shared.part = self._shared.part
            return dataclasses.replace(self, linear_part=lp, _shared=shared)
        names = {lm.name for lm in self.frame.masses}
        extra = []
        for n, m in masses.items():
            name = f"sensor_{n}"
            while name in names:
                name += "_"
            names.add(name)
            extra.append(LumpedMass(name, self.points[n].node, float(m), 0.0, "sensors"))
        frame = dataclasses.replace(self.frame, masses=self.frame.masses + tuple(extra))
        return dataclasses.replace(self, frame=frame, _shared=_Shared())

    # -- assembly ------------------------------------------------------------------------
    def damping_matrices(self) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
        """Viscous damping ``C`` [N s/m] over the free DOFs and its derivatives per linear
        parameter, from ``damping.rayleigh`` or ``damping.matrix``; None for modal damping.

        Raises
        ------
        ModelFileError
            Naming ``damping.matrix`` (wrong size, unreadable file, non-finite entries) or
            ``damping`` (a linear part that brings its own C as well).
        """
        d = self.damping
        if d.modal:
            return None
        asm = self.assemble()
        if asm.C is not None:
            raise ModelFileError(
                self.source,
                ("damping",),
                "the linear part brings its own C matrix; drop "
                "damping.rayleigh / damping.matrix or the linear part's C",
            )
        if d.rayleigh is not None:
            alpha, beta = d.rayleigh
            dC = {n: alpha * asm.dM[n] + beta * asm.dK[n] for n in asm.dM}
            return alpha * asm.M + beta * asm.K, dC
        C = self._damping_matrix_values(asm.n_dofs)
        return C, {n: np.zeros_like(C) for n in asm.dM}

    def _damping_matrix_values(self, n: int) -> np.ndarray:
        src = self.damping.matrix
        try:
            if isinstance(src, str):
                if src.endswith(".npy"):
                    C = np.load(src, allow_pickle=False)
                else:
                    import scipy.io

                    C = scipy.io.mmread(src)
                    C = C.toarray() if hasattr(C, "toarray") else C
            else:
                C = src
            C = np.array(C, dtype=float)
        except (OSError, ValueError) as exc:
            raise ModelFileError(self.source, ("damping", "matrix"), str(exc)) from None
        if C.shape != (n, n):
            raise ModelFileError(
                self.source,
                ("damping", "matrix"),
                f"expected {n} x {n} (the model's free DOFs, "
                f"in the order of Model.assemble().dofs), got {' x '.join(map(str, C.shape))}",
            )
        if not np.all(np.isfinite(C)):
            raise ModelFileError(self.source, ("damping", "matrix"), "has non-finite entries")
        return C

    def assemble(self) -> Assembly:
        """M, K and their exact derivatives at the current values (cached per values)."""
        linear = self.parameter_names(group="linear")
        key = tuple((n, self.parameters[n].value) for n in linear)
        cache = self._shared.assemblies
        if key in cache:
            cache.move_to_end(key)
            return cache[key]
        asm = (
            self._assemble_frame(linear) if self.frame is not None else self._assemble_part(linear)
        )
        cache[key] = asm
        if len(cache) > _CACHE_SIZE:
            cache.popitem(last=False)
        return asm

    def _assemble_frame(self, linear: list[str]) -> Assembly:
        s, values = self._shared.structure, self.values()
        return Assembly(
            M=_readonly(s.matrix("M", values)),
            K=_readonly(s.matrix("K", values)),
            dofs=s.dofs,
            dM={n: s.derivative("M", n) for n in linear},
            dK={n: s.derivative("K", n) for n in linear},
            node_xy=dict(s.node_xy),
            _index=s.index,
            _points=self.points,
            _masses=s.mass_report(values),
            _group_mass=lambda groups: s.group_mass_matrix(values, groups),
        )

    def _assemble_part(self, linear: list[str]) -> Assembly:
        part = self._shared.part
        index = {d: i for i, d in enumerate(part.dofs)}
        M = np.array(part.M)
        r = np.array([d == "x" for _, d in part.dofs], dtype=float)
        report = {"linear part": float(r @ M @ r)}
        sensors = 0.0
        for node, m in self.linear_part.masses.items():
            for d in ("x", "y", "z"):
                if (node, d) in index:
                    M[index[(node, d)], index[(node, d)]] += m
            sensors += m
        report |= {"sensors": sensors, "total": report["linear part"] + sensors}
        zeros = _readonly(np.zeros_like(M))
        return Assembly(
            M=_readonly(M),
            K=part.K,
            dofs=part.dofs,
            dM={n: zeros for n in linear},
            dK={n: zeros for n in linear},
            C=part.C,
            node_xy=dict(part.node_xy),
            _index=index,
            _points=self.points,
            _masses=report,
        )

    # -- writing -------------------------------------------------------------------------
    def to_toml(self) -> str:
        """The model as model-file text (linear-part files as absolute paths)."""
        return self._toml(None)

    def _toml(self, base: Path | None) -> str:
        head = f"# Model file written by analysis.model from {self.source}\n\n"
        text = tomli_w.dumps(to_document(self, base))
        return head + _SHORT_ARRAY.sub(_join_array, text)

    def save(self, path: str | Path) -> Path:
        """Write the model file; :func:`load_model` reads it back to an equal model."""
        path = Path(path)
        path.write_text(self._toml(path.parent))
        log.info("model written to %s", path)
        return path


_SHORT_ARRAY = re.compile(r"= \[\n((?:    [^\n\[\]{}]+,\n){1,3})\]")


def _join_array(match: re.Match) -> str:
    """One-line form of a short array of scalars (tomli_w writes one item per line)."""
    items = [line.strip().rstrip(",") for line in match.group(1).splitlines()]
    return f"= [{', '.join(items)}]"


def _load_part(spec: LinearPartSpec) -> LinearPart:
    files = spec.files.get("file") or dict(spec.files)
    inline = spec.dof_map if isinstance(spec.dof_map, tuple) else None
    dof_map = spec.dof_map if isinstance(spec.dof_map, str) else None
    try:
        return import_linear(files, spec.format, dof_map=dof_map, dofs=inline)
    except (OSError, ValueError, KeyError) as exc:
        raise SpecError(("linear_part",), str(exc)) from None


def load_model(path: str | Path | None = None, *, allow_truth: bool = False) -> Model:
    """Read a model file.

    Parameters
    ----------
    path : str or Path, optional
        The TOML model file; ``None`` loads the shipped reference rig
        (``analysis/models/clearance_rig.toml``).
    allow_truth : bool
        Accept a ``[truth]`` table (for the simulator only); it is then ``Model.truth``.

    Raises
    ------
    ModelFileError
        Naming the file, the key path and the problem.
    """
    path = REFERENCE_RIG if path is None else Path(path)
    return Model.from_toml_text(path.read_text(), str(path), allow_truth=allow_truth)
