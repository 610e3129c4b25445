"""Harmonic basis and the alternating frequency-time (AFT) transform.

A periodic signal of base frequency ``omega_b`` (the fundamental divided by the least common
denominator of the orders, so sub-harmonics are whole harmonics of the base) is stored as real
coefficients ``c = [a0, a1, b1, ..., aH, bH]``::

    x(tau) = a0 + sum_k a_k cos(k tau) + b_k sin(k tau),   tau = omega_b t.

The complex phasor of harmonic ``k`` in the measurement-file convention
``x(t) = Re{ sum_k X_k exp(i k omega_b t) }`` is ``X_k = a_k - i b_k`` (``X_0 = a0``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from functools import reduce

import numpy as np

__all__ = ["HarmonicBasis", "base_denominator", "order_indices"]


def base_denominator(orders: list[Fraction] | tuple[Fraction, ...]) -> int:
    """Least common denominator of the orders: the fundamental is this harmonic of the base."""
    return reduce(math.lcm, (Fraction(o).denominator for o in orders), 1)


def order_indices(orders, denominator: int) -> np.ndarray:
    """Harmonic index (of the base frequency) of each order, shape (n_orders,)."""
    idx = []
    for o in orders:
        k = Fraction(o) * denominator
        if k.denominator != 1 or k <= 0:
            raise ValueError(f"order {o} is not a positive multiple of 1/{denominator}")
        idx.append(int(k))
    return np.asarray(idx, dtype=int)


@dataclass(frozen=True)
class HarmonicBasis:
    """Harmonics ``0..n_harmonics`` of the base frequency sampled at ``n_time`` points.

    Parameters
    ----------
    n_harmonics : int
        Highest harmonic ``H`` of the base frequency kept in the balance.
    n_time : int
        AFT time samples per base period; at least ``2 H + 1`` (non-smooth laws want many more).
    denominator : int
        The fundamental is harmonic ``denominator`` of the base (1 without sub-harmonics).
    """

    n_harmonics: int
    n_time: int
    denominator: int = 1
    E: np.ndarray = field(init=False, repr=False, compare=False)
    dE: np.ndarray = field(init=False, repr=False, compare=False)
    P: np.ndarray = field(init=False, repr=False, compare=False)
    EdE: np.ndarray = field(init=False, repr=False, compare=False)
    PP: np.ndarray = field(init=False, repr=False, compare=False)
    k: np.ndarray = field(init=False, repr=False, compare=False)
    jump_weights: np.ndarray = field(init=False, repr=False, compare=False)
    _tau: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        H, N = self.n_harmonics, self.n_time
        if H < 1:
            raise ValueError(f"HarmonicBasis.n_harmonics: must be >= 1, got {H}")
        if N < 2 * H + 1:
            raise ValueError(f"HarmonicBasis.n_time: must be >= 2H+1 = {2 * H + 1}, got {N}")
        if self.denominator < 1:
            raise ValueError("HarmonicBasis.denominator: must be >= 1")
        tau = 2 * np.pi * np.arange(N) / N
        k = np.arange(1, H + 1)
        E = np.empty((N, 2 * H + 1))
        dE = np.zeros((N, 2 * H + 1))
        E[:, 0] = 1.0
        E[:, 1::2] = np.cos(np.outer(tau, k))
        E[:, 2::2] = np.sin(np.outer(tau, k))
        dE[:, 1::2] = -k * E[:, 2::2]
        dE[:, 2::2] = k * E[:, 1::2]
        w = np.full(2 * H + 1, 2.0 / N)
        w[0] = 1.0 / N
        object.__setattr__(self, "E", E)
        object.__setattr__(self, "dE", dE)
        object.__setattr__(self, "P", (E * w).T.copy())
        object.__setattr__(self, "_tau", tau)
        # for the AFT's hot path: samples of a signal and its tau-derivative in one product,
        # the projection twice over (for df/du and df/dv), the harmonic numbers
        object.__setattr__(self, "EdE", np.vstack([E, dE]))
        object.__setattr__(self, "PP", np.hstack([self.P, self.P]))
        object.__setattr__(self, "k", k.astype(float))
        # integral weights: coefficient c = jump_weights[c] * integral of f phi_c over a period
        jw = np.full(2 * H + 1, 1.0 / np.pi)
        jw[0] = 0.5 / np.pi
        object.__setattr__(self, "jump_weights", jw)

    @property
    def size(self) -> int:
        """Number of real coefficients per signal, ``2 H + 1``."""
        return 2 * self.n_harmonics + 1

    @property
    def tau(self) -> np.ndarray:
        """Sample phases of the base period, shape (n_time,), rad."""
        return self._tau

    def to_time(self, c: np.ndarray) -> np.ndarray:
        """Samples of signals, shape (n_time, ...) from coefficients of shape (2H+1, ...)."""
        return np.tensordot(self.E, c, axes=(1, 0))

    def rate_to_time(self, c: np.ndarray, omega_base: float) -> np.ndarray:
        """Samples of the time derivative, shape (n_time, ...)."""
        return omega_base * np.tensordot(self.dE, c, axes=(1, 0))

    def from_time(self, x: np.ndarray) -> np.ndarray:
        """Coefficients, shape (2H+1, ...) of sampled signals of shape (n_time, ...)."""
        return np.tensordot(self.P, x, axes=(1, 0))

    def to_complex(self, c: np.ndarray) -> np.ndarray:
        """Phasors ``X_k`` for ``k = 0..H``, shape (H+1, ...), from coefficients."""
        c = np.asarray(c)
        X = np.empty((self.n_harmonics + 1,) + c.shape[1:], dtype=complex)
        # parts written in place: a complex temporary costs a solve point more than its Newton
        X.real[0], X.imag[0] = c[0], 0.0
        X.real[1:] = c[1::2]
        np.negative(c[2::2], out=X.imag[1:])
        return X

    def from_complex(self, X: np.ndarray) -> np.ndarray:
        """Coefficients from phasors of shape (H+1, ...); ``X_0`` must be real."""
        X = np.asarray(X)
        c = np.empty((self.size,) + X.shape[1:])
        c[0] = X[0].real
        c[1::2] = X[1:].real
        c[2::2] = -X[1:].imag
        return c

    def time_shift_matrix(self, dtau: float) -> np.ndarray:
        """Operator on coefficients that delays a signal by ``dtau`` (rad of the base)."""
        S = np.zeros((self.size, self.size))
        S[0, 0] = 1.0
        for k in range(1, self.n_harmonics + 1):
            c, s = math.cos(k * dtau), math.sin(k * dtau)
            i = 2 * k - 1
            S[i : i + 2, i : i + 2] = [[c, -s], [s, c]]
        return S
