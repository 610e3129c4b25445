"""A plan run without hardware: the commands its procedure gives and how long they take.

:class:`ModelPlant` answers a procedure's commands (:mod:`rig.run.commands`) from a linear model
plant instead of a DAQ: the drive force is ``G_k(f) V_k`` per order (plus an optional coupling
of the fundamental into the other orders) and every response channel reads twice the force.
The procedure does everything it does on the rig (pretest, force control, records, writes),
and every command is recorded: the tests check plans this way, and :func:`dry_run` turns the
record into what a user wants to know before a test (``rig plans show NAME``, the GUI's plan
editor): the steps, the measurements and the time the acquisition takes.

The time is a lower bound: on a linear plant force control is on target after one or two
measurements, a structure near its resonance takes more (each further measurement of a step
costs :attr:`DryRun.iteration_s` on average), and the settling test may wait longer than the
settling periods a plan asks for.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from rig.config.plans import Plan, RandomPlan
from rig.config.setup import LabSetup, load_setup
from rig.estimation.harmonics import HarmonicEstimate
from rig.run.commands import (
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
from rig.signals.multisine import PeriodPlan, plan_period

__all__ = ["DryRun", "ModelPlant", "dry_run", "flat_gain"]

#: Drive-to-force gain of the dry run's plant [N/V]: a modal shaker through its amplifier on a
#: light structure (the reference rig needs about 0.1-0.3 V for 2-8 N). Only the drive levels
#: depend on it, not the commands or their time.
FLAT_GAIN_N_PER_V = 30.0


def flat_gain(frequency_hz: float, orders) -> np.ndarray:
    """The dry run's plant: :data:`FLAT_GAIN_N_PER_V` at every order and frequency."""
    return np.full(len(orders), FLAT_GAIN_N_PER_V, dtype=complex)


def _estimate(phasors: np.ndarray, orders, f: float, std: float, n_blocks: int) -> HarmonicEstimate:
    c, h = phasors.shape
    return HarmonicEstimate(
        orders=tuple(orders),
        frequencies_hz=np.array([float(o) for o in orders]) * f,
        phasors=phasors,
        std=np.full((c, h), std),
        block_phasors=np.repeat(phasors[None], n_blocks, axis=0),
        nonperiodic_rms=np.full(c, std),
        samples_per_block=100,
        first_index_offset=0,
    )


class ModelPlant:
    """Executes procedure commands against a linear model plant, records them and the time
    the acquisition would take (module docstring).

    Parameters
    ----------
    ctx : RunContext
    gain : callable(frequency_hz, orders) -> ndarray (H,) complex, N/V
    coupling : float
        Force at order k generated per N of fundamental force (k != 1).
    """

    def __init__(self, ctx: RunContext, gain: Callable = flat_gain, coupling: float = 0.0) -> None:
        self.ctx = ctx
        self.gain = gain
        self.coupling = coupling
        self.commands: list[object] = []
        self.steps: list[WriteStep] = []
        self.frf = None
        self.seconds = 0.0  # acquisition and ramps so far [s]
        self.step_seconds: list[float] = []  # of each written step [s]
        self._step_start = 0.0
        self._drive: tuple[PeriodPlan, np.ndarray] | None = None
        self._wave: np.ndarray | None = None
        self._records_gain = 5.0

    def run(self, procedure) -> list[object]:
        """Run ``procedure`` (``callable(RunContext) -> generator``) to its end."""
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
        """The plant's answer to one command (what the engine would return)."""
        handler = self._HANDLERS.get(type(cmd))
        if handler is None:
            raise TypeError(f"unexpected command {cmd!r}")
        return handler(self, cmd)

    def _set_drive(self, cmd: SetDrive) -> DriveApplied:
        period = plan_period(cmd.frequency_hz, self.ctx.sample_rate_hz, cmd.orders)
        self._drive = (period, np.asarray(cmd.drive_v, complex))
        self.seconds += cmd.ramp_s
        return DriveApplied(period, 0, self._drive[1])

    def _acquire(self, cmd: Acquire) -> Measurement:
        if self._drive is None:
            raise RuntimeError("Acquire before any SetDrive")
        period, drive = self._drive
        periods = cmd.settle_periods + cmd.blocks * cmd.block_periods
        self.seconds += periods * period.samples_per_period / self.ctx.sample_rate_hz
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

    def _set_waveform(self, cmd: SetWaveform) -> WaveformApplied:
        self._wave = np.asarray(cmd.period_v, float)
        return WaveformApplied(self._wave.size, 0, float(np.max(np.abs(self._wave))))

    def _acquire_records(self, cmd: AcquireRecords) -> Records:
        wave = np.tile(self._wave, cmd.records)
        self.seconds += wave.size / self.ctx.sample_rate_hz
        rng = np.random.default_rng(len(self.commands))
        force = self._records_gain * wave
        c = len(self.ctx.channels)
        data = 2.0 * force[:, None] + 1e-3 * rng.standard_normal((wave.size, c))
        data[:, self.ctx.drive_force_index] = force
        if not np.any(wave):
            data = 1e-3 * rng.standard_normal((wave.size, c))
        return Records(data, 0, self._wave.size, self.ctx.sample_rate_hz)

    def _begin_step(self, cmd: BeginStep) -> None:
        self._step_start = self.seconds

    def _write_step(self, cmd: WriteStep) -> None:
        self.steps.append(cmd)
        self.step_seconds.append(self.seconds - self._step_start)

    def _write_random(self, cmd: WriteRandom) -> None:
        self.frf = cmd.frf

    def _ignore(self, cmd) -> None:
        return None

    _HANDLERS: dict[type, Callable] = {
        SetDrive: _set_drive,
        Acquire: _acquire,
        SetWaveform: _set_waveform,
        AcquireRecords: _acquire_records,
        BeginStep: _begin_step,
        WriteStep: _write_step,
        WriteRandom: _write_random,
        Notify: _ignore,
        Warn: _ignore,
    }


