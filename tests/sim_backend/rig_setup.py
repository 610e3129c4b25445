"""Shared set-up of the simulated-rig tests: the paper's channels, drives and one test step."""

from __future__ import annotations

import numpy as np

from rig.backends.protocol import AcquisitionConfig, AIChannelConfig, AOChannelConfig
from rig.estimation.harmonics import HarmonicEstimate, estimate_harmonics
from sim_backend.daq import SimulatedDaq

FS = 2048.0
ORDERS = (1, 2, 3)


def paper_config(
    sample_rate_hz: float = FS, extra_points: tuple[int, ...] = ()
) -> AcquisitionConfig:
    """Impedance head at point 3, accelerometers at 6 and 7 (and more), drive loop-back."""
    ai = [
        AIChannelConfig("force", "Dev1/ai0", "force", 22.5, "mV/N", point=3),
        AIChannelConfig("acc3", "Dev1/ai1", "acceleration", 100.0, "mV/g", point=3),
        AIChannelConfig("acc6", "Dev1/ai2", "acceleration", 100.0, "mV/g", point=6),
        AIChannelConfig("acc7", "Dev1/ai3", "acceleration", 100.0, "mV/g", point=7),
    ]
    for i, p in enumerate(extra_points):
        ai.append(
            AIChannelConfig(f"acc{p}", f"Dev1/ai{4 + i}", "acceleration", 100.0, "mV/g", point=p)
        )
    ai.append(AIChannelConfig("drive", f"Dev1/ai{len(ai)}", "voltage", 1.0, "V/V", iepe=False))
    return AcquisitionConfig(sample_rate_hz, AOChannelConfig("Dev1/ao0", 5.0), tuple(ai))


def multisine(n: int, amplitude_v: float, side: float = 0.02, phase_rad: float = 0.0) -> np.ndarray:
    """One period (n samples) of orders 1, 2, 3 with side harmonics at ``side`` [V]."""
    t = np.arange(n) / n
    return amplitude_v * (
        np.cos(2 * np.pi * t + phase_rad)
        + side * np.cos(4 * np.pi * t)
        + side * np.cos(6 * np.pi * t)
    )


def settle_and_estimate(
    daq: SimulatedDaq, period_start: int, n: int, settle_s: float, periods: int
) -> tuple[HarmonicEstimate, np.ndarray, int]:
    """Read until ``settle_s`` after ``period_start``, then ``periods`` whole periods.

    Returns the estimate (phase origin at a period start of the drive), the samples used and
    the index of their first sample.
    """
    first_needed = period_start + int(np.ceil(settle_s * daq.sample_rate_hz / n)) * n
    _, first = daq.read(1, 5.0)
    current = first + 1
    aligned = period_start + -(-(current - period_start) // n) * n
    skip = max(first_needed, aligned) - current
    if skip > 0:
        daq.read(skip, 5.0)
    data, first = daq.read(periods * n, 5.0)
    assert (first - period_start) % n == 0
    est = estimate_harmonics(data, daq.sample_rate_hz, daq.sample_rate_hz / n, ORDERS)
    return est, data, first
