"""Planar Euler-Bernoulli frame element: axial bar plus bending beam, consistent mass.

Each node has three DOFs in the global frame, in the order ``(u_x, u_y, r_z)``: translations
[m] and the rotation about z [rad]. The element matrices are linear in their material
coefficients: the stiffness is ``E`` times :func:`stiffness_matrix` evaluated with ``E = 1``
and the mass is the mass per length times :func:`mass_matrix` evaluated with ``1 kg/m``; the
assembly uses this to build exact parameter derivatives.

References
----------
J.S. Przemieniecki, *Theory of Matrix Structural Analysis*, McGraw-Hill, 1968, ch. 5 and 11
(frame element stiffness and consistent mass).
"""

from __future__ import annotations

import math

import numpy as np

from ..settings import SettingError, Text, declare, settings
from .values import Finite

__all__ = ["SECTION_SHAPES", "Section", "mass_matrix", "rotation_matrix", "stiffness_matrix"]

SECTION_SHAPES = ("rect", "rect_tube", "general")


@settings()
class Section:
    """Cross-section of a frame member: ``rect`` (solid rectangle ``b x h``, ``h`` in the
    bending direction), ``rect_tube`` (square hollow tube) or ``general`` (area and second
    moment given directly; computed for the other shapes)."""

    shape: Text = declare(f"Shape: one of {', '.join(SECTION_SHAPES)}.", "general")
    b_m: Finite | None = declare("Width of a solid rectangle [m].", None, key="b")
    h_m: Finite | None = declare("Height of a solid rectangle [m].", None, key="h")
    outer_m: Finite | None = declare("Outer side of a square tube [m].", None, key="outer")
    wall_m: Finite | None = declare("Wall thickness of a square tube [m].", None, key="wall")
    area_m2: Finite | None = declare("Area [m^2] (general only).", None, key="A")
    inertia_m4: Finite | None = declare(
        "Second moment about the bending axis [m^4].", None, key="I"
    )

    def __post_init__(self) -> None:
        needed = {
            "rect": ("b_m", "h_m"),
            "rect_tube": ("outer_m", "wall_m"),
            "general": ("area_m2", "inertia_m4"),
        }
        if self.shape not in needed:
            raise SettingError(
                ("shape",), f"unknown shape {self.shape!r}; expected one of {SECTION_SHAPES}"
            )
        for name in ("b_m", "h_m", "outer_m", "wall_m", "area_m2", "inertia_m4"):
            value = getattr(self, name)
            if name in needed[self.shape]:
                if value is None:
                    raise SettingError((name,), f"required for shape {self.shape!r}")
                if not (math.isfinite(value) and value > 0):
                    raise SettingError((name,), f"must be a positive number, got {value!r}")
            elif value is not None and name not in ("area_m2", "inertia_m4"):
                raise SettingError((name,), f"not used by shape {self.shape!r}")
        if self.shape == "rect_tube" and not 2 * self.wall_m < self.outer_m:
            raise SettingError(
                ("wall_m",), f"wall {self.wall_m} m is too thick for outer side {self.outer_m} m"
            )
        if self.shape != "general":
            object.__setattr__(self, "area_m2", self._area())
            object.__setattr__(self, "inertia_m4", self._inertia())

    def _area(self) -> float:
        if self.shape == "rect":
            return self.b_m * self.h_m
        inner = self.outer_m - 2 * self.wall_m
        return self.outer_m**2 - inner**2

    def _inertia(self) -> float:
        if self.shape == "rect":
            return self.b_m * self.h_m**3 / 12
        inner = self.outer_m - 2 * self.wall_m
        return (self.outer_m**4 - inner**4) / 12


