"""Piecewise-linear clearance laws: one-sided stop, dead zone, bilinear spring.

Also the one-sided stop geometry (:func:`penetration`, :class:`OneSidedStop`) shared with the
Hertzian contact of :mod:`analysis.elements.contact`.
"""

from __future__ import annotations

from functools import cached_property
from typing import ClassVar

import numpy as np
from numba import njit

from .base import CompiledLaw, ElementEval, ElementParameterError, NonlinearElement, register

__all__ = ["BilinearSpring", "GapSpring", "OneSidedStop", "TwoSidedGap", "penetration"]


def penetration(u: np.ndarray, gap: float, side: int) -> tuple[np.ndarray, np.ndarray]:
    """Contact state and penetration of a one-sided stop.

    Parameters
    ----------
    u : ndarray, shape (...), m
        Relative displacement.
    gap : float, m
        Clearance, ``>= 0``.
    side : {-1, +1}
        ``-1``: stop below, contact while ``u < -gap``; ``+1``: stop above, ``u > gap``.

    Returns
    -------
    in_contact : ndarray of bool, shape (...)
        ``side * u > gap`` (strict: the switch itself counts as open).
    delta : ndarray, shape (...), m
        Penetration ``side * u - gap`` in contact, 0 elsewhere.
    """
    in_contact = side * u > gap
    return in_contact, np.where(in_contact, side * u - gap, 0.0)


class OneSidedStop(NonlinearElement):
    """Base of stops acting on one side of a clearance (not registered).

    Adds the option ``side`` (``-1`` default: stop below, ``+1``: stop above) and the
    parameters ``gap`` [m] ``>= 0``; subclasses use :func:`penetration`.
    """

    option_names: ClassVar[dict[str, object]] = {"side": -1}

    @property
    def side(self) -> int:
        """``-1`` (stop below) or ``+1`` (stop above)."""
        return int(self.options["side"])  # type: ignore[call-overload]

    def _validate(self) -> None:
        side = self._option_number("side")
        if side not in (-1.0, 1.0):
            raise ElementParameterError(
                "side",
                f"element {self.kind!r}: option 'side' must be -1 (stop below) or +1 "
                f"(stop above), got {self.options['side']!r}",
            )
        self.options["side"] = int(side)


@njit(cache=True)
def _stops_law(u, v, p):
    """``f``, ``df_du``, ``df_dv`` of linear stops of one stiffness and clearance on the sides
    given, ``p = (k, gap, side_1, ...)``, in the order of operations of :func:`_linear_stop`."""
    k, gap = p[0], p[1]
    n = u.size
    f, df_du = np.zeros(n), np.zeros(n)
    for j in range(2, p.size):
        side = p[j]
        for i in range(n):
            if side * u[i] > gap:
                f[i] += -side * k * (side * u[i] - gap)
                df_du[i] += -k
    return f, df_du, np.zeros(n)


@njit(cache=True)
def _bilinear_law(u, v, p):
    """``f``, ``df_du``, ``df_dv`` of the bilinear spring, ``p = (k_pos, k_neg)``."""
    n = u.size
    f, df_du = np.empty(n), np.empty(n)
    for i in range(n):
        df_du[i] = -p[0] if u[i] > 0 else -p[1]
        f[i] = df_du[i] * u[i]
    return f, df_du, np.zeros(n)


def _linear_stop(u: np.ndarray, k: float, gap: float, side: int) -> tuple[np.ndarray, ...]:
    """``f, df_du, df_dk, df_dgap`` of ``f = -side k (side u - gap)`` in contact, 0 outside."""
    in_contact, delta = penetration(u, gap, side)
    return (
        -side * k * delta,
        np.where(in_contact, -k, 0.0),
        -side * delta,
        np.where(in_contact, side * k, 0.0),
    )


