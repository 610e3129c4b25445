"""Planar frame description, mesh and assembly into affine mass and stiffness forms.

A frame is named nodes, members between nodes (split at every node lying on them, then meshed
into :mod:`~analysis.fe.beam` elements), joints between coincident nodes (each direction tied,
free or a spring), supports, springs and lumped masses. Every linear coefficient (``E``,
``rho``, non-structural mass, spring stiffness, lumped mass) is a number or the name of a
parameter, and enters one matrix linearly, so the assembly keeps one constant matrix plus one
unit matrix per parameter::

    K(p) = K0 + sum_i p_i K_i        dK/dp_i = K_i (exact)

Tied DOFs are eliminated by a Boolean transformation (node b's DOF becomes node a's) and fixed
DOFs are removed; the result is over the free DOFs only.
"""

from __future__ import annotations

import logging
import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..settings import Integer, KeyPath, SettingError, Text, declare, dotted, settings
from .beam import Section, mass_matrix, stiffness_matrix
from .values import DIRECTIONS, Coefficient, Connection, Direction, Finite

__all__ = [
    "DIRECTIONS",
    "FrameSpec",
    "Joint",
    "LinearStructure",
    "LumpedMass",
    "Material",
    "Member",
    "SpecError",
    "Spring",
    "build_structure",
    "mesh_members",
]

log = logging.getLogger(__name__)

JOINT_CONNECTIONS = ("rigid", "free")
GEOMETRY_TOL_M = 1e-6
Dof = tuple[str, str]


class SpecError(ValueError):
    """A problem in a structure description, located by the key path of the model file."""

    def __init__(self, path: KeyPath, problem: str) -> None:
        self.path = tuple(path)
        self.problem = problem
        super().__init__(f"{dotted(self.path)}: {problem}" if self.path else problem)


@settings()
class Material:
    """A material: Young's modulus and density, numbers or parameter names."""

    E: Coefficient = declare("Young's modulus [Pa].")
    rho: Coefficient = declare("Density [kg/m^3].")


@settings()
class Member:
    """A straight member between two nodes, meshed with ``elements`` in total or elements no
    longer than ``max_element_length_m`` on each stretch between the nodes lying on it."""

    name: Text = declare("Member name, unique in the frame.")
    nodes: tuple[Text, ...] = declare("The two end nodes.")
    section: Text = declare("Section name.")
    material: Text = declare("Material name.")
    elements: Integer | None = declare("Number of elements of the whole member.", None)
    max_element_length_m: Finite | None = declare(
        "Longest element [m] (instead of elements).", None, key="max_element_length"
    )
    nsm_kg_per_m: Coefficient = declare("Non-structural mass [kg/m].", 0.0, key="nsm")
    group: Text = declare("Mass group (the mass report's).", "frame")

    def __post_init__(self) -> None:
        if len(self.nodes) != 2 or self.nodes[0] == self.nodes[1]:
            raise SettingError(("nodes",), f"need two different nodes, got {self.nodes!r}")
        if (self.elements is None) == (self.max_element_length_m is None):
            raise SettingError((), "give exactly one of 'elements' and 'max_element_length'")
        if self.elements is not None and not self.elements >= 1:
            raise SettingError(("elements",), f"must be a positive integer, got {self.elements!r}")
        if self.max_element_length_m is not None and not self.max_element_length_m > 0:
            raise SettingError(
                ("max_element_length_m",), f"must be positive, got {self.max_element_length_m!r}"
            )


