"""Calibration parameters in scaled coordinates.

``theta = log(p / nominal)`` for parameters with ``scaling = "log"`` (stiffnesses spanning
decades: k_c) and ``theta = p / nominal`` otherwise, so every coordinate is of order one and a
step in ``theta`` means the same to the optimiser for every parameter.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from analysis.model import Model

__all__ = ["ParameterSpace"]


@dataclass(frozen=True)
class ParameterSpace:
    """Names, scaling, nominal values and bounds of the calibrated parameters.

    Attributes
    ----------
    names : tuple of str
    log : ndarray of bool, shape (n,)
    nominal : ndarray, shape (n,)
        Reference values of the scaling (the model file's ``nominal``).
    lower, upper : ndarray, shape (n,)
        Bounds in physical units.
    """

    names: tuple[str, ...]
    log: np.ndarray
    nominal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def from_model(cls, model: Model, names: Sequence[str]) -> ParameterSpace:
        """The space of ``names`` as the model file describes them."""
        unknown = [n for n in names if n not in model.parameters]
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}; known: {sorted(model.parameters)}")
        ps = [model.parameters[n] for n in names]
        nominal = np.array([p.nominal if p.nominal else p.value for p in ps], dtype=float)
        if np.any(nominal == 0):
            bad = [p.name for p, v in zip(ps, nominal, strict=True) if v == 0]
            raise ValueError(f"parameters {bad}: nominal 0 cannot scale a calibration")
        return cls(
            names=tuple(names),
            log=np.array([p.scaling == "log" for p in ps]),
            nominal=nominal,
            lower=np.array([p.lower for p in ps], dtype=float),
            upper=np.array([p.upper for p in ps], dtype=float),
        )

    @property
    def size(self) -> int:
        return len(self.names)

    def to_theta(self, p: npt.ArrayLike) -> np.ndarray:
        """Scaled coordinates of physical values, shape (n,) (or (m, n) for m points)."""
        p = np.asarray(p, dtype=float)
        theta = p / self.nominal
        # the logarithm only of the log-scaled ones (a linear one may well be 0); p may hold
        # many points, one per row
        log = self.log
        theta[..., log] = np.log(np.abs(p[..., log]) / np.abs(self.nominal[log]))
        return theta

    def to_physical(self, theta: np.ndarray) -> np.ndarray:
        """Physical values of scaled coordinates, shape (n,)."""
        theta = np.asarray(theta, dtype=float)
        return np.where(self.log, self.nominal * np.exp(theta), theta * self.nominal)

    def dp_dtheta(self, theta: np.ndarray) -> np.ndarray:
        """Derivative of each physical value with respect to its coordinate, shape (n,)."""
        return np.where(self.log, self.to_physical(theta), self.nominal)

    def theta_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds in scaled coordinates (a log parameter's lower bound must be > 0)."""
        lo = np.where(
            self.log,
            np.log(np.maximum(self.lower, 1e-300) / self.nominal),
            self.lower / self.nominal,
        )
        hi = np.where(self.log, np.log(self.upper / self.nominal), self.upper / self.nominal)
        return np.minimum(lo, hi), np.maximum(lo, hi)

    def as_dict(self, p: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, p, strict=True)}
