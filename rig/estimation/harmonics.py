"""Harmonic (phasor) estimation from phase-synchronous blocks.

Input and output share one sample clock and one start trigger, so a sample index is a phase
reference. The record after settling is cut into blocks of a whole number of base periods; in
each block every order has a whole number of cycles, and the DFT bin of that cycle count is the
exact least-squares phasor of the order (no leakage, no window). Block phasors are averaged;
their scatter gives the standard error of the mean.

Phasor convention (``docs/measurement-file.md``): ``x(t) = Re{sum_k X_k exp(i omega_k t)}`` with
``|X_k|`` the amplitude and ``t = 0`` at the start of the first averaged block.

Leakage
-------
A component at a frequency that is *not* a whole multiple of the base frequency (mains hum, a
free transient at a natural frequency, a drive whose realised frequency was not passed in) is
not orthogonal to the orders over one block: it leaks into every order with the Dirichlet
kernel of the block length. Such content changes from block to block, so it shows up in the
block scatter (``std``) and in :attr:`HarmonicEstimate.nonperiodic_rms`, the RMS of what is not
periodic in the base period; compare that with the channel's noise floor to flag it. Harmonics
of the base frequency that are not among the orders (the 4th, 5th, ... harmonics of a contact
nonlinearity) are orthogonal to the orders and do not leak.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Iterable
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from rig.signals.multisine import as_orders, base_denominator

__all__ = ["HarmonicEstimate", "estimate_harmonics", "period_aligned_offset", "samples_per_period"]

logger = logging.getLogger(__name__)

_PERIOD_TOLERANCE = 1e-6


@dataclass(frozen=True)
class HarmonicEstimate:
    """Averaged phasors of every channel at every order.

    Attributes
    ----------
    orders : tuple of Fraction
        Harmonic orders (H of them), the column order of the phasor arrays.
    frequencies_hz : ndarray, shape (H,), Hz
        Frequency of each order.
    phasors : ndarray, shape (C, H), complex, channel units
        Mean of the block phasors.
    std : ndarray, shape (C, H), float, channel units
        Standard error of ``phasors``: ``sqrt(E|X_hat - X|^2)`` estimated as the block scatter
        ``sqrt(sum_b |X_b - X_hat|^2 / (B - 1)) / sqrt(B)``; NaN when ``B == 1``.
    block_phasors : ndarray, shape (B, C, H), complex, channel units
        Phasor of every block, all referenced to the start of the first block.
    nonperiodic_rms : ndarray, shape (C,), float, channel units
        RMS of the samples minus their block-averaged waveform (noise, drift, non-synchronous
        content), corrected for the B-1 degrees of freedom; NaN when ``B == 1``.
    samples_per_block : int
        Samples in one block.
    first_index_offset : int
        Index into the input array of the first sample of block 0 (the phase origin).
    """

    orders: tuple[Fraction, ...]
    frequencies_hz: np.ndarray
    phasors: np.ndarray
    std: np.ndarray
    block_phasors: np.ndarray
    nonperiodic_rms: np.ndarray
    samples_per_block: int
    first_index_offset: int

    def __post_init__(self) -> None:
        b, c, h = self.block_phasors.shape
        if len(self.orders) != h or self.phasors.shape != (c, h) or self.std.shape != (c, h):
            raise ValueError(
                f"HarmonicEstimate: inconsistent shapes: orders {len(self.orders)}, phasors "
                f"{self.phasors.shape}, std {self.std.shape}, block_phasors {(b, c, h)}"
            )

    @property
    def n_blocks(self) -> int:
        """Number of averaged blocks B."""
        return self.block_phasors.shape[0]

    def split(self, n: int) -> tuple[HarmonicEstimate, HarmonicEstimate]:
        """The first ``n`` orders and the others, as two estimates from the same blocks."""

        def part(sl: slice) -> HarmonicEstimate:
            return dataclasses.replace(
                self,
                orders=self.orders[sl],
                frequencies_hz=self.frequencies_hz[sl],
                phasors=self.phasors[:, sl],
                std=self.std[:, sl],
                block_phasors=self.block_phasors[:, :, sl],
            )

        return part(slice(0, n)), part(slice(n, None))


def pool_estimates(a: HarmonicEstimate, b: HarmonicEstimate) -> HarmonicEstimate:
    """One estimate from the blocks of two consecutive ones at the same drive and orders.

    The blocks of ``b`` must follow those of ``a`` by whole base periods, so that every block
    phasor shares ``a``'s time origin.
    """
    if a.orders != b.orders:
        raise ValueError(f"pool_estimates: different orders {a.orders} and {b.orders}")
    bp = np.concatenate([a.block_phasors, b.block_phasors])
    n = bp.shape[0]
    mean = bp.mean(axis=0)
    std = np.sqrt(np.sum(np.abs(bp - mean) ** 2, axis=0) / (n - 1) / n)
    na, nb = a.n_blocks, b.n_blocks
    npr = np.sqrt(
        (na * np.nan_to_num(a.nonperiodic_rms) ** 2 + nb * np.nan_to_num(b.nonperiodic_rms) ** 2)
        / n
    )
    return dataclasses.replace(
        a, phasors=mean, std=std, block_phasors=bp, nonperiodic_rms=npr, first_index_offset=0
    )


def samples_per_period(
    sample_rate_hz: float, fundamental_hz: float, orders: Iterable[object]
) -> int:
    """Whole number of samples in one base period, checked.

    Parameters
    ----------
    sample_rate_hz : float
        Sample rate [Hz].
    fundamental_hz : float
        Realised fundamental frequency [Hz] (from :func:`rig.signals.plan_period`).
    orders : iterable of rationals
        Harmonic orders.

    Returns
    -------
    int
        ``N = m fs / f``.

    Raises
    ------
    ValueError
        If ``m fs / f`` is not a whole number to 1e-6 (blocks would not hold whole cycles).
    """
    if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
        raise ValueError(f"sample_rate_hz: must be > 0, got {sample_rate_hz}")
    if not (math.isfinite(fundamental_hz) and fundamental_hz > 0):
        raise ValueError(f"fundamental_hz: must be > 0, got {fundamental_hz}")
    exact = base_denominator(as_orders(orders)) * sample_rate_hz / fundamental_hz
    n = round(exact)
    if n < 1 or abs(exact - n) > _PERIOD_TOLERANCE * max(n, 1):
        raise ValueError(
            f"fundamental_hz: {fundamental_hz!r} Hz gives {exact!r} samples per base period at "
            f"{sample_rate_hz!r} Hz, not a whole number; pass the realised frequency from "
            f"plan_period"
        )
    return n


def period_aligned_offset(
    first_index: int, period_start_index: int, samples_per_period: int
) -> int:
    """Samples to skip so that a block starts on a period boundary of the drive.

    Parameters
    ----------
    first_index : int
        Sample index (counted from the backend's start) of the first sample read.
    period_start_index : int
        A sample index at which a base period of the current drive waveform starts and from
        which it is fully in force. ``write_periodic`` returns the index where the new waveform
        is fully in force; that is a period start only if the cross-fade spans whole periods of
        the new waveform (or the backend says so).
    samples_per_period : int
        Samples per base period N.

    Returns
    -------
    int
        Smallest ``offset >= 0`` with ``first_index + offset >= period_start_index`` and
        ``first_index + offset - period_start_index`` a multiple of N.
    """
    if samples_per_period < 1:
        raise ValueError(f"samples_per_period: must be >= 1, got {samples_per_period}")
    lag = period_start_index - first_index
    return lag if lag >= 0 else lag % samples_per_period


def _as_samples(samples: np.ndarray) -> np.ndarray:
    x = np.asarray(samples, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2:
        raise ValueError(f"samples: expected shape (n_samples, C), got {np.shape(samples)}")
    if not np.all(np.isfinite(x)):
        raise ValueError("samples: contain NaN or inf")
    return x


def estimate_harmonics(
    samples: np.ndarray,
    sample_rate_hz: float,
    fundamental_hz: float,
    orders: Iterable[object],
    block_periods: int = 1,
    first_index_offset: int = 0,
    max_blocks: int | None = None,
) -> HarmonicEstimate:
    """Estimate the phasors of every channel at the given orders.

    Parameters
    ----------
    samples : ndarray, shape (n_samples, C) or (n_samples,), channel units
        Phase-synchronous samples (shared clock and start trigger).
    sample_rate_hz : float
        Sample rate [Hz].
    fundamental_hz : float
        Realised fundamental frequency [Hz]; ``m fs / f`` must be a whole number.
    orders : iterable of rationals
        Harmonic orders (H), e.g. ``(1, 2, 3)`` or ``("1/2", 1, 2)``.
    block_periods : int
        Base periods per block.
    first_index_offset : int
        Samples skipped at the start (settling); block 0 starts there and is the phase origin.
        It must lie a whole number of base periods after the drive came into force (see
        :func:`period_aligned_offset`).
    max_blocks : int, optional
        Use at most this many blocks (default: all whole blocks).

    Returns
    -------
    HarmonicEstimate

    Raises
    ------
    ValueError
        If there is no whole block, an order reaches the Nyquist frequency, or the frequency
        does not give whole periods.

    Notes
    -----
    Block phasor: ``X_b = (2 / L) sum_n x_b[n] exp(-i 2 pi c_k n / L)`` with ``L`` samples per
    block and ``c_k`` whole cycles of order ``k`` per block. Because ``c_k`` is whole, every
    block's phasor already refers to the first block's start. References: J. Schoukens,
    R. Pintelon, *System Identification: A Frequency Domain Approach*, 2nd ed., Wiley 2012,
    ch. 2 (periodic excitation, block averaging and sample variance).
    """
    orders_f = as_orders(orders)
    x = _as_samples(samples)
    if block_periods < 1:
        raise ValueError(f"block_periods: must be >= 1, got {block_periods}")
    if not 0 <= first_index_offset <= x.shape[0]:
        raise ValueError(
            f"first_index_offset: must be in [0, {x.shape[0]}], got {first_index_offset}"
        )
    n_period = samples_per_period(sample_rate_hz, fundamental_hz, orders_f)
    length = n_period * block_periods
    m = base_denominator(orders_f)
    cycles = np.array([int(o * m) * block_periods for o in orders_f])
    if 2 * cycles.max() >= length:
        raise ValueError(
            f"orders: order {max(orders_f)} has {cycles.max()} cycles in a {length}-sample "
            f"block, at or beyond Nyquist; raise the sample rate"
        )
    n_blocks = (x.shape[0] - first_index_offset) // length
    if max_blocks is not None:
        n_blocks = min(n_blocks, max_blocks)
    if n_blocks < 1:
        raise ValueError(
            f"samples: {x.shape[0] - first_index_offset} samples after the offset hold no whole "
            f"block of {length} samples"
        )
    used = x[first_index_offset : first_index_offset + n_blocks * length]
    blocks = used.reshape(n_blocks, length, x.shape[1])
    spectra = np.fft.rfft(blocks, axis=1)[:, cycles, :] * (2.0 / length)
    block_phasors = np.transpose(spectra, (0, 2, 1))  # (B, C, H)
    phasors = block_phasors.mean(axis=0)
    std, nonperiodic = _scatter(blocks, block_phasors, phasors)
    return HarmonicEstimate(
        orders=orders_f,
        frequencies_hz=np.array([float(o) for o in orders_f]) * fundamental_hz,
        phasors=phasors,
        std=std,
        block_phasors=block_phasors,
        nonperiodic_rms=nonperiodic,
        samples_per_block=length,
        first_index_offset=first_index_offset,
    )


def _scatter(
    blocks: np.ndarray, block_phasors: np.ndarray, phasors: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Standard error of the mean phasor (C, H) and non-periodic RMS (C,) from the blocks."""
    n_blocks = block_phasors.shape[0]
    if n_blocks < 2:
        nan = np.full(phasors.shape, np.nan)
        return nan, np.full(blocks.shape[2], np.nan)
    spread = np.sum(np.abs(block_phasors - phasors) ** 2, axis=0) / (n_blocks - 1)
    std = np.sqrt(spread / n_blocks)
    residual = blocks - blocks.mean(axis=0)
    nonperiodic = np.sqrt(np.sum(residual**2, axis=(0, 1)) / ((n_blocks - 1) * blocks.shape[1]))
    return std, nonperiodic