@settings()
class Joint:
    """Connection of two coincident nodes: per direction ``"rigid"`` (tied), ``"free"`` or a
    spring stiffness (N/m or N m/rad; a number or a parameter name)."""

    name: Text = declare("Joint name, unique in the frame.")
    nodes: tuple[Text, ...] = declare("The two coincident nodes.")
    x: Connection = declare("Connection in x: rigid, free or a stiffness [N/m].", "rigid")
    y: Connection = declare("Connection in y: rigid, free or a stiffness [N/m].", "rigid")
    rz: Connection = declare("Connection in rz: rigid, free or a stiffness [N m/rad].", "rigid")

    def __post_init__(self) -> None:
        if len(self.nodes) != 2:
            raise SettingError(("nodes",), f"need two nodes, got {list(self.nodes)!r}")

    def connection(self, direction: str) -> Coefficient:
        return typing.cast(Coefficient, getattr(self, direction))


@settings()
class Spring:
    """Linear spring in one direction from ``node`` to ground, or to node ``to``."""

    name: Text = declare("Spring name.")
    node: Text = declare("Node.")
    direction: Direction = declare("Direction.")
    k: Coefficient = declare("Stiffness [N/m or N m/rad].")
    to: Text | None = declare("Other node (none: ground).", None)


@settings()
class LumpedMass:
    """Point mass ``m_kg`` (x and y) and rotary inertia ``J_kgm2`` (rz) at a node."""

    name: Text = declare("Mass name.")
    node: Text = declare("Node.")
    m_kg: Coefficient = declare("Mass in x and y [kg].", key="m")
    J_kgm2: Coefficient = declare("Rotary inertia in rz [kg m^2].", 0.0, key="J")
    group: Text = declare("Mass group (the mass report's).", "lumped")


@dataclass(frozen=True)
class FrameSpec:
    """Everything that defines the linear frame model."""

    nodes: dict[str, tuple[float, float]]
    sections: dict[str, Section]
    materials: dict[str, Material]
    members: tuple[Member, ...]
    joints: tuple[Joint, ...] = ()
    springs: tuple[Spring, ...] = ()
    masses: tuple[LumpedMass, ...] = ()
    supports: dict[str, tuple[str, ...]] = field(default_factory=dict)

    def coefficient_uses(self) -> list[tuple[KeyPath, Coefficient, bool]]:
        """``(key path, coefficient, strictly positive?)`` for every linear coefficient."""
        uses: list[tuple[KeyPath, Coefficient, bool]] = []
        for name, mat in self.materials.items():
            uses += [
                (("materials", name, "E"), mat.E, True),
                (("materials", name, "rho"), mat.rho, False),
            ]
        uses += [(("members", i, "nsm"), m.nsm_kg_per_m, False) for i, m in enumerate(self.members)]
        uses += [(("springs", i, "k"), s.k, False) for i, s in enumerate(self.springs)]
        for i, j in enumerate(self.joints):
            for d in DIRECTIONS:
                if j.connection(d) not in JOINT_CONNECTIONS:
                    uses.append((("joints", i, d), j.connection(d), False))
        for i, m in enumerate(self.masses):
            uses += [(("masses", i, "m"), m.m_kg, False), (("masses", i, "J"), m.J_kgm2, False)]
        return uses

    def check(self) -> None:
        """Check references between the parts; raise :class:`SpecError` naming the key path."""
        _check_names(("members",), [m.name for m in self.members])
        _check_names(("joints",), [j.name for j in self.joints])
        for i, m in enumerate(self.members):
            for node in m.nodes:
                self._need_node(("members", i, "nodes"), node)
            if m.section not in self.sections:
                raise SpecError(("members", i, "section"), f"unknown section {m.section!r}")
            if m.material not in self.materials:
                raise SpecError(("members", i, "material"), f"unknown material {m.material!r}")
        for i, j in enumerate(self.joints):
            for node in j.nodes:
                self._need_node(("joints", i, "nodes"), node)
            a, b = (np.array(self.nodes[n]) for n in j.nodes)
            if np.hypot(*(a - b)) > GEOMETRY_TOL_M:
                raise SpecError(("joints", i, "nodes"), f"nodes {j.nodes} do not coincide")
        for i, s in enumerate(self.springs):
            self._need_node(("springs", i, "node"), s.node)
            _need_direction(("springs", i, "direction"), s.direction)
            if s.to is not None:
                self._need_node(("springs", i, "to"), s.to)
        for i, m in enumerate(self.masses):
            self._need_node(("masses", i, "node"), m.node)
        for node, dirs in self.supports.items():
            self._need_node(("supports", node), node)
            for k, d in enumerate(dirs):
                _need_direction(("supports", node, k), d)
        for path, coef, positive in self.coefficient_uses():
            if not isinstance(coef, str):
                _check_value(path, float(coef), positive)

    def _need_node(self, path: KeyPath, node: str) -> None:
        if node not in self.nodes:
            raise SpecError(path, f"unknown node {node!r}")


