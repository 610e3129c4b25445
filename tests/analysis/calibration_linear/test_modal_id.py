"""Modal identification: exact poles of noise-free modal sums, the rig under noise."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.calibration.linear import fit_poles, identify_modes, load_random_run
from analysis.calibration.linear.lscf import lscf_poles, starting_poles
from tests.analysis.calibration_linear.synthetic import TRUE_ZETA, truth_model

F_HZ = np.arange(100, 1501) * 0.1  # 10-150 Hz
FR_HZ = np.array([30.0, 80.0, 84.0])  # a close pair at 80 and 84 Hz
ZETA = np.array([0.01, 0.02, 0.005])


def _three_modes(extra: bool = False, seed: int = 1):
    """Receptance-like FRFs of 3 modes at 4 channels (complex residues), shape (nf, 4)."""
    rng = np.random.default_rng(seed)
    wr = 2 * np.pi * FR_HZ
    A = rng.standard_normal((3, 4)) * wr[:, None] ** 2 * 1e-6
    B = rng.standard_normal((3, 4)) * wr[:, None] * 1e-8
    w = 2 * np.pi * F_HZ[:, None]
    g = 1 / (wr**2 - w**2 + 2j * ZETA * wr * w)
    H = g @ A + (1j * w * g) @ B
    if extra:  # modes below and above the band
        for fe, ze in ((3.0, 0.02), (400.0, 0.01), (600.0, 0.01)):
            we = 2 * np.pi * fe
            H = H + rng.standard_normal(4) * 1e-6 * we**2 / (we**2 - w**2 + 2j * ze * we * w)
    return H, A, B


def _poles(fr_hz, zeta):
    w = 2 * np.pi * np.asarray(fr_hz)
    return -zeta * w + 1j * w * np.sqrt(1 - zeta**2)


def test_three_modes_exact_without_noise() -> None:
    H, A, B = _three_modes()
    fit = identify_modes(F_HZ, H)
    assert fit.n_modes == 3
    lam = _poles(FR_HZ, ZETA)
    assert np.max(np.abs(fit.poles - lam) / np.abs(lam)) < 1e-6
    assert np.max(np.abs(fit.a - A)) < 1e-6 * np.max(np.abs(A))
    assert np.max(np.abs(fit.b - B)) < 1e-6 * np.max(np.abs(B))
    assert fit.rms_relative_error < 1e-9


def test_three_modes_with_out_of_band_modes() -> None:
    """Residual terms absorb modes below and above the band (tolerance 1e-5 on the poles)."""
    H, A, _ = _three_modes(extra=True)
    fit = identify_modes(F_HZ, H)
    lam = _poles(FR_HZ, ZETA)
    assert fit.n_modes == 3
    assert np.max(np.abs(fit.poles - lam) / np.abs(lam)) < 1e-5
    assert np.max(np.abs(fit.zeta / ZETA - 1)) < 1e-3
    assert np.max(np.abs(fit.a - A)) < 1e-3 * np.max(np.abs(A))


def test_synthesize_with_another_damping() -> None:
    H, A, B = _three_modes()
    fit = fit_poles(F_HZ, H, FR_HZ * 1.001, ZETA * 1.1)
    wr, w = 2 * np.pi * FR_HZ, 2 * np.pi * F_HZ[:, None]
    g = 1 / (wr**2 - w**2 + 2j * 0.03 * wr * w)
    expected = g @ A + (1j * w * g) @ B
    np.testing.assert_allclose(fit.synthesize(F_HZ, 0.03), expected, rtol=1e-8, atol=0)
    np.testing.assert_allclose(fit.synthesize(F_HZ), H, rtol=1e-8, atol=0)


def test_starting_poles_find_a_pole_on_an_octave_edge() -> None:
    H, _, _ = _three_modes()  # 80 Hz = 10 Hz * 2^3 is a sub-band edge
    found = starting_poles(F_HZ, H, (10.0, 150.0))
    np.testing.assert_allclose([p.frequency_hz for p in found], FR_HZ, rtol=1e-6)


def test_lscf_poles_of_a_lightly_damped_mode_are_exact() -> None:
    """One mode at 25 Hz, 0.6 % damping, 10-40 Hz at 0.125 Hz: the order-2 model is exact in
    the z-domain up to the numerator, so the pole comes out to 1e-4 (the reduced problem is
    solved by QR: normal equations lose it to round-off on noise-free data)."""
    f = np.arange(10, 40, 0.125)
    wr, w = 2 * np.pi * 25.0, 2 * np.pi * f
    h = 1 / (wr**2 - w**2 + 2j * 0.006 * wr * w)
    poles = lscf_poles(f, h[:, None], [2], 42.0)[2]
    p = poles[poles.imag > 0][0]
    assert abs(abs(p) / wr - 1) < 1e-4
    assert abs(-p.real / abs(p) / 0.006 - 1) < 0.05


def test_weighted_starting_poles_ignore_channels_of_pure_noise() -> None:
    """Four good channels and four of noise only (coherence near 0): with the coherence as
    weights the three modes are found to 0.5 %."""
    H, _, _ = _three_modes()
    rng = np.random.default_rng(3)
    scale = np.abs(H).max()
    noise = scale * (rng.standard_normal((F_HZ.size, 4)) + 1j * rng.standard_normal((F_HZ.size, 4)))
    Hn = np.concatenate([H, noise], axis=1)
    g2 = np.concatenate([np.ones_like(H.real), np.full(noise.shape, 0.01)], axis=1)
    found = starting_poles(F_HZ, Hn, (10.0, 150.0), weights=g2)
    np.testing.assert_allclose([p.frequency_hz for p in found], FR_HZ, rtol=5e-3)


@pytest.mark.slow
def test_rig_modes_under_noise(noisy_run) -> None:
    """2 % noise: all 7 modes in 2-500 Hz, frequencies to 1e-4, damping to 2 %."""
    model = truth_model()
    run = load_random_run(noisy_run, model)
    fit = identify_modes(run.frequency_hz, run.H)
    f_true, _ = model.assemble().normal_modes(7)
    z_true = np.array([TRUE_ZETA[k] for k in range(1, 8)])
    assert fit.n_modes == 7
    np.testing.assert_allclose(fit.frequency_hz, f_true, rtol=1e-4)
    np.testing.assert_allclose(fit.zeta, z_true, rtol=0.02)
    assert fit.rms_relative_error < 0.03


def test_identify_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError, match="shape"):
        identify_modes(F_HZ, np.ones((F_HZ.size + 1, 2), complex))
    with pytest.raises(ValueError, match="frequencies"):
        identify_modes(F_HZ, np.ones((F_HZ.size, 2), complex), (10.0, 10.5))
