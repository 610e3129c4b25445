"""Viscous dampers: odd power laws of the relative velocity ``v``."""

from __future__ import annotations

from .base import register
from .polynomial import PowerSeriesElement

__all__ = ["CubicDamper", "LinearDamper", "QuadraticDamper"]


class _Damper(PowerSeriesElement):
    """Single-term damper ``f = -c v |v|^(n - 1)``: always opposes the velocity."""

    on_velocity = True
    signed = True


@register
class LinearDamper(_Damper):
    """Linear viscous damper ``f = -c v``.

    Parameters
    ----------
    c : float, N s/m
        Damping coefficient, ``>= 0``.
    """

    kind = "linear_damper"
    param_names = ("c",)
    param_units = ("N s/m",)
    nonnegative_params = param_names
    powers = (1,)
    description = "linear viscous damper f = -c v"


@register
class QuadraticDamper(_Damper):
    """Quadratic damper ``f = -c2 v |v|``.

    Once differentiable at ``v = 0`` (``df_dv = -2 c2 |v|``), so exact everywhere.

    Parameters
    ----------
    c2 : float, N s^2/m^2
        Coefficient, ``>= 0``.
    """

    kind = "quadratic_damper"
    param_names = ("c2",)
    param_units = ("N s^2/m^2",)
    nonnegative_params = param_names
    powers = (2,)
    description = "quadratic damper f = -c2 v|v|"


@register
class CubicDamper(_Damper):
    """Cubic damper ``f = -c3 v^3``.

    Parameters
    ----------
    c3 : float, N s^3/m^3
        Coefficient, ``>= 0``.
    """

    kind = "cubic_damper"
    param_names = ("c3",)
    param_units = ("N s^3/m^3",)
    nonnegative_params = param_names
    powers = (3,)
    description = "cubic damper f = -c3 v^3"
