"""Base class and registry of the nonlinear element library.

An element is a force law ``f(u, v)`` acting between DOF ``a`` and DOF ``b`` (or ground), with
``u = q_a - q_b`` and ``v = dq_a/dt - dq_b/dt`` (``q_b = 0`` for a grounded element). ``f`` is
the force the element exerts **on the structure at DOF a** (the reaction ``-f`` acts at ``b``);
a linear spring of stiffness ``k`` is therefore ``f = -k u``. This is the sign of ``rig.md``:
the bump stop pushes the beam tip up (``f > 0``) while the tip is below ``-gap``.

A new element type is one small subclass: set ``kind``, ``param_names`` (and ``option_names``
if it has non-calibrated settings) and implement :meth:`NonlinearElement._evaluate`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = ["ELEMENT_TYPES", "ElementEval", "NonlinearElement", "make_element", "register"]

ELEMENT_TYPES: dict[str, type[NonlinearElement]] = {}


def register(cls: type[NonlinearElement]) -> type[NonlinearElement]:
    """Class decorator: make an element type available by its ``kind`` in model files."""
    if not cls.kind:
        raise TypeError(f"{cls.__name__}: set the class attribute 'kind'")
    if cls.kind in ELEMENT_TYPES and ELEMENT_TYPES[cls.kind] is not cls:
        raise TypeError(f"element kind {cls.kind!r} is registered twice")
    ELEMENT_TYPES[cls.kind] = cls
    return cls


@dataclass(frozen=True)
class ElementEval:
    """Force and exact derivatives of an element at a set of samples.

    Attributes
    ----------
    f : ndarray, shape (...), N
        Force on DOF a.
    df_du : ndarray, shape (...), N/m
    df_dv : ndarray, shape (...), N s/m
    df_dp : ndarray, shape (n_params, ...) or None
        Derivative with respect to each parameter, in ``param_names`` order (units N per
        parameter unit). ``None`` unless requested.
    """

    f: np.ndarray
    df_du: np.ndarray
    df_dv: np.ndarray
    df_dp: np.ndarray | None = None


class NonlinearElement:
    """A nonlinear force law between two DOFs or a DOF and ground.

    Parameters
    ----------
    **values : float
        One value per name in ``param_names`` (all required) and optional settings named in
        ``option_names``.

    Notes
    -----
    Laws with switching points (gaps, contact, friction regularised or not) are not
    differentiable there. Every subclass evaluates its derivatives from the branch selected by
    the strict inequality that defines the law (for example ``u < -gap`` for contact), i.e. the
    one-sided derivative of the branch the sample lies in. Sampled periodic responses hit a
    switching point with probability zero, so harmonic-balance Jacobians and parameter
    sensitivities are exact almost everywhere; finite-difference checks stay away from switches.
    """

    kind: ClassVar[str] = ""
    param_names: ClassVar[tuple[str, ...]] = ()
    param_units: ClassVar[tuple[str, ...]] = ()
    option_names: ClassVar[dict[str, object]] = {}
    description: ClassVar[str] = ""

    def __init__(self, **values: float) -> None:
        unknown = set(values) - set(self.param_names) - set(self.option_names)
        if unknown:
            raise ValueError(
                f"element {self.kind!r}: unknown parameter(s) {sorted(unknown)}; "
                f"expected {list(self.param_names)}"
                + (f" and options {list(self.option_names)}" if self.option_names else "")
            )
        missing = [n for n in self.param_names if n not in values]
        if missing:
            raise ValueError(f"element {self.kind!r}: missing parameter(s) {missing}")
        p = np.empty(len(self.param_names))
        for i, n in enumerate(self.param_names):
            try:
                p[i] = float(values[n])
            except (TypeError, ValueError):
                raise ValueError(
                    f"element {self.kind!r}: parameter {n!r} must be a number, got {values[n]!r}"
                ) from None
            if not np.isfinite(p[i]):
                raise ValueError(f"element {self.kind!r}: parameter {n!r} is not finite")
        self._p = p
        self.options = {k: values.get(k, d) for k, d in self.option_names.items()}
        self._validate()

    # -- subclass hooks -------------------------------------------------------------------
    def _validate(self) -> None:
        """Check parameter values; raise ``ValueError`` naming the parameter."""

    def _evaluate(self, u: np.ndarray, v: np.ndarray, want_params: bool) -> ElementEval:
        raise NotImplementedError

    # -- public API ----------------------------------------------------------------------
    @property
    def params(self) -> dict[str, float]:
        """Parameter values by name."""
        return dict(zip(self.param_names, self._p.tolist(), strict=True))

    @property
    def p(self) -> np.ndarray:
        """Parameter vector in ``param_names`` order (a copy)."""
        return self._p.copy()

    def with_params(self, **updates: float) -> NonlinearElement:
        """Return a copy with some parameters (or options) replaced."""
        values = {**self.params, **self.options, **updates}
        return type(self)(**values)

    def evaluate(self, u: np.ndarray, v: np.ndarray, want_params: bool = False) -> ElementEval:
        """Force and derivatives at samples ``u`` [m] and ``v`` [m/s] of equal shape."""
        u = np.asarray(u, dtype=float)
        v = np.asarray(v, dtype=float)
        if u.shape != v.shape:
            raise ValueError(f"element {self.kind!r}: u and v shapes differ: {u.shape} vs {v.shape}")
        return self._evaluate(u, v, want_params)

    def force(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Force on DOF a [N] at samples ``u`` [m], ``v`` [m/s]."""
        return self.evaluate(u, v).f

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v:g}" for k, v in self.params.items())
        opts = "".join(f", {k}={v!r}" for k, v in self.options.items())
        return f"{type(self).__name__}({args}{opts})"


def make_element(kind: str, **values: float) -> NonlinearElement:
    """Create an element of a registered ``kind`` (as named in model files)."""
    # Importing the package registers the built-in library.
    import analysis.elements  # noqa: F401

    try:
        cls = ELEMENT_TYPES[kind]
    except KeyError:
        raise ValueError(
            f"unknown nonlinear element kind {kind!r}; known: {sorted(ELEMENT_TYPES)}"
        ) from None
    return cls(**values)