def _check_names(path: KeyPath, names: list[str]) -> None:
    seen: set[str] = set()
    for i, name in enumerate(names):
        if name in seen:
            raise SpecError((*path, i, "name"), f"duplicate name {name!r}")
        seen.add(name)


def _need_direction(path: KeyPath, direction: str) -> None:
    if direction not in DIRECTIONS:
        raise SpecError(path, f"bad direction {direction!r}; expected one of {DIRECTIONS}")


def _check_value(path: KeyPath, value: float, positive: bool) -> None:
    if not math.isfinite(value) or value < 0 or (positive and value == 0):
        raise SpecError(path, f"must be {'> 0' if positive else '>= 0'}, got {value!r}")


# -- mesh --------------------------------------------------------------------------------------
def _split_counts(lengths: list[float], member: Member) -> list[int]:
    """Elements per stretch: a total spread to minimise the longest element, or a max length."""
    if member.max_element_length_m is not None:
        return [max(1, math.ceil(L / member.max_element_length_m - 1e-9)) for L in lengths]
    counts = [1] * len(lengths)
    for _ in range(member.elements - len(lengths)):
        i = max(range(len(lengths)), key=lambda k: lengths[k] / counts[k])
        counts[i] += 1
    return counts


def _nodes_on_member(frame: FrameSpec, i: int) -> list[tuple[float, str]]:
    """Named nodes strictly inside member ``i``, as ``(distance from node a, name)``."""
    m = frame.members[i]
    a, b = (np.array(frame.nodes[n], dtype=float) for n in m.nodes)
    L = float(np.hypot(*(b - a)))
    if L <= GEOMETRY_TOL_M:
        raise SpecError(("members", i, "nodes"), f"nodes {m.nodes} coincide (zero length)")
    e = (b - a) / L
    inside: list[tuple[float, str]] = []
    for name, xy in frame.nodes.items():
        d = np.array(xy, dtype=float) - a
        t = float(d @ e)
        if GEOMETRY_TOL_M < t < L - GEOMETRY_TOL_M and abs(d[0] * e[1] - d[1] * e[0]) < 1e-6:
            inside.append((t, name))
    inside.sort()
    for (t0, n0), (t1, n1) in zip(inside, inside[1:], strict=False):
        if t1 - t0 <= GEOMETRY_TOL_M:
            raise SpecError(
                ("members", i),
                f"nodes {n0!r} and {n1!r} coincide inside the member; split the member there",
            )
    return [(0.0, m.nodes[0]), *inside, (L, m.nodes[1])]


