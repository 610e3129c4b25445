"""Harmonic estimation from phase-synchronous blocks, and the settling test."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from rig.estimation import (
    SettlingCriteria,
    check_settling,
    estimate_harmonics,
    period_aligned_offset,
    samples_per_period,
)
from rig.signals import plan_period

FS = 5120.0


def _signal(phasors, orders, fundamental_hz, t):
    """x(t) = Re{sum X_k exp(i 2 pi k f t)}, evaluated directly with cosines."""
    return sum(
        abs(x) * np.cos(2 * np.pi * float(k) * fundamental_hz * t + np.angle(x))
        for x, k in zip(phasors, orders, strict=True)
    )


def test_exact_recovery_with_subharmonic_offset_and_unmeasured_harmonics():
    orders = (Fraction(1, 2), 1, 2, 3)
    plan = plan_period(24.1, FS, orders)
    f = plan.fundamental_hz
    n_period = plan.samples_per_period
    truth = np.array(
        [
            [0.1 * np.exp(0.4j), 2.0 * np.exp(-0.3j), 0.04 * np.exp(1.2j), 0.05j],
            [0.0, 0.7, -0.02 + 0.01j, 0.003 * np.exp(-2.5j)],
        ]
    )
    offset = 3 * n_period  # settling periods skipped; the origin is their end
    n = offset + 4 * 2 * n_period + 17  # 4 blocks of 2 periods and a partial block
    t = (np.arange(n) - offset) / FS
    x = np.stack([_signal(row, orders, f, t) for row in truth], axis=1)
    # Content orthogonal to the orders over a base period: DC, and orders 5/2, 4 and 5.
    x += 0.3 + 0.2 * np.cos(2 * np.pi * 2.5 * f * t + 1.0)[:, None]
    x += 0.5 * np.cos(2 * np.pi * 4 * f * t)[:, None] + 0.4 * np.sin(2 * np.pi * 5 * f * t)[:, None]
    est = estimate_harmonics(x, FS, f, orders, block_periods=2, first_index_offset=offset)
    assert est.n_blocks == 4
    assert est.samples_per_block == 2 * n_period
    np.testing.assert_allclose(est.phasors, truth, atol=1e-12)
    np.testing.assert_allclose(est.block_phasors, np.broadcast_to(truth, (4, 2, 4)), atol=1e-12)
    np.testing.assert_allclose(est.std, 0.0, atol=1e-12)
    np.testing.assert_allclose(est.nonperiodic_rms, 0.0, atol=1e-12)
    np.testing.assert_allclose(est.frequencies_hz, f * np.array([0.5, 1, 2, 3]), rtol=1e-15)


def test_std_is_the_standard_error_of_the_mean():
    """Monte Carlo: 600 independent noisy channels, white noise of std sigma per sample.

    Per block ``X_b = (2/L) sum x[n] e^{-i theta n}``, so ``E|X_b - X|^2 = 4 sigma^2 / L`` and the
    standard error of the mean over B blocks is ``2 sigma / sqrt(L B)``. Tolerance: 20 % on the
    mean reported std and on the Monte Carlo error (both have a sampling error of a few %).
    """
    rng = np.random.default_rng(7)
    plan = plan_period(31.0, FS, (1, 2, 3))
    n_blocks, trials, sigma = 8, 600, 0.05
    length = plan.samples_per_period
    t = np.arange(n_blocks * length) / FS
    truth = np.array([1.0, 0.02j, 0.02])
    clean = _signal(truth, plan.orders, plan.fundamental_hz, t)
    x = clean[:, None] + sigma * rng.standard_normal((t.size, trials))
    est = estimate_harmonics(x, FS, plan.fundamental_hz, plan.orders)
    expected = 2 * sigma / np.sqrt(length * n_blocks)
    actual = np.sqrt(np.mean(np.abs(est.phasors - truth) ** 2, axis=0))  # (H,), Monte Carlo
    np.testing.assert_allclose(actual, expected, rtol=0.2)
    np.testing.assert_allclose(np.mean(est.std, axis=0), expected, rtol=0.2)
    # The noise also shows as non-periodic content of about sigma.
    assert np.median(est.nonperiodic_rms) == pytest.approx(sigma, rel=0.1)


def test_single_block_has_no_scatter_estimate():
    plan = plan_period(20.0, FS, (1,))
    x = np.cos(2 * np.pi * plan.fundamental_hz * np.arange(plan.samples_per_period) / FS)
    est = estimate_harmonics(x, FS, plan.fundamental_hz, (1,))
    assert est.n_blocks == 1
    np.testing.assert_allclose(est.phasors, [[1.0]], atol=1e-12)
    assert np.isnan(est.std).all() and np.isnan(est.nonperiodic_rms).all()


def test_leakage_of_a_non_synchronous_component_is_the_dirichlet_kernel_and_is_flagged():
    plan = plan_period(25.0, FS, (1, 2, 3))
    f, length = plan.fundamental_hz, plan.samples_per_period
    n_blocks = 6
    n = np.arange(n_blocks * length)
    amp, f_hum = 0.1, 1.37 * f  # not a multiple of the base frequency
    periodic = np.cos(2 * np.pi * f * n / FS)
    x = periodic + amp * np.cos(2 * np.pi * f_hum * n / FS)
    est = estimate_harmonics(x, FS, f, (1, 2, 3))
    # Independent reference: the block DFT of the hum via the geometric series, per block.
    nu = f_hum / FS * length  # cycles of the hum per block (non-integer)
    expected = []
    for b in range(n_blocks):
        phase0 = 2 * np.pi * nu * b  # the hum's phase at the block's start
        row = []
        for c in (1, 2, 3):

            def geo(d):
                z = np.exp(2j * np.pi * d / length)
                return (1 - z**length) / (1 - z)

            leak = (
                amp
                / length
                * (np.exp(1j * phase0) * geo(nu - c) + np.exp(-1j * phase0) * geo(-nu - c))
            )
            row.append(leak + (1.0 if c == 1 else 0.0))
        expected.append(row)
    np.testing.assert_allclose(est.block_phasors[:, 0, :], np.array(expected), atol=1e-12)
    # Flag: block scatter and non-periodic RMS rise well above the clean record's (zero).
    clean = estimate_harmonics(periodic, FS, f, (1, 2, 3))
    assert clean.nonperiodic_rms[0] < 1e-12
    assert est.nonperiodic_rms[0] > 0.3 * amp / np.sqrt(2)
    assert est.std[0, 0] > 1e-3


def test_input_errors_are_explained():
    with pytest.raises(ValueError, match="not a whole number"):
        samples_per_period(FS, 24.1, (1, 2, 3))
    plan = plan_period(24.1, FS, (1,))
    x = np.zeros((plan.samples_per_period - 1, 2))
    with pytest.raises(ValueError, match="no whole block"):
        estimate_harmonics(x, FS, plan.fundamental_hz, (1,))
    with pytest.raises(ValueError, match="Nyquist"):
        estimate_harmonics(np.zeros(64), 64.0, 8.0, (1, 4))
    with pytest.raises(ValueError, match="first_index_offset"):
        estimate_harmonics(np.zeros(64), 64.0, 8.0, (1,), first_index_offset=65)


@pytest.mark.parametrize(
    ("first_index", "in_force", "expected"),
    [(0, 300, 300), (300, 300, 0), (305, 300, 95), (400, 300, 0), (1299, 300, 1)],
)
def test_period_aligned_offset(first_index, in_force, expected):
    assert period_aligned_offset(first_index, in_force, 100) == expected


# --------------------------------------------------------------------------- settling


def _settling_record(seed: int, n_blocks: int = 60):
    """Steady multi-sine plus a decaying free transient at a natural frequency, with noise."""
    rng = np.random.default_rng(seed)
    plan = plan_period(20.0, FS, (1, 2, 3))
    f, length = plan.fundamental_hz, plan.samples_per_period
    t = np.arange(n_blocks * length) / FS
    steady = _signal([1.0, 0.05j, 0.02], plan.orders, f, t)
    tau, f_n = 0.4, 23.0
    transient = 0.5 * np.exp(-t / tau) * np.cos(2 * np.pi * f_n * t)
    x = steady + transient + 1e-3 * rng.standard_normal(t.size)
    return plan, x, transient, length


def test_settling_is_reached_after_the_transient_decays_not_before():
    plan, x, transient, length = _settling_record(seed=1)
    est = estimate_harmonics(x, FS, plan.fundamental_hz, plan.orders)
    crit = SettlingCriteria(relative_tolerance=0.01)
    # Reference: the transient's own contribution to each block's fundamental phasor (direct
    # sum), and the first block after which its block-to-block change stays within 1 %.
    blocks = transient.reshape(-1, length)
    kernel = np.exp(-2j * np.pi * np.arange(length) / length) * 2 / length
    change = np.abs(np.diff(blocks @ kernel))
    expected_from = int(np.flatnonzero(change > 0.01)[-1]) + 1
    verdict = check_settling(est.block_phasors, plan.orders, crit)
    assert verdict.settled
    assert abs(verdict.settled_from_block - expected_from) <= 1
    assert verdict.change_ratios.shape == (est.n_blocks - 1,)
    early = check_settling(est.block_phasors[: expected_from - 2], plan.orders, crit)
    assert not early.settled and early.settled_from_block is None
    assert "not settled" in early.message


def test_noise_alone_settles_thanks_to_the_noise_floor():
    rng = np.random.default_rng(5)
    n_blocks = 30
    block = 1.0 + 0.03 * (rng.standard_normal(n_blocks) + 1j * rng.standard_normal(n_blocks))
    block_phasors = block[:, None, None]
    strict = SettlingCriteria(relative_tolerance=0.001, noise_factor=0.0)
    assert not check_settling(block_phasors, (1,), strict).settled
    verdict = check_settling(block_phasors, (1,), SettlingCriteria(relative_tolerance=0.001))
    assert verdict.settled
    # Estimated per-block noise scatter: E|n|^2 = 2 * 0.03^2 for this complex noise.
    assert verdict.noise_std[0, 0] == pytest.approx(0.03 * np.sqrt(2), rel=0.3)
    given = check_settling(
        block_phasors, (1,), SettlingCriteria(relative_tolerance=0.001), noise_std=0.03 * np.sqrt(2)
    )
    assert given.settled


def test_settling_criteria_validation_and_selection():
    with pytest.raises(ValueError, match="SettlingCriteria.relative_tolerance"):
        SettlingCriteria(relative_tolerance=0)
    with pytest.raises(ValueError, match="SettlingCriteria.consecutive_blocks"):
        SettlingCriteria(consecutive_blocks=0)
    x = np.ones((5, 2, 3), dtype=complex)
    x[:, 1, 2] = np.arange(5)  # channel 1, order 3 keeps growing
    assert check_settling(x, (1, 2, 3)).settled
    crit = SettlingCriteria(orders=(1, 3), channels=(1,))
    assert not check_settling(x, (1, 2, 3), crit).settled
    with pytest.raises(ValueError, match="not among the measured orders"):
        check_settling(x, (1, 2, 3), SettlingCriteria(orders=("1/2",)))
