"""Estimation from acquired time blocks: harmonic phasors, settling, and FRFs (H1, periodic)."""

from rig.estimation.frf import H1Estimate, h1_frf, periodic_frf, welch_average_count
from rig.estimation.harmonics import (
    HarmonicEstimate,
    estimate_harmonics,
    period_aligned_offset,
    samples_per_period,
)
from rig.estimation.settling import SettlingCriteria, SettlingVerdict, check_settling

__all__ = [
    "H1Estimate",
    "HarmonicEstimate",
    "SettlingCriteria",
    "SettlingVerdict",
    "check_settling",
    "estimate_harmonics",
    "h1_frf",
    "periodic_frf",
    "period_aligned_offset",
    "samples_per_period",
    "welch_average_count",
]
