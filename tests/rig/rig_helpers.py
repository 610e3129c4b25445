"""Shared pieces of the run-engine tests: reduced plans, the simulated rig, a recording stand-in.

Plans are tested by recording what they ask for on :class:`rig.run.dry_run.ModelPlant` (a linear
model plant, no backend at all), given a :func:`context`. ``sim_daq`` and ``run_on_sim`` run
plans on the real simulated rig (``sim_backend``) in its fast mode at a reduced sample rate.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from rig.config.plans import FrequencyPlan, FrequencyRange, SteppedSinePlan, load_plan
from rig.config.setup import LabSetup, load_setup
from rig.run.commands import (
    RunContext,
)
from rig.run.session import TestRun
from sim_backend.daq import FaultSwitches, SimulatedDaq

FS_TEST = 5120.0  # sample rate of the tests on the simulated rig (orders up to 120 Hz)


def setup_at(sample_rate_hz: float = FS_TEST) -> LabSetup:
    """The reference setup at the tests' sample rate."""
    return load_setup("reference").with_sample_rate(sample_rate_hz)


def reduced_plan(
    levels_n: Iterable[float] = (2.0, 4.0),
    ranges: Iterable[tuple[float, float, float]] = ((21.0, 23.0, 1.0),),
    base: str = "paper",
    **acquisition: object,
) -> SteppedSinePlan:
    """The paper plan with fewer levels and frequencies (and acquisition settings changed)."""
    plan = load_plan(base)
    excitation = dataclasses.replace(plan.excitation, levels_n=tuple(levels_n))
    freqs = FrequencyPlan(tuple(FrequencyRange(*r) for r in ranges), "up")
    acq = dataclasses.replace(plan.acquisition, **acquisition)
    return dataclasses.replace(
        plan, excitation=excitation, frequencies=freqs, acquisition=acq, name=f"{base}-reduced"
    )


def sim_daq(setup: LabSetup, faults: FaultSwitches | None = None, **options) -> SimulatedDaq:
    """The simulated rig with the setup's sensor masses, fast mode, seed 7."""
    options.setdefault("seed", 7)
    return SimulatedDaq(
        "reference", faults=faults, sensor_masses_kg=setup.sensor_masses_kg(), **options
    )


def run_on_sim(
    plan,
    path: Path,
    *,
    setup: LabSetup | None = None,
    daq: SimulatedDaq | None = None,
    subscribers: Iterable[Callable] = (),
    resume: bool = False,
    **kwargs,
):
    """Run a plan (or resume a file) on the simulated rig; returns (summary, run, daq)."""
    setup = setup or setup_at()
    daq = daq or sim_daq(setup)
    try:
        if resume:
            run = TestRun.resume(daq, path, setup=setup, **kwargs)
        else:
            run = TestRun(daq, plan, setup, path, **kwargs)
        for s in subscribers:
            run.engine.bus.subscribe(s)
        summary = run.execute()
    finally:
        daq.close()
    return summary, run, daq


def assert_ramped_to_zero(daq) -> None:
    """The drive ends at exactly 0 V after a ramp: over the last half second the envelope
    (peak of every 50 ms) only falls."""
    out = daq.output_samples()
    assert out.size and out[-1] == 0.0
    n = int(0.05 * daq.sample_rate_hz)
    tail = out[-10 * n :]
    envelope = np.abs(tail).reshape(10, n).max(axis=1)
    assert envelope[0] > 0 and np.all(np.diff(envelope) <= 1e-12)


def context(setup: LabSetup, points=(3, 6, 7), sample_rate_hz: float | None = None) -> RunContext:
    """A RunContext for a procedure test."""
    channels = setup.channels_for_points(points)
    idx = [c.role for c in channels].index("drive-force")
    return RunContext(
        sample_rate_hz or setup.daq.sample_rate_hz, channels, idx, setup.drive.limit_v
    )