def mesh_members(
    frame: FrameSpec,
) -> tuple[dict[str, tuple[float, float]], list[tuple[int, str, str]]]:
    """Split members at the nodes on them and mesh every stretch.

    Returns
    -------
    node_xy : dict
        Coordinates [m] of named nodes and generated ones (named ``"member:k"``).
    elements : list of (member index, node a, node b)
    """
    node_xy = {n: (float(x), float(y)) for n, (x, y) in frame.nodes.items()}
    elements: list[tuple[int, str, str]] = []
    for i, m in enumerate(frame.members):
        stations = _nodes_on_member(frame, i)
        lengths = [t1 - t0 for (t0, _), (t1, _) in zip(stations, stations[1:], strict=False)]
        if m.elements is not None and m.elements < len(lengths):
            raise SpecError(
                ("members", i, "elements"),
                f"{m.elements} element(s) cannot cover the {len(lengths)} stretches between "
                f"the nodes on the member {[n for _, n in stations]}",
            )
        a = np.array(frame.nodes[m.nodes[0]], dtype=float)
        e = (np.array(frame.nodes[m.nodes[1]], dtype=float) - a) / stations[-1][0]
        k = 0
        for ((t0, n0), (t1, n1)), count in zip(
            zip(stations, stations[1:], strict=False), _split_counts(lengths, m), strict=True
        ):
            chain = [n0]
            for j in range(1, count):
                k += 1
                name = f"{m.name}:{k}"
                xy = a + e * (t0 + (t1 - t0) * j / count)
                node_xy[name] = (float(xy[0]), float(xy[1]))
                chain.append(name)
            chain.append(n1)
            elements += [(i, p, q) for p, q in zip(chain, chain[1:], strict=False)]
    return node_xy, elements


# -- DOF numbering -----------------------------------------------------------------------------
def _number_dofs(
    frame: FrameSpec, node_xy: Mapping[str, tuple[float, float]], elements: list
) -> tuple[tuple[Dof, ...], dict[Dof, int], frozenset[Dof]]:
    order: dict[str, None] = {}
    for _, p, q in elements:
        order.setdefault(p)
        order.setdefault(q)
    for n in node_xy:
        order.setdefault(n)
    parent: dict[Dof, Dof] = {}

    def root(dof: Dof) -> Dof:
        while dof in parent:
            dof = parent[dof]
        return dof

    for j in frame.joints:
        for d in DIRECTIONS:
            if j.connection(d) == "rigid":
                ra, rb = root((j.nodes[0], d)), root((j.nodes[1], d))
                if ra != rb:
                    parent[rb] = ra
    fixed_roots = {root((n, d)) for n, dirs in frame.supports.items() for d in dirs}
    reduced: dict[Dof, int] = {}
    labels: list[Dof] = []
    index: dict[Dof, int] = {}
    fixed: set[Dof] = set()
    for n in order:
        for d in DIRECTIONS:
            r = root((n, d))
            if r in fixed_roots:
                fixed.add((n, d))
                continue
            if r not in reduced:
                reduced[r] = len(labels)
                labels.append(r)
            index[(n, d)] = reduced[r]
    return tuple(labels), index, frozenset(fixed)


# -- assembly ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Term:
    matrix: str  # "K" or "M"
    coef: Coefficient
    unit: np.ndarray
    dofs: tuple[Dof, ...]
    group: str | None = None  # mass group, for group mass matrices


