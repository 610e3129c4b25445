"""Acquisition: what the engine computes between writing the output and reading the inputs.

The engine (:mod:`rig.run.engine`) sequences commands, reads the backend and enforces safety;
the numbers in between are here, free of I/O, threads and events:

- the output in force (:class:`Output`): a multi-sine synthesised from a :class:`SetDrive`
  (:func:`drive_output`, checked against the drive limit) or a given waveform
  (:func:`waveform_output`), with the band the signal checks look at;
- where a measurement may start (:func:`first_sample`): after the settling periods, on a
  period boundary of the output;
- the harmonic estimate of an averaging window (:func:`estimate_window`) and the settling test
  on it (:func:`settling_test`): block-to-block changes below the tolerance and no drift between
  the window's halves.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from rig.estimation.harmonics import HarmonicEstimate, estimate_harmonics, period_aligned_offset
from rig.estimation.settling import SettlingCriteria, check_settling
from rig.run.commands import Acquire, SetDrive, SetWaveform
from rig.signals.multisine import PeriodPlan, plan_period, synthesize

__all__ = [
    "Output",
    "drive_output",
    "estimate_window",
    "first_sample",
    "settling_test",
    "silent_output",
    "waveform_output",
]


@dataclass
class Output:
    """The waveform in force.

    Attributes
    ----------
    wave : ndarray, shape (n,)
        One period of the output [V].
    samples_per_period : int
    steady_index : int
        First sample of the steady (post-ramp) output, from the backend.
    band_hz : (float, float) or None
        The band the signal checks integrate over (None: no drive, no band).
    period : PeriodPlan, optional
        The multi-sine's period plan (None for a given waveform).
    drive_v : ndarray, shape (n_orders,), complex, optional
        The multi-sine's drive phasors [V].
    """

    wave: np.ndarray
    samples_per_period: int
    steady_index: int
    band_hz: tuple[float, float] | None
    period: PeriodPlan | None = None
    drive_v: np.ndarray | None = None


def silent_output(sample_rate_hz: float) -> np.ndarray:
    """The zero waveform written at the start (10 ms long)."""
    return np.zeros(max(1, int(round(sample_rate_hz / 100.0))))


def drive_output(cmd: SetDrive, sample_rate_hz: float, limit_v: float) -> tuple[Output, np.ndarray]:
    """The multi-sine of ``cmd`` (steady index still unknown: 0) and its period [V].

    Raises
    ------
    ValueError
        The waveform would exceed ``limit_v`` (the message says by how much).
    """
    period = plan_period(cmd.frequency_hz, sample_rate_hz, cmd.orders)
    drive = np.asarray(cmd.drive_v, dtype=complex)
    wave = synthesize(drive, period, limit_v=limit_v)
    f = period.frequencies_hz
    band = (0.5 * float(f.min()), 1.5 * float(f.max()))
    return Output(wave, period.samples_per_period, 0, band, period, drive), wave


def waveform_output(cmd: SetWaveform) -> Output:
    """The given waveform of ``cmd`` as the output in force (steady index still unknown: 0)."""
    wave = np.asarray(cmd.period_v, dtype=float)
    lo_hz, hi_hz = cmd.band_hz
    return Output(wave, wave.size, 0, (float(lo_hz), float(hi_hz)))


def first_sample(out: Output, cursor: int, settle_periods: int) -> int:
    """The first sample a measurement may use: ``settle_periods`` after the steady output, and
    not before ``cursor`` (what was read already), on a period boundary of the output."""
    n = out.samples_per_period
    start = out.steady_index + settle_periods * n
    if cursor > start:
        start = cursor + period_aligned_offset(cursor, out.steady_index, n)
    return start


def estimate_window(
    window: np.ndarray, sample_rate_hz: float, out: Output, cmd: Acquire
) -> tuple[HarmonicEstimate, HarmonicEstimate | None]:
    """Harmonic estimate of an averaging window at the output's orders, and at the command's
    extra orders (distortion beyond the driven ones) when it asks for them."""
    orders = out.period.orders
    est = estimate_harmonics(
        window,
        sample_rate_hz,
        out.period.fundamental_hz,
        (*orders, *cmd.extra_orders),
        cmd.block_periods,
    )
    return est.split(len(orders)) if cmd.extra_orders else (est, None)


def settling_test(est: HarmonicEstimate, orders, cmd: Acquire) -> tuple[bool, str]:
    """Settling test on an averaging window: block-to-block changes and drift of the halves."""
    bp = est.block_phasors
    n_blocks = bp.shape[0]
    crit = SettlingCriteria(relative_tolerance=cmd.settling_tolerance, consecutive_blocks=2)
    verdict = check_settling(bp, orders, crit)
    if not (verdict.settled and verdict.settled_from_block == 0):
        return False, verdict.message
    i1 = list(orders).index(Fraction(1)) if Fraction(1) in orders else 0
    half = n_blocks // 2
    x = bp[:, :, i1]
    first, last = x[:half].mean(axis=0), x[-half:].mean(axis=0)
    scatter = np.sqrt(np.sum(np.abs(x - x.mean(axis=0)) ** 2, axis=0) / max(n_blocks - 1, 1))
    tol = np.maximum(
        cmd.drift_tolerance * np.abs(x.mean(axis=0)), 3.0 * scatter * np.sqrt(2.0 / half)
    )
    ratio = np.abs(last - first) / np.maximum(tol, np.finfo(float).tiny)
    if np.any(ratio > 1.0):
        return False, f"drifting: the halves of the window differ by {ratio.max():.3g} x tolerance"
    return True, verdict.message
