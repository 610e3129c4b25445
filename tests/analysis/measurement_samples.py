"""Valid synthetic measurement files for tests.

The responses are those of a linear single-degree-of-freedom oscillator driven at point 3
(mass 2 kg, stiffness 5e4 N/m, damping 10 N s/m: natural frequency about 25.2 Hz), so they are
physically consistent: accelerance at the drive point and a scaled copy at the tip.

Usage from any test::

    from tests.analysis.measurement_samples import write_sample_stepped_sine
    data = read_measurement(write_sample_stepped_sine(tmp_path / "run.h5"))
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from analysis.measurement_file import (
    Actuator,
    ChannelInfo,
    RandomFRF,
    StepRecord,
    create_stepped_sine,
    write_random,
)

MASS_KG = 2.0
STIFFNESS_N_PER_M = 5.0e4
DAMPING_NS_PER_M = 10.0
TIP_FACTOR = 2.5
"""Tip acceleration over drive-point acceleration (a rigid-mode stand-in)."""

LEVELS_N = (2.0, 4.0)
ORDERS_NUM = (1, 2, 3)
ORDERS_DEN = (1, 1, 1)
SIDE_HARMONIC = 0.02
"""Amplitude of the 2nd and 3rd force harmonics relative to the fundamental."""
FREQUENCIES_HZ = (22.0, 24.0, 25.0, 26.0, 28.0)


def sample_channels() -> tuple[ChannelInfo, ...]:
    """Three channels: drive force and acceleration at point 3, tip acceleration at point 7."""
    return (
        ChannelInfo("force3", 3, "y", "force", "N", 22.4, "mV/N", "drive-force", 0.0, "IH-1"),
        ChannelInfo(
            "acc3", 3, "y", "acceleration", "m/s^2", 10.2, "mV/g", "drive-acceleration", 0.0, "IH-1"
        ),
        ChannelInfo("acc7", 7, "-y", "acceleration", "m/s^2", 10.0, "mV/g", "response", 0.002, ""),
    )


def sample_actuator() -> Actuator:
    """The shaker at point 3, direction y."""
    return Actuator(3, "y")


def sample_force_targets() -> np.ndarray:
    """Target force phasors, shape (L, H), complex, N: fundamental plus 2 % side harmonics."""
    ratio = np.array([1.0, SIDE_HARMONIC, SIDE_HARMONIC])
    return np.outer(LEVELS_N, ratio).astype(complex)


def accelerance(frequency_hz: np.ndarray) -> np.ndarray:
    """Drive-point accelerance of the oscillator, same shape as ``frequency_hz``, (m/s^2)/N."""
    omega = 2 * np.pi * np.asarray(frequency_hz, dtype=float)
    k, m, c = STIFFNESS_N_PER_M, MASS_KG, DAMPING_NS_PER_M
    return -(omega**2) / (k - m * omega**2 + 1j * c * omega)


def sample_step_records(seed: int = 0) -> list[StepRecord]:
    """Up and down sweeps over :data:`FREQUENCIES_HZ` at every level, in plan order.

    Returns
    -------
    list of StepRecord
        ``2 * len(LEVELS_N) * len(FREQUENCIES_HZ)`` records with ``plan_index`` 0, 1, ...
    """
    rng = np.random.default_rng(seed)
    targets = sample_force_targets()
    orders = np.array(ORDERS_NUM) / np.array(ORDERS_DEN)
    records = []
    for level, target in enumerate(targets):
        for direction in (+1, -1):
            for f in FREQUENCIES_HZ[::direction]:
                force = target * (1 + 0.01 * rng.standard_normal(target.shape))
                acc = accelerance(f * orders) * force
                response = np.stack([force, acc, TIP_FACTOR * acc])
                response_std = 0.001 * np.abs(response)
                records.append(
                    StepRecord(
                        plan_index=len(records),
                        level_index=level,
                        sweep_direction=direction,
                        frequency_target_hz=f,
                        frequency_hz=f * (1 + 1e-6),
                        force=force,
                        force_std=response_std[0],
                        response=response,
                        response_std=response_std,
                        drive=0.1 * force,
                        n_blocks=8,
                        control_iterations=3,
                        control_converged=True,
                        control_error=0.005,
                        timestamp=1.7e9 + len(records),
                    )
                )
    return records


def sample_stepped_sine_kwargs() -> dict[str, Any]:
    """Keyword arguments of :func:`create_stepped_sine` for the sample run (all but ``path``)."""
    return {
        "channels": sample_channels(),
        "actuator": sample_actuator(),
        "levels_n": LEVELS_N,
        "orders_num": ORDERS_NUM,
        "orders_den": ORDERS_DEN,
        "force_targets": sample_force_targets(),
        "config": {"kind": "stepped-sine", "levels_n": list(LEVELS_N)},
        "setup": {"daq": "simulated", "operator": "test"},
    }


def write_sample_stepped_sine(
    path: Path, *, records: list[StepRecord] | None = None, status: str = "success"
) -> Path:
    """Write a finished stepped-sine file with :func:`sample_step_records` (or ``records``)."""
    with create_stepped_sine(path, **sample_stepped_sine_kwargs()) as writer:
        for record in sample_step_records() if records is None else records:
            writer.append_step(record)
        writer.finish(status, "" if status == "success" else f"sample run {status}")
    return path


def sample_random_frf(n_freq: int = 201) -> RandomFRF:
    """H1 of the oscillator from 0 to 100 Hz for :func:`sample_channels`, coherence 0.99."""
    freq = np.linspace(0.0, 100.0, n_freq)
    acc = accelerance(freq)
    h1 = np.stack([np.ones(n_freq), acc, TIP_FACTOR * acc], axis=1)
    return RandomFRF(
        frequency_hz=freq,
        h1=h1,
        coherence=np.full(h1.shape, 0.99),
        force_psd=np.full(n_freq, 1e-3),
        n_averages=50,
        window="hann",
        overlap=0.5,
        fs_hz=1024.0,
        rms_force_n=0.3,
    )


def write_sample_random(path: Path) -> Path:
    """Write a random-excitation file with :func:`sample_random_frf`."""
    return write_random(
        path,
        channels=sample_channels(),
        actuator=sample_actuator(),
        frf=sample_random_frf(),
        config={"kind": "random", "band_hz": [0, 100]},
        setup={"daq": "simulated"},
    )