@dataclass(frozen=True)
class LinearStructure:
    """Affine mass and stiffness forms of a meshed frame over its free DOFs.

    Attributes
    ----------
    dofs : tuple of (node, direction)
        Labels of the free DOFs (the label of a tied DOF is the first node of its joint).
    index : dict
        ``(node, direction) -> free DOF index`` for every free DOF label, tied ones included.
    fixed : frozenset
        Labels of supported DOFs.
    node_xy : dict
        Coordinates [m] of all nodes, generated ones included.
    n_elements : dict
        Number of beam elements per member group.
    """

    dofs: tuple[Dof, ...]
    index: dict[Dof, int]
    fixed: frozenset[Dof]
    node_xy: dict[str, tuple[float, float]]
    n_elements: dict[str, int]
    terms: tuple[_Term, ...]
    mass_items: tuple[tuple[str, str, Coefficient, float], ...]
    _const: dict[str, np.ndarray] = field(repr=False)
    _unit: dict[tuple[str, str], np.ndarray] = field(repr=False)
    _zeros: np.ndarray = field(repr=False)

    @property
    def parameter_names(self) -> set[str]:
        """Parameters that enter M or K."""
        return {p for _, p in self._unit}

    def matrix(self, which: str, values: Mapping[str, float]) -> np.ndarray:
        """``K`` or ``M`` (shape (n, n)) at the parameter ``values``."""
        out = self._const[which].copy()
        for (w, p), unit in self._unit.items():
            if w == which:
                out += values[p] * unit
        return out

    def derivative(self, which: str, parameter: str) -> np.ndarray:
        """Exact ``dK/dp`` or ``dM/dp`` (shape (n, n), read-only); zeros if ``p`` does not
        enter."""
        unit = self._unit.get((which, parameter))
        return unit if unit is not None else self._zeros

    def group_mass_matrix(self, values: Mapping[str, float], groups: set[str]) -> np.ndarray:
        """Mass matrix (shape (n, n), kg) of the mass groups ``groups`` only."""
        out = np.zeros_like(self._const["M"])
        for t in self.terms:
            if t.matrix == "M" and t.group in groups:
                _scatter(out, _resolve(t.coef, values) * t.unit, t.dofs, self.index)
        return out

    def mass_report(self, values: Mapping[str, float]) -> dict[str, float]:
        """Translational mass [kg] by group, plus ``"lumped"``, ``"sensors"`` and ``"total"``.

        Members of a group with non-structural mass report ``"<group> structural"`` and
        ``"<group> non-structural"``, other member groups and lumped-mass groups ``"<group>"``.
        """
        with_nsm = {g for g, kind, _, _ in self.mass_items if kind == "non-structural"}
        report: dict[str, float] = {}
        for group, kind, coef, unit in self.mass_items:
            key = group
            if kind == "non-structural" or (kind == "structural" and group in with_nsm):
                key = f"{group} {kind}"
            elif kind == "lumped" and group in self.n_elements:
                key = f"{group} lumped"
            report[key] = report.get(key, 0.0) + _resolve(coef, values) * unit
        report.setdefault("lumped", 0.0)
        report.setdefault("sensors", 0.0)
        report["total"] = math.fsum(report.values())
        return report


def _resolve(coef: Coefficient, values: Mapping[str, float]) -> float:
    return float(values[coef]) if isinstance(coef, str) else float(coef)


def _scatter(out: np.ndarray, mat: np.ndarray, dofs: tuple[Dof, ...], index: Mapping) -> None:
    idx = np.array([index.get(d, -1) for d in dofs])
    keep = np.flatnonzero(idx >= 0)
    rows, cols = np.meshgrid(idx[keep], idx[keep], indexing="ij")
    np.add.at(out, (rows, cols), mat[np.ix_(keep, keep)])


def _node_dofs(node: str) -> tuple[Dof, ...]:
    return tuple((node, d) for d in DIRECTIONS)


def _frame_terms(frame: FrameSpec, node_xy: Mapping, elements: list) -> tuple[list, list]:
    terms: list[_Term] = []
    masses: list[tuple[str, str, Coefficient, float]] = []
    for i, a, b in elements:
        m = frame.members[i]
        sec, mat = frame.sections[m.section], frame.materials[m.material]
        xa, xb = np.array(node_xy[a]), np.array(node_xy[b])
        L = float(np.hypot(*(xb - xa)))
        dofs = _node_dofs(a) + _node_dofs(b)
        terms.append(
            _Term("K", mat.E, stiffness_matrix(xa, xb, 1.0, sec.area_m2, sec.inertia_m4), dofs)
        )
        terms.append(_Term("M", mat.rho, mass_matrix(xa, xb, sec.area_m2), dofs, m.group))
        masses.append((m.group, "structural", mat.rho, sec.area_m2 * L))
        if m.nsm_kg_per_m != 0.0:
            terms.append(_Term("M", m.nsm_kg_per_m, mass_matrix(xa, xb, 1.0), dofs, m.group))
            masses.append((m.group, "non-structural", m.nsm_kg_per_m, L))
    return terms, masses


