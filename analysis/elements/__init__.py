"""Library of nonlinear force laws for local nonlinearities (stops, contact, friction, ...).

Importing this package registers every built-in kind in :data:`ELEMENT_TYPES`; create
elements by name with :func:`make_element`. Sign convention and how to add a kind: see
:mod:`analysis.elements.base`.
"""

from __future__ import annotations

from .base import ELEMENT_TYPES, ElementEval, NonlinearElement, register
from .contact import HertzContact
from .damping import CubicDamper, LinearDamper, QuadraticDamper
from .friction import CoulombFriction
from .gaps import BilinearSpring, GapSpring, OneSidedStop, TwoSidedGap
from .polynomial import (
    CubicSpring,
    LinearSpring,
    PolynomialSpring,
    PowerSeriesElement,
    QuadraticSpring,
)

__all__ = [
    "ELEMENT_TYPES",
    "BilinearSpring",
    "CoulombFriction",
    "CubicDamper",
    "CubicSpring",
    "ElementEval",
    "GapSpring",
    "HertzContact",
    "LinearDamper",
    "LinearSpring",
    "NonlinearElement",
    "OneSidedStop",
    "PolynomialSpring",
    "PowerSeriesElement",
    "QuadraticDamper",
    "QuadraticSpring",
    "TwoSidedGap",
    "element_summary",
    "make_element",
    "register",
]


def make_element(kind: str, **values: float) -> NonlinearElement:
    """Create an element of a registered ``kind`` (as named in model files). It lives in the
    package, not in :mod:`~analysis.elements.base`, so that whoever creates an element has
    imported every built-in kind (and the base module needs none of them)."""
    try:
        cls = ELEMENT_TYPES[kind]
    except KeyError:
        raise ValueError(
            f"unknown nonlinear element kind {kind!r}; known: {sorted(ELEMENT_TYPES)}"
        ) from None
    return cls(**values)


def _constraint(cls: type[NonlinearElement], name: str) -> str | None:
    if name in cls.positive_params:
        return "> 0"
    return ">= 0" if name in cls.nonnegative_params else None


def element_summary() -> list[dict]:
    """Describe every registered element kind, sorted by kind (for CLIs and the GUI).

    Returns
    -------
    list of dict
        One entry per kind with keys ``kind`` (str), ``class`` (class name),
        ``description`` (str), ``params`` (list of dicts with ``name``, ``unit``,
        ``constraint`` (``"> 0"``, ``">= 0"`` or None) and ``default`` (None if required))
        and ``options`` (dict of option name to default).
    """
    return [
        {
            "kind": kind,
            "class": cls.__name__,
            "description": cls.description,
            "params": [
                {
                    "name": name,
                    "unit": unit,
                    "constraint": _constraint(cls, name),
                    "default": cls.param_defaults.get(name),
                }
                for name, unit in zip(cls.param_names, cls.param_units, strict=True)
            ],
            "options": dict(cls.option_names),
        }
        for kind, cls in sorted(ELEMENT_TYPES.items())
    ]