@register
class GapSpring(OneSidedStop):
    """One-sided linear stop.

    ``side = -1``: ``f = k (-u - gap)`` for ``u < -gap``; ``side = +1``: ``f = -k (u - gap)``
    for ``u > gap``; ``f = 0`` otherwise. Continuous, with a kink at the switch
    ``u = side * gap``, which counts as open (zero derivatives).

    Parameters
    ----------
    k : float, N/m
        Stop stiffness, ``> 0``.
    gap : float, m
        Clearance, ``>= 0``.
    side : {-1, +1}, optional
        Option: side of the stop, default -1 (below).
    """

    kind = "gap_spring"
    param_names = ("k", "gap")
    param_units = ("N/m", "m")
    positive_params = ("k",)
    nonnegative_params = ("gap",)
    description = "one-sided linear stop: f = k(-u - gap) for u < -gap (side -1) or mirror"

    def compiled_law(self) -> tuple[CompiledLaw, np.ndarray]:
        """:func:`_stops_law` on the element's side."""
        return _stops_law, self._law_p

    @cached_property
    def _law_p(self) -> np.ndarray:
        return np.array([self._p[0], self._p[1], self.side], dtype=float)

    def _evaluate(self, u: np.ndarray, v: np.ndarray, want_params: bool) -> ElementEval:
        if not want_params and (ev := self._compiled_evaluate(u, v)) is not None:
            return ev
        f, df_du, df_dk, df_dgap = _linear_stop(u, self._p[0], self._p[1], self.side)
        df_dp = np.stack([df_dk, df_dgap]) if want_params else None
        return ElementEval(f, df_du, np.zeros_like(u), df_dp)


@register
class TwoSidedGap(NonlinearElement):
    """Dead-zone spring: ``f = -k (u - gap)`` for ``u > gap``, ``-k (u + gap)`` for
    ``u < -gap``, 0 between.

    Continuous with kinks at ``u = +-gap``, which count as open (zero derivatives); it is the
    sum of the two :class:`GapSpring` sides.

    Parameters
    ----------
    k : float, N/m
        Stiffness outside the clearance, ``> 0``.
    gap : float, m
        Half-width of the dead zone, ``>= 0``.
    """

    kind = "two_sided_gap"
    param_names = ("k", "gap")
    param_units = ("N/m", "m")
    positive_params = ("k",)
    nonnegative_params = ("gap",)
    description = "dead-zone spring: f = -k(u - gap) for u > gap, -k(u + gap) for u < -gap"

    def compiled_law(self) -> tuple[CompiledLaw, np.ndarray]:
        """:func:`_stops_law` on both sides."""
        return _stops_law, self._law_p

    @cached_property
    def _law_p(self) -> np.ndarray:
        return np.array([self._p[0], self._p[1], 1.0, -1.0])

    def _evaluate(self, u: np.ndarray, v: np.ndarray, want_params: bool) -> ElementEval:
        if not want_params and (ev := self._compiled_evaluate(u, v)) is not None:
            return ev
        upper, lower = (_linear_stop(u, self._p[0], self._p[1], side) for side in (1, -1))
        f, df_du, df_dk, df_dgap = (a + b for a, b in zip(upper, lower, strict=True))
        df_dp = np.stack([df_dk, df_dgap]) if want_params else None
        return ElementEval(f, df_du, np.zeros_like(u), df_dp)


@register
class BilinearSpring(NonlinearElement):
    """Bilinear spring: ``f = -k_pos u`` for ``u > 0``, ``f = -k_neg u`` otherwise.

    Continuous with a kink at ``u = 0``, where the ``k_neg`` branch is used
    (``df_du = -k_neg``).

    Parameters
    ----------
    k_pos, k_neg : float, N/m
        Stiffness for positive and non-positive ``u``, ``>= 0``.
    """

    kind = "bilinear_spring"
    param_names = ("k_pos", "k_neg")
    param_units = ("N/m", "N/m")
    nonnegative_params = param_names
    description = "bilinear spring: f = -k_pos u for u > 0, -k_neg u otherwise"

    def compiled_law(self) -> tuple[CompiledLaw, np.ndarray]:
        """:func:`_bilinear_law`."""
        return _bilinear_law, self._p

    def _evaluate(self, u: np.ndarray, v: np.ndarray, want_params: bool) -> ElementEval:
        if not want_params and (ev := self._compiled_evaluate(u, v)) is not None:
            return ev
        k_pos, k_neg = self._p
        positive = u > 0
        df_dp = np.stack([np.where(positive, -u, 0.0), np.where(positive, 0.0, -u)])
        df_du = np.where(positive, -k_pos, -k_neg)
        return ElementEval(df_du * u, df_du, np.zeros_like(u), df_dp if want_params else None)
