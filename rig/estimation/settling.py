"""Settling test: are the block phasors steady enough to accept a step?

After a drive change the structure's free transient decays with time constants
``1 / (zeta omega)`` of the modes near the drive. While it lasts, the phasors of consecutive
blocks differ by more than the noise. The test compares each consecutive change
``|X_{b+1} - X_b|`` of the checked orders with a tolerance

    tol = max(relative_tolerance * |X_last|, noise_factor * sqrt(2) * sigma),

where ``sigma`` is the per-block noise scatter of the phasor (``sqrt(2) sigma`` is the scatter
of a difference of two blocks). ``sigma`` is given by the caller (for example from a quiet
record or a settled earlier step) or estimated from the anti-correlation of consecutive changes
over the last half of the blocks, an estimate that a transient or a drift pulls down, not up (see
``_noise_from_difference_correlation``). With an estimated floor, a record of pure noise
settles within 20 blocks in about 97 % of cases; pass ``noise_std`` when it is known.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from rig.signals.multisine import as_orders

__all__ = ["SettlingCriteria", "SettlingVerdict", "check_settling"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SettlingCriteria:
    """When the block phasors count as settled.

    Parameters
    ----------
    relative_tolerance : float
        Allowed change between consecutive blocks relative to the phasor's amplitude.
    noise_factor : float
        Allowed change in units of the noise scatter of a block difference; keeps noisy
        channels from never settling (3 gives a false alarm rate of ``exp(-9)`` per check).
    consecutive_blocks : int
        Number of consecutive changes at the end of the record that must all be within tolerance.
    orders : tuple of Fraction
        Orders checked (default the fundamental).
    channels : tuple of int, optional
        Channel columns checked (default all).
    """

    relative_tolerance: float = 0.01
    noise_factor: float = 3.0
    consecutive_blocks: int = 2
    orders: tuple[Fraction, ...] = (Fraction(1),)
    channels: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.relative_tolerance) and self.relative_tolerance > 0):
            raise ValueError(
                f"SettlingCriteria.relative_tolerance: must be > 0, got {self.relative_tolerance}"
            )
        if not (math.isfinite(self.noise_factor) and self.noise_factor >= 0):
            raise ValueError(
                f"SettlingCriteria.noise_factor: must be >= 0, got {self.noise_factor}"
            )
        if self.consecutive_blocks < 1:
            raise ValueError(
                f"SettlingCriteria.consecutive_blocks: must be >= 1, got {self.consecutive_blocks}"
            )
        object.__setattr__(self, "orders", as_orders(self.orders, "SettlingCriteria.orders"))
        if self.channels is not None:
            channels = tuple(int(c) for c in self.channels)
            if not channels or min(channels) < 0:
                raise ValueError(
                    f"SettlingCriteria.channels: need non-negative indices, got {self.channels}"
                )
            object.__setattr__(self, "channels", channels)


@dataclass(frozen=True)
class SettlingVerdict:
    """Outcome of :func:`check_settling`, with the numbers behind it.

    Attributes
    ----------
    settled : bool
        The last ``consecutive_blocks`` changes are all within tolerance.
    settled_from_block : int or None
        First block from which every later change is within tolerance (None if the last change
        is not); the blocks from here on can be averaged.
    change_ratios : ndarray, shape (B - 1,), float
        Worst ``|X_{b+1} - X_b| / tol`` over the checked channels and orders, per change.
    tolerance : ndarray, shape (C', H'), channel units
        Tolerance of each checked channel and order.
    noise_std : ndarray, shape (C', H'), channel units
        Per-block noise scatter used (given or estimated).
    message : str
        One line for the log and the step record.
    """

    settled: bool
    settled_from_block: int | None
    change_ratios: np.ndarray
    tolerance: np.ndarray
    noise_std: np.ndarray
    message: str


def _noise_from_difference_correlation(x: np.ndarray) -> np.ndarray:
    """Per-block noise scatter (C', H') from the last half of the blocks (needs B >= 4).

    For white block noise the consecutive changes ``d_b = X_{b+1} - X_b`` are anti-correlated,
    ``E[Re(d_{b+1} conj(d_b))] = -sigma^2``; a decaying transient or a drift makes consecutive
    changes point the same way and drives the estimate towards zero, so the noise floor can
    only tighten the test while the record is still settling.
    """
    tail = x[-max(4, x.shape[0] // 2) :]
    d = np.diff(tail, axis=0)
    lag = np.mean(np.real(d[1:] * np.conj(d[:-1])), axis=0)
    return np.sqrt(np.maximum(-lag, 0.0))


def _select(block_phasors: np.ndarray, orders: tuple[Fraction, ...], crit: SettlingCriteria):
    x = np.asarray(block_phasors, dtype=complex)
    if x.ndim == 2:
        x = x[:, None, :]
    if x.ndim != 3 or x.shape[2] != len(orders):
        raise ValueError(
            f"block_phasors: expected shape (B, C, {len(orders)}), got {np.shape(block_phasors)}"
        )
    missing = [str(o) for o in crit.orders if o not in orders]
    if missing:
        raise ValueError(f"SettlingCriteria.orders: {missing} not among the measured orders")
    cols = [orders.index(o) for o in crit.orders]
    rows = list(crit.channels) if crit.channels is not None else list(range(x.shape[1]))
    if max(rows) >= x.shape[1]:
        raise ValueError(f"SettlingCriteria.channels: {rows} beyond the {x.shape[1]} channels")
    return x[:, rows][:, :, cols]


def check_settling(
    block_phasors: np.ndarray,
    orders: Iterable[object],
    criteria: SettlingCriteria | None = None,
    noise_std: np.ndarray | float | None = None,
) -> SettlingVerdict:
    """Decide whether consecutive block phasors have stopped changing.

    Parameters
    ----------
    block_phasors : ndarray, shape (B, C, H) or (B, H), complex, channel units
        Phasors of consecutive blocks (``HarmonicEstimate.block_phasors``), oldest first.
    orders : iterable of rationals
        The H orders of the last axis.
    criteria : SettlingCriteria, optional
        Tolerances and what to check (defaults: 1 %, fundamental, all channels).
    noise_std : ndarray, shape (C', H'), or float, optional
        Per-block noise scatter of the checked phasors; estimated from the data if omitted.

    Returns
    -------
    SettlingVerdict
    """
    crit = criteria or SettlingCriteria()
    x = _select(block_phasors, as_orders(orders), crit)
    n_blocks = x.shape[0]
    if n_blocks < 2:
        raise ValueError(f"block_phasors: need at least 2 blocks, got {n_blocks}")
    if noise_std is None:
        sigma = _noise_from_difference_correlation(x) if n_blocks >= 4 else np.zeros(x.shape[1:])
    else:
        sigma = np.broadcast_to(np.asarray(noise_std, dtype=float), x.shape[1:]).copy()
    tol = np.maximum(
        crit.relative_tolerance * np.abs(x[-1]), crit.noise_factor * math.sqrt(2.0) * sigma
    )
    tol = np.maximum(tol, np.finfo(float).tiny)
    ratios = np.max(np.abs(np.diff(x, axis=0)) / tol, axis=(1, 2))
    outside = np.flatnonzero(ratios > 1.0)
    start = 0 if outside.size == 0 else int(outside[-1]) + 1
    settled_from = start if start <= n_blocks - 2 else None
    within = n_blocks - 1 - start
    settled = within >= crit.consecutive_blocks
    message = (
        f"{'settled' if settled else 'not settled'}: the last {within} consecutive changes are "
        f"within tolerance (need {crit.consecutive_blocks}); last change "
        f"{ratios[-1]:.3g} x tolerance, worst {ratios.max():.3g} x over {n_blocks} blocks"
    )
    logger.debug(message)
    return SettlingVerdict(settled, settled_from, ratios, tol, sigma, message)
