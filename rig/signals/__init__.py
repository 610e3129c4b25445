"""Drive signals: stepped multi-sine synthesis and band-limited random excitation."""

from rig.signals.multisine import (
    MultisineSpec,
    PeriodPlan,
    as_orders,
    base_denominator,
    cosine_ramp,
    crossfade,
    plan_period,
    synthesize,
    waveform_peak_v,
)
from rig.signals.random import band_limited_random

__all__ = [
    "MultisineSpec",
    "PeriodPlan",
    "as_orders",
    "band_limited_random",
    "base_denominator",
    "cosine_ramp",
    "crossfade",
    "plan_period",
    "synthesize",
    "waveform_peak_v",
]
