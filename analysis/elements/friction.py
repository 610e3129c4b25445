"""Regularised Coulomb friction (memoryless)."""

from __future__ import annotations

from functools import cached_property

import numpy as np
from numba import njit

from .base import CompiledLaw, ElementEval, ElementParameterError, NonlinearElement, register

__all__ = ["CoulombFriction"]


@njit(cache=True)
def _coulomb_law(u, v, p):
    """``f``, ``df_du``, ``df_dv`` at samples ``u``, ``v`` for ``p = (f_slip, v_reg)``."""
    f_slip, v_reg = p[0], p[1]
    n = v.size
    f, df_dv = np.empty(n), np.empty(n)
    for i in range(n):
        t = np.tanh(v[i] / v_reg)
        f[i] = -f_slip * t
        df_dv[i] = -(f_slip / v_reg) * (1.0 - t * t)
    return f, np.zeros(n), df_dv


@register
class CoulombFriction(NonlinearElement):
    """Coulomb friction regularised by a hyperbolic tangent, ``f = -f_slip tanh(v / v_reg)``.

    The law depends on the current velocity only: it is memoryless and has no stick phase
    (near ``v = 0`` it acts as a stiff viscous damper of coefficient ``f_slip / v_reg``).
    A stick-slip (Jenkins, hysteretic) joint needs an internal state and is not part of this
    library. The law is smooth, so the derivatives are exact everywhere:
    ``df_dv = -(f_slip / v_reg) (1 - tanh^2)``, ``df_df_slip = -tanh(v / v_reg)``.

    Parameters
    ----------
    f_slip : float, N
        Slip force, ``>= 0``.
    v_reg : float, m/s, optional
        Regularisation velocity (option, not calibrated), ``> 0``; default 1e-3.
    """

    kind = "coulomb_friction"
    param_names = ("f_slip",)
    param_units = ("N",)
    nonnegative_params = ("f_slip",)
    option_names = {"v_reg": 1e-3}
    description = "Coulomb friction f = -f_slip tanh(v / v_reg), memoryless (no stick)"

    def _validate(self) -> None:
        v_reg = self._option_number("v_reg")
        if not v_reg > 0:
            raise ElementParameterError(
                "v_reg", f"element {self.kind!r}: option 'v_reg' must be > 0, got {v_reg}"
            )
        self.options["v_reg"] = v_reg

    def compiled_law(self) -> tuple[CompiledLaw, np.ndarray]:
        """:func:`_coulomb_law` (the numpy code below gives the parameter derivative)."""
        return _coulomb_law, self._law_p

    @cached_property
    def _law_p(self) -> np.ndarray:
        return np.array([self._p[0], self.options["v_reg"]], dtype=float)

    def _evaluate(self, u: np.ndarray, v: np.ndarray, want_params: bool) -> ElementEval:
        if not want_params and (ev := self._compiled_evaluate(u, v)) is not None:
            return ev
        (f_slip,) = self._p
        v_reg = self.options["v_reg"]
        t = np.tanh(v / v_reg)
        df_dv = -(f_slip / v_reg) * (1.0 - t * t)
        return ElementEval(-f_slip * t, np.zeros_like(u), df_dv, -t[None] if want_params else None)
