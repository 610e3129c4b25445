"""Base class and registry of the nonlinear element library.

An element is a force law ``f(u, v)`` acting between DOF ``a`` and DOF ``b`` (or ground), with
``u = q_a - q_b`` and ``v = dq_a/dt - dq_b/dt`` (``q_b = 0`` for a grounded element). ``f`` is
the force the element exerts **on the structure at DOF a** (the reaction ``-f`` acts at ``b``);
a linear spring of stiffness ``k`` is therefore ``f = -k u``. This is the sign of ``docs/rig.md``:
the bump stop pushes the beam tip up (``f > 0``) while the tip is below ``-gap``.

A new element type is one small subclass: set ``kind``, ``param_names`` and ``param_units``
(and ``option_names`` if it has non-calibrated settings, ``positive_params`` /
``nonnegative_params`` for sign constraints), implement :meth:`NonlinearElement._evaluate` and
decorate the class with :func:`register`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = [
    "ELEMENT_TYPES",
    "CompiledLaw",
    "ElementEval",
    "ElementParameterError",
    "NonlinearElement",
    "register",
]

ELEMENT_TYPES: dict[str, type[NonlinearElement]] = {}

#: ``law(u, v, p) -> (f, df_du, df_dv)`` compiled with numba (see ``compiled_law``).
CompiledLaw = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, ...]]


def register(cls: type[NonlinearElement]) -> type[NonlinearElement]:
    """Class decorator: make an element type available by its ``kind`` in model files.

    Raises
    ------
    TypeError
        If ``kind`` is empty or taken by another class, or the class attributes that
        describe the parameters are inconsistent.
    """
    name = cls.__name__
    if not cls.kind:
        raise TypeError(f"{name}: set the class attribute 'kind'")
    if cls.kind in ELEMENT_TYPES and ELEMENT_TYPES[cls.kind] is not cls:
        raise TypeError(f"element kind {cls.kind!r} is registered twice")
    if len(cls.param_units) != len(cls.param_names):
        raise TypeError(f"{name}: param_units must give one unit per name in param_names")
    declared = set(cls.positive_params) | set(cls.nonnegative_params) | set(cls.param_defaults)
    if not declared <= set(cls.param_names):
        raise TypeError(f"{name}: constraints or defaults name unknown parameters")
    if set(cls.option_names) & set(cls.param_names):
        raise TypeError(f"{name}: an option has the name of a parameter")
    ELEMENT_TYPES[cls.kind] = cls
    return cls


class ElementParameterError(ValueError):
    """A parameter or option an element refuses (unknown, missing or a bad value); its name is
    :attr:`parameter`, so that a model file can locate the error at the key that gives it."""

    def __init__(self, parameter: str, message: str) -> None:
        super().__init__(message)
        self.parameter = parameter


def _as_number(kind: str, what: str, name: str, value: object) -> float:
    """``value`` of the parameter or option (``what``) ``name`` as a finite float; booleans
    and strings are refused."""
    if not isinstance(value, bool | np.bool_ | str | bytes):
        try:
            x = float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            pass
        else:
            if not np.isfinite(x):
                raise ElementParameterError(
                    name, f"element {kind!r}: {what} {name!r} is not finite, got {value!r}"
                )
            return x
    raise ElementParameterError(
        name, f"element {kind!r}: {what} {name!r} must be a number, got {value!r}"
    )


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
        One value per name in ``param_names`` (required unless listed in ``param_defaults``)
        and optional settings named in ``option_names``.

    Attributes
    ----------
    kind : str
        Registered name, as used in model files.
    param_names, param_units : tuple of str
        Calibratable parameters and their units, in the order of ``p`` and ``df_dp``.
    param_defaults : dict
        Values of parameters that may be omitted.
    positive_params, nonnegative_params : tuple of str
        Parameters that must be ``> 0`` and ``>= 0``; checked on construction.
    option_names : dict
        Non-calibrated settings and their defaults (validated by the subclass).
    options : dict
        This element's option values.

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
    param_defaults: ClassVar[dict[str, float]] = {}
    positive_params: ClassVar[tuple[str, ...]] = ()
    nonnegative_params: ClassVar[tuple[str, ...]] = ()
    option_names: ClassVar[dict[str, object]] = {}
    description: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs: object) -> None:
        super().__init_subclass__(**kwargs)
        # a subclass that writes its own law does not inherit its parent's compiled form of
        # another law: the balance would evaluate the parent's law without a word
        if "_evaluate" in cls.__dict__ and "compiled_law" not in cls.__dict__:
            cls.compiled_law = NonlinearElement.compiled_law  # type: ignore[method-assign]

    def __init__(self, **values: float) -> None:
        unknown = set(values) - set(self.param_names) - set(self.option_names)
        if unknown:
            raise ElementParameterError(
                sorted(unknown)[0],
                f"element {self.kind!r}: unknown parameter(s) {sorted(unknown)}; "
                f"expected {list(self.param_names)}"
                + (f" and options {list(self.option_names)}" if self.option_names else ""),
            )
        values = {**self.param_defaults, **values}
        missing = [n for n in self.param_names if n not in values]
        if missing:
            raise ElementParameterError(
                missing[0], f"element {self.kind!r}: missing parameter(s) {missing}"
            )
        self._p = np.array(
            [_as_number(self.kind, "parameter", n, values[n]) for n in self.param_names]
        )
        for n, x in self.params.items():
            if n in self.positive_params and not x > 0:
                raise ElementParameterError(
                    n, f"element {self.kind!r}: parameter {n!r} must be > 0, got {x}"
                )
            if n in self.nonnegative_params and not x >= 0:
                raise ElementParameterError(
                    n, f"element {self.kind!r}: parameter {n!r} must be >= 0, got {x}"
                )
        self.options = {k: values.get(k, d) for k, d in self.option_names.items()}
        self._validate()

    # -- subclass hooks -------------------------------------------------------------------
    def switch_threshold(self) -> tuple[float, np.ndarray] | None:
        """Displacement ``u_s`` where the force jumps, and ``du_s/dp`` (shape (n_params,)).

        Only laws whose force is *discontinuous* at a displacement threshold return one (the
        paper's contact: its damping term jumps at entry and exit); continuous laws, kinks
        included, return ``None``. The balance integrates such jumps exactly between AFT
        samples (:mod:`analysis.mhb.aft`), which keeps its residual continuous.
        """
        return None

    def compiled_law(self) -> tuple[CompiledLaw, np.ndarray] | None:
        """The law compiled with numba, for the balance's compiled AFT, or ``None``.

        ``(law, p)`` where ``law(u, v, p)`` takes 1-D float arrays ``u``, ``v`` and returns
        ``f, df_du, df_dv`` (1-D, the values :meth:`evaluate` gives), ``p`` a float array of
        whatever settings the law needs. Without one the balance evaluates the law through
        :meth:`evaluate` (numpy).
        """
        return None

    def _compiled_evaluate(self, u: np.ndarray, v: np.ndarray) -> ElementEval | None:
        """:meth:`evaluate` without parameter derivatives by the compiled law, in any shape:
        what a law with one calls, so that the balance's two paths agree; ``None`` without
        one (a subclass that writes its own law and calls its parent's code)."""
        compiled = self.compiled_law()
        if compiled is None:
            return None
        law, p = compiled
        return ElementEval(*(a.reshape(u.shape) for a in law(u.ravel(), v.ravel(), p)))

    def _validate(self) -> None:
        """Check option values (and any further parameter rules); raise ``ValueError``.

        Parameters are already finite numbers satisfying the declared sign constraints.
        """

    def _option_number(self, name: str) -> float:
        """Option ``name`` as a finite float, or ``ValueError`` naming it."""
        return _as_number(self.kind, "option", name, self.options[name])

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
        """Force and exact derivatives at a set of samples.

        Parameters
        ----------
        u : array_like, shape (...), m
            Relative displacement ``q_a - q_b``.
        v : array_like, same shape as `u`, m/s
            Relative velocity.
        want_params : bool
            Also return ``df_dp``, shape ``(n_params, ...)``.

        Returns
        -------
        ElementEval
        """
        u = np.asarray(u, dtype=float)
        v = np.asarray(v, dtype=float)
        if u.shape != v.shape:
            raise ValueError(
                f"element {self.kind!r}: u and v shapes differ: {u.shape} vs {v.shape}"
            )
        out = self._evaluate(u, v, want_params)
        # Arithmetic on 0-d arrays gives numpy scalars: return arrays for every input shape.
        return ElementEval(
            np.asarray(out.f),
            np.asarray(out.df_du),
            np.asarray(out.df_dv),
            None if out.df_dp is None else np.asarray(out.df_dp),
        )

    def force(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Force on DOF a [N] at samples ``u`` [m], ``v`` [m/s]."""
        return self.evaluate(u, v).f

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items())
        opts = "".join(f", {k}={v!r}" for k, v in self.options.items())
        return f"{type(self).__name__}({args}{opts})"
