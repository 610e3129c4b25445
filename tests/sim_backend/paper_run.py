"""A compact stepped-sine run of the paper's kind on any DAQ backend (for tests and figures).

Force control with the rig's controller, a fixed settling time, harmonic estimation over whole
periods; returns what a run records per step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from rig.estimation.harmonics import estimate_harmonics
from rig.procedures.force_control import ControlSettings, ForceController, loop_check_gain
from tests.sim_backend.rig_setup import ORDERS

RAMP_S = 0.1


@dataclass
class StepRecord:
    level_n: float
    frequency_hz: float
    drive_v: np.ndarray  # (3,) complex
    phasors: np.ndarray  # (C, 3) complex
    std: np.ndarray  # (C, 3)
    iterations: int
    converged: bool


@dataclass
class RunRecord:
    steps: list[StepRecord]
    simulated_s: float
    wall_s: float


def _wave(drive: np.ndarray, n: int) -> np.ndarray:
    t = np.arange(n) / n
    return sum((drive[i] * np.exp(2j * np.pi * (i + 1) * t)).real for i in range(3))


def _measure(daq, drive, n, settle_s, periods):
    index = daq.write_periodic(_wave(drive, n), RAMP_S)
    fs = daq.sample_rate_hz
    start = index + int(np.ceil(settle_s * fs / n)) * n
    _, first = daq.read(1, 5.0)
    if start > first + 1:
        daq.read(start - first - 1, 5.0)
    data, first = daq.read(periods * n, 5.0)
    return estimate_harmonics(data, fs, fs / n, ORDERS)


def run_stepped_sine(
    daq,
    levels_n: tuple[float, ...],
    frequencies_hz: np.ndarray,
    settle_s: float = 1.5,
    periods: int = 10,
    max_drive_v: float = 4.0,
) -> RunRecord:
    """Run every level upwards through the frequencies with force control at each step."""
    fs = daq.sample_rate_hz
    # side orders are measured to about 1 % of the fundamental (the noise floors): a floor of
    # 3 % of the fundamental keeps the controller from chasing noise
    settings = ControlSettings(max_drive_v=max_drive_v, max_iterations=6, harmonic_floor_ratio=0.03)
    controller = ForceController(settings)
    t0 = time.monotonic()
    daq.start()
    steps: list[StepRecord] = []
    for level in levels_n:
        gain = None
        for f in frequencies_hz:
            n = int(round(fs / f))
            if gain is None:  # low-level loop check
                probe = np.array([0.01, 0.0002, 0.0002], dtype=complex)
                est = _measure(daq, probe, n, settle_s, periods)
                gain = loop_check_gain(probe, est.phasors[0])
            targets = level * np.array([1.0, 0.02, 0.02], dtype=complex)
            drive = controller.start_step(targets, gain)
            for _ in range(settings.max_iterations + 1):
                est = _measure(daq, drive, n, settle_s, periods)
                decision = controller.next_drive(drive, est.phasors[0], est.std[0])
                if decision.done:
                    break
                drive = decision.drive_v
            record = controller.record
            gain = record.final_gain
            steps.append(
                StepRecord(
                    level, fs / n, drive, est.phasors, est.std, record.iterations, record.converged
                )
            )
    simulated = daq.simulated_time_s
    daq.stop()
    return RunRecord(steps, simulated, time.monotonic() - t0)
