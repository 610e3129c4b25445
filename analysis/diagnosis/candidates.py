"""Candidate model changes: a law of the element library at a location, or a linear change.

A :class:`Location` is where an effect may act, read from the model's structure: a measured
point in any direction it moves in (to ground), one spring of the model, a group of springs
sharing a stiffness parameter, a rigid direction of a joint (released into a spring), two nodes
of different members (an element between them) or the whole structure (a linear parameter). A
:class:`Law` is one element kind of the library (or a lumped mass, or a linear parameter) with
its parameters split into those entering linearly (fitted by least squares) and those entering
nonlinearly (a clearance, refined continuously). A :class:`Candidate` pairs them and knows how
to write itself into a model file (:meth:`Candidate.apply`).

Only the kinds defined in :mod:`analysis.elements` are candidates: an element kind registered
from elsewhere (a simulator's hysteretic truth) is not part of the library a diagnosis may
propose.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from analysis.model import DofRef, Model, NonlinearSpec, Parameter
from analysis.model_file import parse_document, to_document

__all__ = [
    "FRICTION_V_REG",
    "LINEAR_KINDS",
    "Candidate",
    "Law",
    "Location",
    "default_candidates",
    "default_laws",
    "default_locations",
]

#: Laws that are linear physics (reported as linear effects, never as nonlinear ones).
LINEAR_KINDS = ("linear_spring", "linear_damper", "mass", "parameter", "joint_spring")

#: Element parameters that enter a law nonlinearly (refined continuously, not by least squares).
NONLINEAR_PARAMS = ("gap",)

#: Regularisation velocity [m/s, or rad/s in a joint's rotation] of the friction candidates,
#: ``f = -f_slip tanh(v / v_reg)``. The balance's nine harmonics resolve a switch this wide
#: for velocity amplitudes up to about ten times it; at the element's default (1e-3) the
#: switch of a joint slipping at 0.08 rad/s needs more harmonics than the analysis uses, and
#: even the exact law, so balanced, misfits a test by several times the noise.
FRICTION_V_REG = 0.01


@dataclass(frozen=True)
class Location:
    """Where a candidate acts.

    Attributes
    ----------
    name : str
        What the place is (``"point 5"``, ``"point 5 x"``, ``"spring mount_right_y"``,
        ``"springs k_mount"``, ``"joint clamp rz"``, ``"point 7 to right_top y"``,
        ``"structure"``): :func:`default_locations`.
    incidences : tuple of (DofRef, DofRef or None)
        ``(at, to)`` of each element placed (one law, shared parameters); empty for a linear
        parameter.
    joint : (str, str) or None
        ``(joint name, direction)`` released from rigid to a spring for this location.
    point : int or None
        The measurement point, for point locations (in any direction).
    kind_ : str
        The location's kind where its fields alone do not tell it (:attr:`kind`).
    alike : tuple of Location
        Other places that move as this one does (:data:`SAME_MOTION`): the data of a test
        cannot tell an element here from one there, so only this one is a candidate.
    """

    name: str
    incidences: tuple[tuple[DofRef, DofRef | None], ...] = ()
    joint: tuple[str, str] | None = None
    point: int | None = None
    kind_: str = ""
    alike: tuple[Location, ...] = ()

    @property
    def moves_as(self) -> tuple[str, ...]:
        """The names of the places that move as this one (:attr:`alike`)."""
        return tuple(loc.name for loc in self.alike)

    @property
    def slug(self) -> str:
        return re.sub(r"[^a-z0-9]+", "_", self.name.lower()).strip("_")

    @property
    def kind(self) -> str:
        """``"point"`` (a measured point in its measured direction), ``"direction"`` (a
        measured point in another direction), ``"spring"`` (one spring of the model),
        ``"group"`` (springs sharing a parameter: one law, its parameters shared), ``"joint"``
        (a joint direction), ``"pair"`` (between two nodes) or ``"structure"`` (a linear
        parameter)."""
        if self.kind_:
            return self.kind_
        if self.joint is not None:
            return "joint"
        if self.point is not None:
            return "point"
        return "group" if self.incidences else "structure"

    @property
    def unmeasured(self) -> bool:
        """Acts at DOFs or in directions the point's sensor does not measure (every kind but
        a point and the structure)."""
        return self.kind not in ("point", "structure")


@dataclass(frozen=True)
class Law:
    """A force law (an element kind with options), a lumped mass or a linear parameter.

    Attributes
    ----------
    kind : str
        Element kind, ``"mass"`` or ``"parameter"``.
    options : dict
        Element options (``side`` of a one-sided stop).
    linear : tuple of str
        Parameters entering linearly (element parameter names; ``("m",)`` for a mass).
    nonlinear : tuple of str
        Parameters entering nonlinearly (``("gap",)``).
    nonnegative : tuple of str
        Linear parameters constrained to be >= 0.
    units : dict name -> str
    """

    kind: str
    options: dict = field(default_factory=dict)
    linear: tuple[str, ...] = ()
    nonlinear: tuple[str, ...] = ()
    nonnegative: tuple[str, ...] = ()
    units: dict = field(default_factory=dict)
    positive: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        side = self.options.get("side")
        if side is None:
            return self.kind
        return f"{self.kind} ({'above' if side > 0 else 'below'})"

    @property
    def is_linear(self) -> bool:
        return self.kind in LINEAR_KINDS

    @property
    def n_params(self) -> int:
        return len(self.linear) + len(self.nonlinear)


@dataclass(frozen=True)
class Candidate:
    """A law at a location (or a linear parameter of the structure).

    Attributes
    ----------
    location : Location
    law : Law
    parameter : str or None
        The model parameter freed by a ``"parameter"`` candidate.
    """

    location: Location
    law: Law
    parameter: str | None = None

    @property
    def label(self) -> str:
        if self.law.kind == "parameter":
            return f"linear parameter {self.parameter}"
        if self.location.joint is not None and self.law.kind == "joint_spring":
            return f"compliant {self.location.name} (linear spring)"
        extra = " with a joint spring" if self.location.joint is not None else ""
        return f"{self.law.label}{extra} at {self.location.name}"

    @property
    def is_linear(self) -> bool:
        return self.law.is_linear

    @property
    def n_params(self) -> int:
        """Parameters a fit adds (a released joint adds its stiffness)."""
        if self.law.kind == "parameter":
            return 1
        extra = 1 if self.location.joint is not None and self.law.kind != "joint_spring" else 0
        return self.law.n_params + extra

    @property
    def key(self) -> str:
        """Unique name, used for new model parameters and elements."""
        if self.law.kind == "parameter":
            return f"param_{self.parameter}"
        side = self.law.options.get("side")
        s = "" if side is None else ("_up" if side > 0 else "_down")
        return f"{self.law.kind}{s}_{self.location.slug}"

    def parameter_names(self) -> dict[str, str]:
        """Model parameter name of every law parameter (and ``"k_joint"`` of a released joint)."""
        if self.law.kind == "parameter":
            return {self.parameter: self.parameter}
        names = {p: f"{p}_{self.key}" for p in (*self.law.linear, *self.law.nonlinear)}
        if self.location.joint is not None:
            joint, direction = self.location.joint
            names["k_joint"] = f"k_{joint}_{direction}"
        return names

    def apply(self, model: Model, values: Mapping[str, float]) -> tuple[Model, list[str]]:
        """``model`` with this candidate added, and the model parameters it introduces or frees.

        Parameters
        ----------
        model : Model
        values : mapping law parameter -> value
            Start values (``"k_joint"`` for a released joint's stiffness); a missing value is
            the parameter's neutral value where one exists.
        """
        if self.law.kind == "parameter":
            return model, [self.parameter]
        names = self.parameter_names()
        params = [
            _new_parameter(names[p], float(values[p]), self.law, p, self.label)
            for p in (*self.law.linear, *self.law.nonlinear)
        ]
        if self.law.kind == "mass":
            return _add_mass(model, self.location, params[0]), [params[0].name]
        if self.law.kind == "linear_spring" and model.frame is not None:
            # a spring is part of the linear structure (in K, seen by the linear test), not
            # an element of the balance; a missing spring adds stiffness (a structure too
            # stiff is its own parameters' candidates)
            stiffness = params[0]
            spring = dataclasses.replace(
                stiffness,
                group="linear",
                value=max(stiffness.value, 0.0),
                lower=max(stiffness.lower, 0.0),
            )
            return _add_springs(model, self.key, self.location, spring), [spring.name]
        out = model
        if self.location.joint is not None:
            k = float(values.get("k_joint", 1e6))
            out = release_joint(out, self.location.joint, names["k_joint"], k, self.label)
        if self.law.kind == "joint_spring":
            return out, [names["k_joint"]]
        for i, (at, to) in enumerate(self.location.incidences):
            spec = NonlinearSpec(
                name=f"{self.key}_{i}" if len(self.location.incidences) > 1 else self.key,
                kind=self.law.kind,
                at=at,
                to=to,
                params={p: names[p] for p in (*self.law.linear, *self.law.nonlinear)},
                options=dict(self.law.options),
            )
            out = out.with_nonlinear(spec, params if i == 0 else ())
        new = [p.name for p in params]
        if self.location.joint is not None:
            new.append(names["k_joint"])
        return out, new


def _new_parameter(name: str, value: float, law: Law, p: str, label: str) -> Parameter:
    scale = abs(value) if value != 0 else 1.0
    if p in law.nonnegative or p in law.nonlinear:
        value = max(value, 0.0)
        if value == 0 and p in law.positive:
            value = 1.0  # the element needs it > 0; the fit moves it from there
        scale = value if value > 0 else 1.0
        lower, upper = 0.0, max(100.0 * scale, 1.0)
    else:
        lower, upper = -1e3 * scale, 1e3 * scale
    return Parameter(
        name=name,
        value=value,
        nominal=scale,
        lower=lower,
        upper=upper,
        calibrate=True,
        scaling="linear",
        unit=law.units.get(p, ""),
        group="linear" if law.kind == "mass" else "nonlinear",
        description=f"{p} of the {label} (added by diagnosis)",
    )


def _edit(model: Model, edit) -> Model:
    doc = to_document(model)
    edit(doc)
    return Model(**parse_document(doc, model.source))


def release_joint(
    model: Model, joint: tuple[str, str], name: str, value: float, label: str = ""
) -> Model:
    """``model`` with direction ``joint[1]`` of joint ``joint[0]`` a spring of parameter
    ``name``."""
    jname, direction = joint
    if not value > 0:  # a screen can estimate a released joint's stiffness below zero
        what = f"{label}: " if label else ""
        raise ValueError(
            f"{what}the stiffness of joint {jname} in {direction} must be positive, got "
            f"{value:.4g} (a screen estimates one below zero where the law does not fit with "
            "the joint released)"
        )

    def edit(doc):
        for j in doc.get("joints", []):
            if j["name"] == jname:
                j[direction] = name
                break
        else:
            raise ValueError(f"model has no joint {jname!r}")
        doc["parameters"][name] = {
            "value": value,
            "nominal": value,
            "lower": 1e-6 * value,
            "upper": 1e6 * value,
            "calibrate": True,
            "scaling": "log",
            "unit": "N/m" if direction != "rz" else "N m/rad",
            "group": "linear",
            "description": f"stiffness of joint {jname} in {direction} ({label})",
        }

    return _edit(model, edit)


def _add_springs(model: Model, key: str, location: Location, param: Parameter) -> Model:
    """``model`` with a frame spring of stiffness parameter ``param`` at every incidence of
    ``location`` (to ground, or between the incidence's two nodes in one direction)."""

    def edit(doc):
        springs = doc.setdefault("springs", [])
        for i, (at, to) in enumerate(location.incidences):
            if to is not None and to.direction != at.direction:
                raise ValueError(
                    f"a spring acts in one direction; {location.name} joins {at.direction} "
                    f"of {at.node} to {to.direction} of {to.node}"
                )
            name = f"{key}_{i}" if len(location.incidences) > 1 else key
            row = {"name": name, "node": at.node, "direction": at.direction, "k": param.name}
            springs.append(row if to is None else {**row, "to": to.node})
        _add_parameter(doc, param)

    return _edit(model, edit)


def _add_parameter(doc: dict, param: Parameter) -> None:
    d = dataclasses.asdict(param)
    d.pop("name")
    unset = (None, math.inf, -math.inf)
    doc["parameters"][param.name] = {k: v for k, v in d.items() if v not in unset}


def _add_mass(model: Model, location: Location, param: Parameter) -> Model:
    node = location.incidences[0][0].node

    def edit(doc):
        doc.setdefault("masses", []).append(
            {"name": param.name, "node": node, "m": param.name, "J": 0.0, "group": "added"}
        )
        _add_parameter(doc, param)

    return _edit(model, edit)


# -- the default candidate set -----------------------------------------------------------------
#: Directions a force law of the library acts in at a point (translations: a moment at a
#: section of a member comes from a joint, which has locations of its own).
POINT_DIRECTIONS = ("x", "y")

#: Reach of a relative element, as a fraction of the structure's largest extent: two nodes of
#: different members this close (a bracket, a limiter, a bolted stop bridging the clearance
#: between them) may hold an element between them.
PAIR_REACH = 0.1

#: Two pairs of nodes move as one place when the difference of their relative displacements
#: is at most this share of their own under any static load (in the structure's flexibility
#: norm, ``sqrt(d' K^-1 d)``): two nodes on one post move alike along it (the post is
#: axially rigid), so a stop from the tip to either is the same element to any test below
#: the post's axial modes. Only the shortest of such pairs is a candidate (a relative element
#: spans the shortest way), naming the others.
SAME_MOTION = 0.01


#: What each scope of the candidate set holds (:func:`default_locations`). ``"measured"``:
#: the places the sensors see directly (each point in its measured direction, each group of
#: springs sharing a parameter, a joint's rotation and transverse direction). ``"structure"``
#: adds every other direction of a point, each spring alone, a joint's axial direction and the
#: pairs of nodes: places whose effect the sensors see only through the structure, so several
#: of them can fit one data set alike (a spring to ground at a post's foot and the mounts
#: beside it); a diagnosis on that scope needs the separating measurement to name one.
LOCATION_SCOPES = {
    "measured": ("point", "group", "joint"),
    "structure": ("point", "direction", "spring", "group", "joint", "pair"),
}
_MEASURED_JOINT_DIRECTIONS = ("rz", "y")


def default_locations(model: Model, scope: str = "measured") -> list[Location]:
    """The places of the model's structure an effect may act in ``scope``
    (:data:`LOCATION_SCOPES`), named after what they are.

    In order: every measurement point in its measured direction (``"point 7"``) and in every
    other direction the structure moves there (``"point 7 x"``); every spring on its own
    (``"spring mount_right_y"``) and every group of springs sharing a stiffness parameter
    (``"springs k_mount"``); every rigid direction of every joint (``"joint clamp rz"``); and
    every pair of a measured point's node and a node of another member within
    :data:`PAIR_REACH` of the structure's extent, in each direction both move in
    (``"point 7 to right_top y"``, ``"point 12 to right_corner x"``).
    """
    asm = model.assemble()
    moves: dict[str, list[str]] = {}
    for node, d in asm.dofs:
        moves.setdefault(node, []).append(d)
    locs = []
    for n, p in model.points.items():
        locs.append(Location(f"point {n}", ((DofRef(p.node, p.direction, n), None),), point=n))
    for n, p in model.points.items():
        for d in POINT_DIRECTIONS:
            if d != p.direction and d in moves.get(p.node, ()):
                locs.append(
                    Location(
                        f"point {n} {d}", ((DofRef(p.node, d), None),), point=n, kind_="direction"
                    )
                )
    if model.frame is not None:
        locs += _spring_locations(model)
        locs += _joint_locations(model)
        locs += _pair_locations(model, asm, moves)
    if scope not in LOCATION_SCOPES:
        raise ValueError(f"locations: expected one of {sorted(LOCATION_SCOPES)}, got {scope!r}")
    kinds = LOCATION_SCOPES[scope]
    kept = [
        loc
        for loc in locs
        if loc.kind in kinds
        and (
            scope == "structure" or loc.joint is None or loc.joint[1] in _MEASURED_JOINT_DIRECTIONS
        )
    ]
    xy = model.frame.nodes if model.frame is not None else {}
    return _merge_same_motion(kept, asm, xy)


def _spring_locations(model: Model) -> list[Location]:
    """Each spring of the frame on its own, then each group sharing a stiffness parameter."""
    assert model.frame is not None
    locs = []
    groups: dict[str, list] = {}
    for s in model.frame.springs:
        inc = (DofRef(s.node, s.direction), None if s.to is None else DofRef(s.to, s.direction))
        locs.append(Location(f"spring {s.name}", (inc,), kind_="spring"))
        if isinstance(s.k, str):
            groups.setdefault(s.k, []).append(inc)
    for pname, incs in groups.items():
        if len(incs) > 1:
            locs.append(Location(f"springs {pname}", tuple(incs), kind_="group"))
    return locs


def _joint_locations(model: Model) -> list[Location]:
    """Each rigid direction of each joint, released into a spring of its own."""
    assert model.frame is not None
    locs = []
    for j in model.frame.joints:
        for d in ("rz", "y", "x"):
            if j.connection(d) == "rigid":
                a, b = j.nodes
                locs.append(
                    Location(
                        f"joint {j.name} {d}", ((DofRef(b, d), DofRef(a, d)),), joint=(j.name, d)
                    )
                )
    return locs


def _on_segment(xy, a, b, tol: float) -> bool:
    (px, py), (ax, ay), (bx, by) = xy, a, b
    dx, dy = bx - ax, by - ay
    t = ((px - ax) * dx + (py - ay) * dy) / (dx * dx + dy * dy)
    if t < -tol or t > 1 + tol:
        return False
    return math.hypot(ax + t * dx - px, ay + t * dy - py) <= tol * math.hypot(dx, dy)


def _pair_locations(model: Model, asm, moves: Mapping[str, Sequence[str]]) -> list[Location]:
    """A measured point's node and each named node of another member within reach."""
    frame = model.frame
    assert frame is not None
    xy = frame.nodes
    xs = [v[0] for v in xy.values()]
    ys = [v[1] for v in xy.values()]
    reach = PAIR_REACH * max(max(xs) - min(xs), max(ys) - min(ys))
    members = {
        node: {
            m.name
            for m in frame.members
            if _on_segment(xy[node], xy[m.nodes[0]], xy[m.nodes[1]], 1e-9)
        }
        for node in xy
    }
    point_at = {p.node: n for n, p in model.points.items()}
    locs, seen = [], set()
    for n, p in model.points.items():
        for other in xy:
            dist = math.dist(xy[p.node], xy[other])
            pair = frozenset((p.node, other))
            if not 0 < dist <= reach or members[p.node] & members[other] or pair in seen:
                continue
            seen.add(pair)
            name = f"point {point_at[other]}" if other in point_at else other
            for d in POINT_DIRECTIONS:
                if d in moves.get(p.node, ()) and d in moves.get(other, ()):
                    locs.append(
                        Location(
                            f"point {n} to {name} {d}",
                            ((DofRef(p.node, d), DofRef(other, d)),),
                            kind_="pair",
                        )
                    )
    return locs


#: Which of several places that move alike is the candidate: the one the sensors see most
#: directly (the screen reads a measured point's states best), then the shortest pair.
_SEEN_FIRST = ("point", "direction", "spring", "pair")


def _merge_same_motion(locs: list[Location], asm, xy) -> list[Location]:
    """``locs`` with the places that move as another (:data:`SAME_MOTION`) folded into it
    (in its ``alike``): the point, direction, spring or pair the sensors see most
    directly, the shortest pair among pairs. Groups and joints are kept as they are."""
    single = [
        i for i, loc in enumerate(locs) if loc.kind in _SEEN_FIRST and len(loc.incidences) == 1
    ]
    if len(single) < 2:
        return locs

    def dof(ref: DofRef) -> int:
        if ref.node is not None:
            return asm.dof_index(ref.node, ref.direction)
        return asm.point_dof(ref.point, ref.direction)

    B = np.zeros((len(single), asm.n_dofs))
    span = []
    for row, i in enumerate(single):
        ((at, to),) = locs[i].incidences
        B[row, dof(at)] += 1.0
        if to is not None:
            B[row, dof(to)] -= 1.0
            span.append(math.dist(xy[at.node], xy[to.node]))
        else:
            span.append(0.0)
    # the flexibility's Gram matrix of the incidences: |b_i - b_j|^2 = G_ii + G_jj - 2 G_ij
    G = B @ np.linalg.solve(np.asarray(asm.K, float), B.T)
    order = sorted(
        range(len(single)),
        key=lambda r: (_SEEN_FIRST.index(locs[single[r]].kind), span[r], single[r]),
    )
    kept: dict[int, list[Location]] = {}
    for r in order:
        home = next(
            (
                k
                for k in kept
                if G[r, r] + G[k, k] - 2 * G[r, k] <= SAME_MOTION**2 * min(G[r, r], G[k, k])
            ),
            None,
        )
        if home is None:
            kept[r] = []
        else:
            kept[home].append(locs[single[r]])
    folded = {single[r] for r in order if r not in kept}
    twins = {single[r]: tuple(v) for r, v in kept.items() if v}
    return [
        dataclasses.replace(loc, alike=twins[i]) if i in twins else loc
        for i, loc in enumerate(locs)
        if i not in folded
    ]


def _element_law(kind: str, **options) -> Law:
    import analysis.elements as lib

    cls = lib.ELEMENT_TYPES[kind]
    names = cls.param_names
    nonneg = tuple(n for n in names if n in cls.nonnegative_params or n in cls.positive_params)
    return Law(
        kind=kind,
        positive=tuple(cls.positive_params),
        options=options,
        linear=tuple(n for n in names if n not in NONLINEAR_PARAMS),
        nonlinear=tuple(n for n in names if n in NONLINEAR_PARAMS),
        nonnegative=nonneg,
        units=dict(zip(names, cls.param_units, strict=True)),
    )


def default_laws() -> list[Law]:
    """One law per kind of the element library (both sides of one-sided stops) and a mass."""
    import analysis.elements as lib

    laws = []
    for kind, cls in sorted(lib.ELEMENT_TYPES.items()):
        if not cls.__module__.startswith("analysis.elements") or kind == "polynomial_spring":
            continue  # library kinds only; the polynomial is a superset of its terms
        if "side" in cls.option_names:
            laws += [_element_law(kind, side=-1), _element_law(kind, side=1)]
        elif "v_reg" in cls.option_names:
            laws.append(_element_law(kind, v_reg=FRICTION_V_REG))
        else:
            laws.append(_element_law(kind))
    laws.append(Law("mass", linear=("m",), nonnegative=("m",), units={"m": "kg"}))
    return laws


def default_candidates(
    model: Model,
    locations: Sequence[Location] | None = None,
    laws: Sequence[Law] | None = None,
    parameters: Sequence[str] | None = None,
    scope: str = "measured",
) -> list[Candidate]:
    """Every law at every location, joint releases, and each linear parameter of the model.

    A mass (at every direction of its node) is a candidate at a point's own location only; a
    released joint gets every law plus its spring alone (``"joint_spring"``: a compliant
    joint, a linear effect). ``parameters`` (default: the model's linear parameters flagged
    ``calibrate``) become linear candidates. ``scope``: the locations' (:data:`LOCATION_SCOPES`)
    when ``locations`` is not given.
    """
    locations = default_locations(model, scope) if locations is None else list(locations)
    laws = default_laws() if laws is None else list(laws)
    out = []
    for loc in locations:
        for law in laws:
            if law.kind == "mass" and loc.kind != "point":
                continue
            if loc.joint is not None and law.kind == "linear_spring":
                continue  # the joint's own spring
            out.append(Candidate(loc, law))
        if loc.joint is not None:
            out.append(Candidate(loc, Law("joint_spring")))
    names = (
        model.parameter_names(group="linear", calibrate=True) if parameters is None else parameters
    )
    structure = Location("structure")
    out += [Candidate(structure, Law("parameter"), parameter=p) for p in names]
    return out
