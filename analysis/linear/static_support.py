"""A support that acts on the mean response only: the shaker holding the drive point.

A shaker on a stinger pushes the structure with the force the impedance head measures. At
every excitation order that force is in the measurement file, so the model is driven by it and
the shaker itself need not be modelled. The mean (order 0) is different: IEPE channels are
AC-coupled, so the mean force is not measured, yet a structure with a one-sided contact moves
its mean position and the shaker's suspension (in series with the stinger) pushes back on it.
:class:`StaticSupport` adds that static stiffness ``k`` at the drive DOF ``d`` to the
receptance at ``omega = 0`` only (Sherman-Morrison)::

    H'(0) = H(0) - k H(0)[:, d] H(0)[d, :] / (1 + k H(0)[d, d])

and leaves every other frequency unchanged. Derivatives with respect to the structure's
parameters follow from the same formula.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis.linear.receptance import frequency_derivative

__all__ = ["StaticSupport"]


@dataclass
class _SupportedBlock:
    inner: Any
    to_drive: Any
    from_drive: Any
    drive: Any
    stiffness: float
    _static: tuple | None = field(default=None, init=False, repr=False, compare=False)
    _dstatic: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def shape(self) -> tuple[int, int]:
        return self.inner.shape

    def __call__(self, omega: np.ndarray) -> np.ndarray:
        w = np.atleast_1d(np.asarray(omega, dtype=float))
        H = np.array(self.inner(w))
        static = w == 0
        if np.any(static):
            a, b, hdd = self._static_terms()
            H[static] -= self.stiffness * (a @ b) / (1.0 + self.stiffness * hdd)
        return H

    def frequency_derivative(self, omega: np.ndarray) -> np.ndarray:
        """``dH/domega``: the structure's. The support changes ``H`` at ``omega = 0`` alone,
        where a balance's harmonic 0 sits whatever the frequency."""
        return frequency_derivative(self.inner, omega)

    def derivative(self, omega: np.ndarray, param: str) -> np.ndarray:
        w = np.atleast_1d(np.asarray(omega, dtype=float))
        dH = np.array(self.inner.derivative(w, param))
        static = w == 0
        if np.any(static):
            dH[static] -= self._static_derivative(param)
        return dH

    def _static_derivative(self, param: str) -> np.ndarray:
        """The support's term of ``dH(0)/dp`` (fixed, as the static terms are: once per
        parameter, where a sensitivity asks for it at every step)."""
        if param not in self._dstatic:
            k = self.stiffness
            a, b, hdd = self._static_terms()
            zero = np.zeros(1)
            da = self.to_drive.derivative(zero, param)[0]
            db = self.from_drive.derivative(zero, param)[0]
            dhdd = self.drive.derivative(zero, param)[0, 0, 0].real
            D = 1.0 + k * hdd
            self._dstatic[param] = k * (da @ b + a @ db) / D - k**2 * (a @ b) * dhdd / D**2
        return self._dstatic[param]

    def _static_terms(self) -> tuple[np.ndarray, np.ndarray, float]:
        # the blocks' receptances are fixed (a model with other values has other blocks), so
        # the static terms are evaluated once: every balance evaluates its blocks at order 0
        if self._static is None:
            zero = np.zeros(1)
            a = self.to_drive(zero)[0]  # (rows, 1)
            b = self.from_drive(zero)[0]  # (1, cols)
            hdd = float(self.drive(zero)[0, 0, 0].real)
            self._static = a, b, hdd
        return self._static


class StaticSupport:
    """A linear model with a spring to ground at one DOF that acts at ``omega = 0`` only.

    Parameters
    ----------
    linear : LinearModel
        The structure (``block(rows, cols)`` with ``__call__`` and ``derivative``).
    dof : int
        Structural DOF index of the support (the drive DOF).
    stiffness : float
        Static stiffness [N/m] (>= 0): the shaker's suspension in series with the stinger.
    """

    def __init__(self, linear, dof: int, stiffness: float) -> None:
        if not (np.isfinite(stiffness) and stiffness >= 0):
            raise ValueError(f"StaticSupport.stiffness: expected >= 0 N/m, got {stiffness!r}")
        self.linear = linear
        self.dof = int(dof)
        self.stiffness = float(stiffness)
        self.param_names = tuple(getattr(linear, "param_names", ()))

    def block(self, rows: list[int], cols: list[int]) -> _SupportedBlock:
        """Receptance block between DOF index lists ``rows`` and ``cols``."""
        rows, cols, d = list(rows), list(cols), [self.dof]
        lin = self.linear
        return _SupportedBlock(
            lin.block(rows, cols),
            lin.block(rows, d),
            lin.block(d, cols),
            lin.block(d, d),
            self.stiffness,
        )