def rotation_matrix(cos_a: float, sin_a: float) -> np.ndarray:
    """Global-to-local transformation of a 2-node frame element.

    Parameters
    ----------
    cos_a, sin_a : float
        Direction cosines of the element axis (node a to node b) in the global frame.

    Returns
    -------
    ndarray, shape (6, 6)
        ``T`` with ``q_local = T @ q_global``; ``T`` is orthogonal.
    """
    r = np.array([[cos_a, sin_a, 0.0], [-sin_a, cos_a, 0.0], [0.0, 0.0, 1.0]])
    T = np.zeros((6, 6))
    T[:3, :3] = r
    T[3:, 3:] = r
    return T


def _local_stiffness(E: float, A: float, I: float, L: float) -> np.ndarray:
    k = np.zeros((6, 6))
    a = E * A / L
    k[np.ix_([0, 3], [0, 3])] = a * np.array([[1.0, -1.0], [-1.0, 1.0]])
    b = E * I / L**3
    bend = np.array(
        [
            [12.0, 6 * L, -12.0, 6 * L],
            [6 * L, 4 * L**2, -6 * L, 2 * L**2],
            [-12.0, -6 * L, 12.0, -6 * L],
            [6 * L, 2 * L**2, -6 * L, 4 * L**2],
        ]
    )
    k[np.ix_([1, 2, 4, 5], [1, 2, 4, 5])] = b * bend
    return k


def _local_mass(m: float, L: float) -> np.ndarray:
    mm = np.zeros((6, 6))
    mm[np.ix_([0, 3], [0, 3])] = m * L / 6 * np.array([[2.0, 1.0], [1.0, 2.0]])
    bend = np.array(
        [
            [156.0, 22 * L, 54.0, -13 * L],
            [22 * L, 4 * L**2, 13 * L, -3 * L**2],
            [54.0, 13 * L, 156.0, -22 * L],
            [-13 * L, -3 * L**2, -22 * L, 4 * L**2],
        ]
    )
    mm[np.ix_([1, 2, 4, 5], [1, 2, 4, 5])] = m * L / 420 * bend
    return mm


def _geometry(xy_a: np.ndarray, xy_b: np.ndarray) -> tuple[float, np.ndarray]:
    d = np.asarray(xy_b, dtype=float) - np.asarray(xy_a, dtype=float)
    L = float(np.hypot(d[0], d[1]))
    if not L > 0:
        raise ValueError("element has zero length")
    return L, rotation_matrix(d[0] / L, d[1] / L)


def stiffness_matrix(
    xy_a: np.ndarray, xy_b: np.ndarray, E: float, area_m2: float, inertia_m4: float
) -> np.ndarray:
    """Global stiffness matrix of a frame element.

    Parameters
    ----------
    xy_a, xy_b : ndarray, shape (2,), m
        Node coordinates.
    E : float, Pa
        Young's modulus.
    area_m2 : float, m^2
    inertia_m4 : float, m^4
        Second moment of area about z.

    Returns
    -------
    ndarray, shape (6, 6)
        In N/m, N, N m over ``(u_xa, u_ya, r_za, u_xb, u_yb, r_zb)``.
    """
    L, T = _geometry(xy_a, xy_b)
    return T.T @ _local_stiffness(E, area_m2, inertia_m4, L) @ T


def mass_matrix(xy_a: np.ndarray, xy_b: np.ndarray, mass_per_length_kg_m: float) -> np.ndarray:
    """Global consistent mass matrix of a frame element (rotary inertia of the section neglected).

    Parameters
    ----------
    xy_a, xy_b : ndarray, shape (2,), m
        Node coordinates.
    mass_per_length_kg_m : float, kg/m
        ``rho * A`` plus any non-structural mass.

    Returns
    -------
    ndarray, shape (6, 6)
        In kg, kg m, kg m^2 over ``(u_xa, u_ya, r_za, u_xb, u_yb, r_zb)``. The translational
        mass is isotropic, so a rigid translation in any direction carries ``m L``.
    """
    L, T = _geometry(xy_a, xy_b)
    return T.T @ _local_mass(mass_per_length_kg_m, L) @ T
