"""Hertzian contact with quadratic damping: the bump stop of ``docs/rig.md``."""

from __future__ import annotations

from functools import cached_property

import numpy as np
from numba import njit

from .base import CompiledLaw, ElementEval, register
from .gaps import OneSidedStop, penetration

__all__ = ["HertzContact"]


@njit(cache=True)
def _hertz_law(u, vel, p):
    """``f``, ``df_du``, ``df_dvel`` of the law at samples ``u``, ``vel`` for
    ``p = (k_c, gap, v, side)``, in the order of operations of the array code."""
    k_c, gap, c, side = p[0], p[1], p[2], p[3]
    n = u.size
    f, df_du, df_dvel = np.zeros(n), np.zeros(n), np.zeros(n)
    for m in range(n):
        if side * u[m] > gap:
            d = side * u[m] - gap
            root = np.sqrt(d)
            f[m] = -side * k_c * d * root - c * (vel[m] * abs(vel[m]))
            df_du[m] = -1.5 * k_c * root
            df_dvel[m] = -2.0 * c * abs(vel[m])
    return f, df_du, df_dvel


@register
class HertzContact(OneSidedStop):
    """Hertzian bump stop with quadratic damping, the paper's law kept exactly.

    With ``side = -1`` (default, stop below, as in ``docs/rig.md``)::

        f = k_c (-u - gap)^1.5 - v * vel * |vel|     for u < -gap
        f = 0                                        otherwise

    and with ``side = +1`` (stop above, the mirror)::

        f = -k_c (u - gap)^1.5 - v * vel * |vel|     for u > gap

    where ``vel`` is the relative velocity (the evaluate argument ``v``) and ``v`` the damping
    parameter. In contact the stiffness term pushes the structure out of the stop, while the
    damping term opposes the velocity: it also pulls the structure towards the stop while it
    leaves, and it makes the force jump by ``-v vel |vel|`` at entry and exit.

    At the switch ``u = side * gap`` the contact counts as open (strict inequality): all
    derivatives are 0 there. In contact, with penetration ``d = side u - gap``::

        df_du = -1.5 k_c d^0.5          df_dvel = -2 v |vel|
        df_dk_c = -side d^1.5           df_dgap = 1.5 side k_c d^0.5       df_dv = -vel |vel|

    Parameters
    ----------
    k_c : float, N/m^1.5
        Hertzian contact stiffness, ``> 0``.
    gap : float, m
        Clearance between the structure at rest and the stop, ``>= 0``.
    v : float, N s^2/m^2
        Quadratic damping coefficient, ``>= 0``.
    side : {-1, +1}, optional
        Option: side of the stop, default -1 (below).

    References
    ----------
    Y. Chen, A. Linderholt, T. Abrahamsson, Y. Xia, M.I. Friswell, "Validation of a model
    calibration method through vibrational testing of a mechanical system with local
    clearance", ISMA 2016.
    """

    kind = "hertz_contact"
    param_names = ("k_c", "gap", "v")
    param_units = ("N/m^1.5", "m", "N s^2/m^2")
    positive_params = ("k_c",)
    nonnegative_params = ("gap", "v")
    description = (
        "Hertzian bump stop with quadratic damping: f = k_c(-u - gap)^1.5 - v vel|vel| "
        "for u < -gap (side -1) or mirror"
    )

    def switch_threshold(self) -> tuple[float, np.ndarray]:
        """The damping term jumps at ``u = side * gap``."""
        return self.side * self._p[1], np.array([0.0, float(self.side), 0.0])

    def compiled_law(self) -> tuple[CompiledLaw, np.ndarray]:
        """Numba code of the law (the balance evaluates it some thousand times per sweep,
        mostly on a few hundred samples, where numpy's per-call overhead dominates); the
        array code below gives the parameter derivatives and is its reference."""
        return _hertz_law, self._law_p

    @cached_property
    def _law_p(self) -> np.ndarray:
        return np.append(self._p, float(self.side))

    def _evaluate(self, u: np.ndarray, vel: np.ndarray, want_params: bool) -> ElementEval:
        if not want_params and (ev := self._compiled_evaluate(u, vel)) is not None:
            return ev
        k_c, gap, c = self._p
        side = self.side
        in_contact, d = penetration(u, gap, side)
        root = np.sqrt(d)
        damping = np.where(in_contact, vel * np.abs(vel), 0.0)
        f = -side * k_c * d * root - c * damping
        df_du = -1.5 * k_c * root
        df_dvel = np.where(in_contact, -2.0 * c * np.abs(vel), 0.0)
        df_dp = np.stack([-side * d * root, 1.5 * side * k_c * root, -damping])
        return ElementEval(f, df_du, df_dvel, df_dp)