def _discrete_terms(frame: FrameSpec) -> tuple[list, list]:
    pair = np.array([[1.0, -1.0], [-1.0, 1.0]])
    terms: list[_Term] = []
    for s in frame.springs:
        if s.to is None:
            terms.append(_Term("K", s.k, np.ones((1, 1)), ((s.node, s.direction),)))
        else:
            terms.append(_Term("K", s.k, pair, ((s.node, s.direction), (s.to, s.direction))))
    for j in frame.joints:
        for d in DIRECTIONS:
            k = j.connection(d)
            if k not in JOINT_CONNECTIONS:
                terms.append(_Term("K", k, pair, ((j.nodes[0], d), (j.nodes[1], d))))
    masses = []
    for lm in frame.masses:
        xy = ((lm.node, "x"), (lm.node, "y"))
        terms.append(_Term("M", lm.m_kg, np.eye(2), xy, lm.group))
        terms.append(_Term("M", lm.J_kgm2, np.ones((1, 1)), ((lm.node, "rz"),), lm.group))
        masses.append((lm.group, "lumped", lm.m_kg, 1.0))
    return terms, masses


def _check_empty_dofs(labels: tuple[Dof, ...], const: dict, unit: dict) -> None:
    """Refuse DOFs that no element, spring or mass reaches (M and K singular there: the
    eigensolver would fail with a bare LAPACK message), naming the node."""
    touched = np.zeros(len(labels), dtype=bool)
    for a in (*const.values(), *unit.values()):
        touched |= np.abs(a).sum(axis=0) > 0
    empty: dict[str, list[str]] = {}
    for i in np.flatnonzero(~touched):
        node, direction = labels[i]
        empty.setdefault(node, []).append(direction)
    for node, dirs in empty.items():
        unused = len(dirs) == len(DIRECTIONS)
        raise SpecError(
            ("nodes", node),
            (
                "no member, joint, spring or mass uses this node; connect it or remove it"
                if unused
                else f"DOF(s) {', '.join(f'{node}/{d}' for d in dirs)} have neither mass nor "
                "stiffness; connect or support them"
            ),
        )


def build_structure(frame: FrameSpec) -> LinearStructure:
    """Mesh ``frame`` and assemble its affine mass and stiffness forms.

    Parameters
    ----------
    frame : FrameSpec
        A checked frame description (see :meth:`FrameSpec.check`).

    Returns
    -------
    LinearStructure
    """
    frame.check()
    node_xy, elements = mesh_members(frame)
    labels, index, fixed = _number_dofs(frame, node_xy, elements)
    terms, masses = _frame_terms(frame, node_xy, elements)
    more_terms, more_masses = _discrete_terms(frame)
    terms += more_terms
    n = len(labels)
    const = {"K": np.zeros((n, n)), "M": np.zeros((n, n))}
    unit: dict[tuple[str, str], np.ndarray] = {}
    for t in terms:
        if isinstance(t.coef, str):
            target = unit.setdefault((t.matrix, t.coef), np.zeros((n, n)))
            _scatter(target, t.unit, t.dofs, index)
        elif t.coef != 0.0:
            _scatter(const[t.matrix], t.coef * t.unit, t.dofs, index)
    zeros = np.zeros((n, n))
    for a in (*unit.values(), zeros):
        a.setflags(write=False)
    _check_empty_dofs(labels, const, unit)
    n_elements: dict[str, int] = {}
    for i, _, _ in elements:
        group = frame.members[i].group
        n_elements[group] = n_elements.get(group, 0) + 1
    log.debug("frame meshed: %d elements, %d free DOFs", len(elements), n)
    return LinearStructure(
        dofs=labels,
        index=index,
        fixed=fixed,
        node_xy=node_xy,
        n_elements=n_elements,
        terms=tuple(terms),
        mass_items=tuple(masses + more_masses),
        _const=const,
        _unit=unit,
        _zeros=zeros,
    )
