"""Seeded synthetic stepped-sine files from a model with known parameters (ground truth).

The "measurement" is the model's own balance at a higher harmonic count than the analysis uses
(H = 15, 256 samples), driven by force phasors with small control errors, with complex Gaussian
noise on every phasor and its standard error stored as the file's uncertainty.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from analysis.measurement_file import Actuator, ChannelInfo, StepRecord, create_stepped_sine
from analysis.mhb.sweep import solve_steps
from analysis.model import Model
from analysis.system import build_problem_dofs

SENSOR_MASS_KG = 0.0055


def channels(points=(6, 7)) -> list[ChannelInfo]:
    chans = [
        ChannelInfo("force", 3, "y", "force", "N", 22.5, "mV/N", "drive-force", 0.0, "IH1"),
        ChannelInfo(
            "acc3",
            3,
            "y",
            "acceleration",
            "m/s^2",
            100.0,
            "mV/g",
            "drive-acceleration",
            0.010,
            "IH1",
        ),
    ]
    chans += [
        ChannelInfo(
            f"acc{p}",
            p,
            "y",
            "acceleration",
            "m/s^2",
            10.0,
            "mV/g",
            "response",
            SENSOR_MASS_KG,
            f"A{p}",
        )
        for p in points
    ]
    return chans


def write_synthetic_run(
    path: Path,
    model: Model,
    *,
    levels_n=(2.0, 4.0, 6.0, 8.0),
    frequencies_hz=None,
    points=(6, 7),
    noise_rel: float = 0.01,
    noise_floor: float = 1e-4,
    force_error: float = 0.005,
    seed: int = 0,
    n_harmonics: int = 15,
    n_time: int = 256,
) -> Path:
    """Write a stepped-sine file of ``model`` (its current values are the truth)."""
    rng = np.random.default_rng(seed)
    if frequencies_hz is None:
        frequencies_hz = np.unique(
            np.round(np.concatenate([np.arange(21, 41, 1.0), np.arange(240, 281) / 10.0]), 6)
        )
    chans = channels(points)
    masses: dict[int, float] = {}
    for ch in chans:
        masses[ch.point] = masses.get(ch.point, 0.0) + ch.mass_kg
    truth = model.add_masses(masses)
    asm = truth.assemble()
    out_dofs = [asm.point_dof(c.point) for c in chans[1:]]
    pb = build_problem_dofs(
        truth, [asm.point_dof(3)], out_dofs, n_harmonics=n_harmonics, n_time=n_time
    )
    H = 3
    targets = np.array([[lv, 0.02 * lv, 0.02 * lv] for lv in levels_n], dtype=complex)
    w = create_stepped_sine(
        path,
        channels=chans,
        actuator=Actuator(3, "y"),
        levels_n=list(levels_n),
        orders_num=[1, 2, 3],
        orders_den=[1, 1, 1],
        force_targets=targets,
        config={"synthetic": True, "noise_rel": noise_rel},
        setup={"source": "synthetic"},
        overwrite=True,
    )
    plan = 0
    with w:
        for li in range(len(levels_n)):
            err = 1 + force_error * (
                rng.standard_normal((len(frequencies_hz), H))
                + 1j * rng.standard_normal((len(frequencies_hz), H))
            )
            F = targets[li][None, :] * err
            res = solve_steps(pb, 2 * np.pi * np.asarray(frequencies_hz), F[:, :, None])
            for j, (f, p) in enumerate(zip(frequencies_hz, res.points, strict=True)):
                assert p.converged, p.message
                wk = 2 * np.pi * f * np.arange(1, H + 1)
                acc = (-(wk**2))[:, None] * p.outputs()  # (H, C-1)
                resp = np.concatenate([F[j][None, :], acc.T])  # (C, H)
                std = noise_rel * np.abs(resp) + noise_floor
                std[0] = noise_rel * 0.2 * np.abs(resp[0]) + 1e-5
                noise = (
                    std
                    / np.sqrt(2)
                    * (rng.standard_normal(resp.shape) + 1j * rng.standard_normal(resp.shape))
                )
                meas = resp + noise
                w.append_step(
                    StepRecord(
                        plan_index=plan,
                        level_index=li,
                        sweep_direction=1,
                        frequency_target_hz=float(f),
                        frequency_hz=float(f),
                        force=meas[0],
                        force_std=std[0],
                        response=meas,
                        response_std=std,
                        drive=0.1 * meas[0],
                        n_blocks=8,
                        control_iterations=2,
                        control_converged=True,
                        control_error=force_error,
                    )
                )
                plan += 1
        w.finish("success", "synthetic")
    return Path(path)
