"""Shared pieces of the run-engine tests: reduced plans, the simulated rig, a recording stand-in.

``RecordingRig`` answers a procedure's commands from a linear model plant (no backend at all):
plans are tested by recording what they ask for. ``sim_daq`` and ``run_on_sim`` run plans on
the real simulated rig (``sim_backend``) in its fast mode at a reduced sample rate.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from fractions import Fraction
from pathlib import Path

import numpy as np

from rig.commands import (
    Acquire,
    AcquireRecords,
    BeginStep,
    DriveApplied,
    Measurement,
    Notify,
    Records,
    RunContext,
    SetDrive,
    SetWaveform,
    Warn,
    WaveformApplied,
    WriteRandom,
    WriteStep,
)
from rig.estimation.harmonics import HarmonicEstimate
from rig.plans import FrequencyPlan, FrequencyRange, SteppedSinePlan, load_plan
from rig.runner import TestRun
from rig.setup import LabSetup, load_setup
from rig.signals.multisine import plan_period
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


# ------------------------------------------------------------------------ recording stand-in


def _estimate(phasors: np.ndarray, orders, f: float, std: float, n_blocks: int) -> HarmonicEstimate:
    c, h = phasors.shape
    blocks = np.repeat(phasors[None], n_blocks, axis=0)
    return HarmonicEstimate(
        orders=tuple(orders),
        frequencies_hz=np.array([float(o) for o in orders]) * f,
        phasors=phasors,
        std=np.full((c, h), std),
        block_phasors=blocks,
        nonperiodic_rms=np.full(c, std),
        samples_per_block=100,
        first_index_offset=0,
    )


class RecordingRig:
    """Executes procedure commands against a linear model plant and records them.

    The plant's force is ``G_k(f) V_k`` per order (plus an optional coupling of the
    fundamental into the other orders), every response channel reads ``2 x`` the force.

    Parameters
    ----------
    ctx : RunContext
    gain : callable(frequency_hz, orders) -> ndarray (H,) complex, N/V
    coupling : float
        Force at order k generated per N of fundamental force (k != 1).
    """

    def __init__(self, ctx: RunContext, gain: Callable, coupling: float = 0.0) -> None:
        self.ctx = ctx
        self.gain = gain
        self.coupling = coupling
        self.commands: list[object] = []
        self.steps: list[object] = []
        self.frf = None
        self._drive = None
        self._wave = None
        self._records_gain = 5.0

    def run(self, procedure) -> list[object]:
        gen = procedure(self.ctx)
        result = None
        while True:
            try:
                cmd = gen.send(result)
            except StopIteration:
                return self.commands
            self.commands.append(cmd)
            result = self.answer(cmd)

    def answer(self, cmd):
        if isinstance(cmd, SetDrive):
            period = plan_period(cmd.frequency_hz, self.ctx.sample_rate_hz, cmd.orders)
            self._drive = (period, np.asarray(cmd.drive_v, complex))
            return DriveApplied(period, 0, self._drive[1])
        if isinstance(cmd, Acquire):
            period, drive = self._drive
            orders = period.orders
            f = period.fundamental_hz
            force = self.gain(f, orders) * drive
            i1 = orders.index(Fraction(1))
            others = np.arange(len(orders)) != i1
            force[others] += self.coupling * force[i1]
            c = len(self.ctx.channels)
            phasors = np.repeat(2.0 * force[None], c, axis=0)
            phasors[self.ctx.drive_force_index] = force
            est = _estimate(phasors, orders, f, 1e-6, cmd.blocks)
            return Measurement(est, f, 0, True, cmd.settle_periods, "", np.ones(c))
        if isinstance(cmd, SetWaveform):
            self._wave = np.asarray(cmd.period_v, float)
            return WaveformApplied(self._wave.size, 0, float(np.max(np.abs(self._wave))))
        if isinstance(cmd, AcquireRecords):
            wave = np.tile(self._wave, cmd.records)
            rng = np.random.default_rng(len(self.commands))
            force = self._records_gain * wave
            c = len(self.ctx.channels)
            data = 2.0 * force[:, None] + 1e-3 * rng.standard_normal((wave.size, c))
            data[:, self.ctx.drive_force_index] = force
            if not np.any(wave):
                data = 1e-3 * rng.standard_normal((wave.size, c))
            return Records(data, 0, self._wave.size, self.ctx.sample_rate_hz)
        if isinstance(cmd, WriteStep):
            self.steps.append(cmd)
            return None
        if isinstance(cmd, WriteRandom):
            self.frf = cmd.frf
            return None
        if isinstance(cmd, BeginStep | Notify | Warn):
            return None
        raise TypeError(f"unexpected command {cmd!r}")


def context(setup: LabSetup, points=(3, 6, 7), sample_rate_hz: float | None = None) -> RunContext:
    """A RunContext for a procedure test."""
    channels = setup.channels_for_points(points)
    idx = [c.role for c in channels].index("drive-force")
    return RunContext(
        sample_rate_hz or setup.daq.sample_rate_hz, channels, idx, setup.drive.limit_v
    )
