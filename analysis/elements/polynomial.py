"""Polynomial springs in the relative displacement, and the shared power-series law.

:class:`PowerSeriesElement` is the common kernel of every law that is a weighted sum of powers
of one kinematic variable: the springs here (powers of ``u``) and the dampers of
:mod:`analysis.elements.damping` (signed powers of ``v``).
"""

from __future__ import annotations

from functools import cached_property
from typing import ClassVar

import numpy as np
from numba import njit

from .base import CompiledLaw, ElementEval, NonlinearElement, register

__all__ = [
    "CubicSpring",
    "LinearSpring",
    "PolynomialSpring",
    "PowerSeriesElement",
    "QuadraticSpring",
]


@njit(cache=True)
def _power_series_law(u, v, p):
    """``f``, ``df_du``, ``df_dv`` of ``f = -sum_j p_j g_j(x)`` at samples ``u``, ``v`` for
    ``p = (on_velocity, signed, n_1..n_m, p_1..p_m)``, in the order of operations of the array
    code (its integer powers 0-2 exact, higher ones by ``pow``, as numpy takes them)."""
    on_velocity, signed = p[0] != 0.0, p[1] != 0.0
    m = (p.size - 2) // 2
    x = v if on_velocity else u
    n = x.size
    f, df_dx = np.zeros(n), np.zeros(n)
    for i in range(n):
        xi = x[i]
        ax = abs(xi) if signed else xi
        for j in range(m):
            e, c = p[2 + j] - 1.0, p[2 + m + j]
            if e == 0.0:
                a = 1.0
            elif e == 1.0:
                a = ax
            elif e == 2.0:
                a = ax * ax
            else:
                a = ax**e
            f[i] -= c * (xi * a)
            df_dx[i] -= (p[2 + j] * c) * a
    zero = np.zeros(n)
    if on_velocity:
        return f, zero, df_dx
    return f, df_dx, zero


class PowerSeriesElement(NonlinearElement):
    """Base of laws ``f = -sum_j p_j g_j(x)``, one parameter per power (not registered).

    ``x`` is ``u`` (springs) or ``v`` (dampers, ``on_velocity = True``); ``g_j`` is ``x^n_j``,
    or ``x |x|^(n_j - 1)`` if ``signed``. Subclasses set ``powers``
    in ``param_names`` order. The laws are smooth (``x |x|`` is once differentiable at 0 with
    derivative 0), so the derivatives are exact everywhere; ``df_dp_j = -g_j(x)``.
    """

    powers: ClassVar[tuple[int, ...]] = ()
    on_velocity: ClassVar[bool] = False
    signed: ClassVar[bool] = False

    def compiled_law(self) -> tuple[CompiledLaw, np.ndarray]:
        """:func:`_power_series_law` (the numpy code below gives the parameter derivatives)."""
        return _power_series_law, self._law_p

    @cached_property
    def _law_p(self) -> np.ndarray:
        return np.array([self.on_velocity, self.signed, *self.powers, *self._p], dtype=float)

    def _evaluate(self, u: np.ndarray, v: np.ndarray, want_params: bool) -> ElementEval:
        if not want_params and (ev := self._compiled_evaluate(u, v)) is not None:
            return ev
        x = v if self.on_velocity else u
        ax = np.abs(x) if self.signed else x
        f, df_dx = np.zeros_like(x), np.zeros_like(x)
        g = []
        for p, n in zip(self._p, self.powers, strict=True):
            a = ax ** (n - 1)  # g = x a, dg/dx = n a (signed or not)
            g.append(x * a)
            f -= p * g[-1]
            df_dx -= (n * p) * a
        zero = np.zeros_like(x)
        df_du, df_dv = (zero, df_dx) if self.on_velocity else (df_dx, zero)
        return ElementEval(f, df_du, df_dv, -np.stack(g) if want_params else None)


@register
class LinearSpring(PowerSeriesElement):
    """Linear spring ``f = -k u``.

    Parameters
    ----------
    k : float, N/m
        Stiffness (any sign: a negative value is a stiffness correction that softens).
    """

    kind = "linear_spring"
    param_names = ("k",)
    param_units = ("N/m",)
    powers = (1,)
    description = "linear spring f = -k u"


@register
class QuadraticSpring(PowerSeriesElement):
    """Quadratic spring ``f = -k2 u^2``.

    Even in ``u``: under a symmetric vibration it produces a mean (static) force, like a
    preload, and even harmonics.

    Parameters
    ----------
    k2 : float, N/m^2
        Coefficient (any sign).
    """

    kind = "quadratic_spring"
    param_names = ("k2",)
    param_units = ("N/m^2",)
    powers = (2,)
    description = "quadratic (even) spring f = -k2 u^2; gives a mean force"


@register
class CubicSpring(PowerSeriesElement):
    """Cubic (Duffing) spring ``f = -k3 u^3``.

    Parameters
    ----------
    k3 : float, N/m^3
        Coefficient: hardening if positive, softening if negative.
    """

    kind = "cubic_spring"
    param_names = ("k3",)
    param_units = ("N/m^3",)
    powers = (3,)
    description = "cubic (Duffing) spring f = -k3 u^3"


@register
class PolynomialSpring(PowerSeriesElement):
    """Polynomial spring ``f = -sum_{j=1..5} k_j u^j``.

    Parameters
    ----------
    k1, k2, k3, k4, k5 : float, N/m^j
        Coefficients (any sign); omitted ones are 0.
    """

    kind = "polynomial_spring"
    param_names = ("k1", "k2", "k3", "k4", "k5")
    param_units = ("N/m", "N/m^2", "N/m^3", "N/m^4", "N/m^5")
    param_defaults = dict.fromkeys(param_names, 0.0)
    powers = (1, 2, 3, 4, 5)
    description = "polynomial spring f = -sum_j k_j u^j, j = 1..5 (omitted k_j = 0)"
