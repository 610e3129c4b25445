"""Synthetic random-excitation runs of the reference rig with known parameters and damping.

The truth is the reference model at Table 2's calibrated values with a 5.5 g sensor at each of
the 13 points (the impedance head at point 3) and the modal damping :data:`TRUE_ZETA`. H1 is
the truth's receptance (superposition of all its modes) as accelerance per newton, times
``1 + noise * (n1 + i n2) / sqrt(2)`` with standard normal ``n1, n2``: complex Gaussian noise of
relative standard deviation ``noise``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from analysis.linear.modal import modal_analysis
from analysis.measurement_file import Actuator, ChannelInfo, RandomFRF, write_random
from analysis.model import Model, load_model

TRUE_VALUES = {
    "E_frame": 205e9,
    "E_corner": 128e9,
    "E_beam": 201e9,
    "rho_corner": 5175.0,
    "k_mount": 57989.0,
}
"""Table 2's calibrated values, the truth of the synthetic runs."""

SENSOR_MASS_KG = 0.0055
TRUE_ZETA = {1: 0.015, 2: 0.012, 3: 0.010, 4: 0.010, 5: 0.006, 6: 0.008, 7: 0.006}
"""Modal damping of the truth's modes 1-7 (three mount modes, two beam bending modes, two
frame modes below 500 Hz); higher modes have 0.5 %."""
DEFAULT_ZETA = 0.005
DRIVE_POINT = 3
POST_POINTS = (8, 9, 12, 13)
REVERSED_POINTS = (10,)
"""Points whose accelerometer is mounted upside down (direction ``-y``)."""


def rig_channels(points=range(1, 14), mass_kg: float = SENSOR_MASS_KG) -> list[ChannelInfo]:
    """Drive force and acceleration at point 3 (one impedance head), accelerometers elsewhere."""
    chans = [ChannelInfo("force3", 3, "y", "force", "N", 22.4, "mV/N", "drive-force", 0.0, "IH")]
    for p in points:
        d = "x" if p in POST_POINTS else "y"
        d = "-" + d if p in REVERSED_POINTS else d
        role = "drive-acceleration" if p == DRIVE_POINT else "response"
        serial = "IH" if p == DRIVE_POINT else f"A{p}"
        chans.append(
            ChannelInfo(
                f"acc{p}", p, d, "acceleration", "m/s^2", 10.0, "mV/g", role, mass_kg, serial
            )
        )
    return chans


def truth_model(
    values: Mapping[str, float] = TRUE_VALUES, mass_kg: float = SENSOR_MASS_KG
) -> Model:
    """The reference rig at ``values`` with the sensors' masses."""
    return load_model().with_values(values).add_masses({p: mass_kg for p in range(1, 14)})


def truth_h1(
    model: Model,
    channels: list[ChannelInfo],
    frequency_hz: np.ndarray,
    zeta: Mapping[int, float] = TRUE_ZETA,
) -> np.ndarray:
    """Noise-free H1, shape (nf, C): accelerance per newton, the force column 1."""
    asm = model.assemble()
    modes = modal_analysis(asm.M, asm.K, dict(zeta), default_zeta=DEFAULT_ZETA)
    col = asm.point_dof(DRIVE_POINT, "y")
    w = 2 * np.pi * np.asarray(frequency_hz, dtype=float)[:, None]
    g = 1.0 / (modes.omega**2 - w**2 + 2j * modes.zeta * modes.omega * w)  # (nf, n_modes)
    h1 = np.ones((w.size, len(channels)), dtype=complex)
    for c, ch in enumerate(channels):
        if ch.role == "drive-force":
            continue
        sign = -1.0 if ch.direction.startswith("-") else 1.0
        row = asm.point_dof(ch.point, ch.direction.lstrip("-"))
        h1[:, c] = sign * -(w[:, 0] ** 2) * (g @ (modes.phi[row] * modes.phi[col]))
    return h1


def write_rig_run(
    path: Path,
    *,
    noise: float = 0.0,
    seed: int = 0,
    values: Mapping[str, float] = TRUE_VALUES,
    zeta: Mapping[int, float] = TRUE_ZETA,
    band_hz: tuple[float, float] = (2.0, 500.0),
    df_hz: float = 0.05,
    points=range(1, 14),
) -> Path:
    """Write a random-excitation file of the truth with relative complex noise ``noise``."""
    chans = rig_channels(points)
    n0, n1 = round(band_hz[0] / df_hz), round(band_hz[1] / df_hz)
    freq = np.arange(n0, n1 + 1) * df_hz
    h1 = truth_h1(truth_model(values), chans, freq, zeta)
    rng = np.random.default_rng(seed)
    e = (rng.standard_normal(h1.shape) + 1j * rng.standard_normal(h1.shape)) / np.sqrt(2)
    h1 = h1 * (1 + noise * e)
    h1[:, 0] = 1.0
    frf = RandomFRF(
        frequency_hz=freq,
        h1=h1,
        coherence=np.full(h1.shape, 1.0 / (1.0 + noise**2)),
        force_psd=np.full(freq.size, 1e-4),
        n_averages=100,
        window="hann",
        overlap=0.5,
        fs_hz=2048.0,
        rms_force_n=0.2,
    )
    return write_random(
        path,
        channels=chans,
        actuator=Actuator(DRIVE_POINT, "y"),
        frf=frf,
        config={"kind": "random", "band_hz": list(band_hz), "noise": noise},
        setup={"daq": "synthetic"},
    )