@dataclass(frozen=True)
class DryRun:
    """What a plan asks of the rig, from :func:`dry_run`.

    Attributes
    ----------
    plan : Plan
    n_steps : int
        Steps written (stepped sine; 1 for a random test).
    n_measurements : int
        Averaged measurements (stepped sine: pretest, control iterations, records).
    seconds : float
        Acquisition and ramp time at least [s] (module docstring).
    iteration_s : float
        Average time of one force-control measurement of a step [s]: what each further
        iteration a structure needs adds.
    step_seconds : tuple of float
        Each step's time on the model plant [s].
    """

    plan: Plan
    n_steps: int
    n_measurements: int
    seconds: float
    iteration_s: float
    step_seconds: tuple[float, ...] = field(default=())

    def to_json(self) -> dict:
        return {
            "plan": self.plan.name,
            "kind": self.plan.kind,
            "n_steps": self.n_steps,
            "n_measurements": self.n_measurements,
            "seconds_at_least": self.seconds,
            "iteration_s": self.iteration_s,
        }


def dry_run(plan: Plan, setup: LabSetup | None = None) -> DryRun:
    """Run ``plan``'s procedure on the :class:`ModelPlant`; its steps, measurements and time.

    A random test's time is its records' (no procedure is run: its records would be built in
    memory at full length).
    """
    setup = setup or load_setup(plan.setup)
    fs = plan.sample_rate_hz or setup.daq.sample_rate_hz
    if isinstance(plan, RandomPlan):
        seconds = plan.n_steps * plan.excitation.record_s
        return DryRun(plan, 1, plan.n_steps, seconds, plan.excitation.record_s)
    from rig.procedures.stepped_sine import stepped_sine_procedure

    channels = setup.channels_for_points(plan.points)
    force = [c.role for c in channels].index("drive-force")
    plant = ModelPlant(RunContext(fs, channels, force, setup.drive.limit_v))
    commands = plant.run(stepped_sine_procedure(plan))
    n_measurements = sum(isinstance(c, Acquire) for c in commands)
    return DryRun(
        plan,
        len(plant.steps),
        n_measurements,
        plant.seconds,
        _mean_iteration_s(commands, fs),
        tuple(plant.step_seconds),
    )


def _mean_iteration_s(commands: list, fs: float) -> float:
    """Average time of a force-control measurement: its ramp, settling and averaging."""
    times, period_s, ramp = [], None, 0.0
    for cmd in commands:
        if isinstance(cmd, SetDrive):
            period = plan_period(cmd.frequency_hz, fs, cmd.orders)
            period_s = period.samples_per_period / fs
            ramp = cmd.ramp_s
        elif isinstance(cmd, Acquire) and cmd.purpose == "control" and period_s is not None:
            periods = cmd.settle_periods + cmd.blocks * cmd.block_periods
            times.append(ramp + periods * period_s)
    return float(np.mean(times)) if times else 0.0
