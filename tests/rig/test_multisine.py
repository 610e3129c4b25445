"""Multi-sine synthesis: orders, period planning, waveform, voltage limit and ramps."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from rig.signals import (
    MultisineSpec,
    as_orders,
    base_denominator,
    cosine_ramp,
    crossfade,
    plan_period,
    synthesize,
    waveform_peak_v,
)

PHASORS = np.array([0.8 * np.exp(0.3j), 0.05 * np.exp(-1.1j), 0.03 * np.exp(2.0j)])


def _direct_waveform(phasors, orders, fundamental_hz, t):
    """Independent evaluation of Re{sum V_k exp(i 2 pi k f t)} with cosines."""
    return sum(
        abs(v) * np.cos(2 * np.pi * float(k) * fundamental_hz * t + np.angle(v))
        for v, k in zip(phasors, orders, strict=True)
    )


def test_orders_are_parsed_as_exact_fractions():
    assert as_orders(["1/2", 1, 2.0, Fraction(3, 1), np.int64(4)]) == (
        Fraction(1, 2),
        Fraction(1),
        Fraction(2),
        Fraction(3),
        Fraction(4),
    )
    assert as_orders([0.5, 1 / 3]) == (Fraction(1, 2), Fraction(1, 3))
    assert base_denominator(as_orders(["1/2", "1/3", 1])) == 6


@pytest.mark.parametrize(
    ("orders", "match"),
    [
        ([], "at least one"),
        ([1, 0], "> 0"),
        ([1, -2], "> 0"),
        ([1, 2, "2/1"], "repeat"),
        ([1, 0.123456], "simple rational"),
        ([True], "positive rational"),
        (["x"], "cannot read"),
    ],
)
def test_bad_orders_are_refused(orders, match):
    with pytest.raises(ValueError, match=match):
        as_orders(orders)


def test_spec_defaults_and_force_targets():
    spec = MultisineSpec()
    assert spec.orders == (1, 2, 3)
    assert spec.relative_amplitudes == (1.0, 0.02, 0.02)
    assert spec.fundamental_index == 0
    phi1 = 0.7
    targets = spec.force_targets(6.0, fundamental_phase_rad=phi1)
    np.testing.assert_allclose(np.abs(targets), [6.0, 0.12, 0.12], rtol=1e-14)
    # Phase of order k relative to k times the fundamental's phase (measurement-file convention).
    np.testing.assert_allclose(
        np.angle(targets / np.exp(1j * phi1 * np.array([1, 2, 3]))), 0.0, atol=1e-14
    )


def test_spec_with_subharmonic_and_explicit_phases():
    spec = MultisineSpec(
        orders=("1/2", 1, 2), relative_amplitudes=(0.05, 1, 0.02), phases_rad=(0.1, 0.0, -0.2)
    )
    assert spec.fundamental_index == 1
    targets = spec.force_targets(2.0)
    np.testing.assert_allclose(targets, [0.1 * np.exp(0.1j), 2.0, 0.04 * np.exp(-0.2j)])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"orders": (2, 3)}, "MultisineSpec.orders: order 1"),
        ({"relative_amplitudes": (1, 0.02)}, "MultisineSpec.relative_amplitudes: expected 3"),
        (
            {"relative_amplitudes": (1, -0.1, 0.02)},
            "MultisineSpec.relative_amplitudes: must be >= 0",
        ),
        ({"relative_amplitudes": (0.5, 0.02, 0.02)}, "fundamental's must be 1"),
        ({"phases_rad": (0, np.nan, 0)}, "MultisineSpec.phases_rad: values must be finite"),
    ],
)
def test_spec_validation_names_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MultisineSpec(**kwargs)


@pytest.mark.parametrize("target_hz", [21.0, 24.1, 27.3, 39.9])
def test_plan_gives_whole_periods_on_the_clock(target_hz):
    fs = 5120.0
    plan = plan_period(target_hz, fs, (1, 2, 3))
    assert isinstance(plan.samples_per_period, int)
    assert plan.fundamental_hz == pytest.approx(fs / plan.samples_per_period, rel=1e-15)
    # Rounding the period to whole samples moves the frequency by at most f^2 / (2 fs).
    assert abs(plan.frequency_error_hz) <= target_hz**2 / (2 * fs) * (1 + 1e-9)
    assert plan.cycles_per_period == (1, 2, 3)
    np.testing.assert_allclose(plan.frequencies_hz, plan.fundamental_hz * np.array([1, 2, 3]))


def test_plan_with_subharmonic_uses_the_base_period():
    fs = 4096.0
    plan = plan_period(25.0, fs, ("1/2", 1, 2, 3))
    assert plan.base_denominator == 2
    assert plan.cycles_per_period == (1, 2, 4, 6)
    assert plan.samples_per_period == round(2 * fs / 25.0)
    assert plan.base_frequency_hz == pytest.approx(plan.fundamental_hz / 2)
    assert plan.period_s == pytest.approx(2 / plan.fundamental_hz)


def test_plan_refuses_too_few_samples_and_large_frequency_error():
    with pytest.raises(ValueError, match="min_samples_per_cycle"):
        plan_period(40.0, 500.0, (1, 2, 3))
    with pytest.raises(ValueError, match="max_relative_frequency_error"):
        plan_period(24.1, 1000.0, (1, 2, 3), max_relative_frequency_error=1e-4)
    with pytest.raises(ValueError, match="fundamental_hz"):
        plan_period(-1.0, 1000.0, (1,))


@pytest.mark.parametrize("orders", [(1, 2, 3), ("1/2", 1, 3)])
def test_synthesized_period_matches_direct_evaluation(orders):
    plan = plan_period(24.1, 5120.0, orders)
    n_periods = 3
    wave = synthesize(PHASORS, plan, limit_v=2.0, n_periods=n_periods)
    assert wave.shape == (n_periods * plan.samples_per_period,)
    t = np.arange(wave.size) / plan.sample_rate_hz
    expected = _direct_waveform(PHASORS, plan.orders, plan.fundamental_hz, t)
    np.testing.assert_allclose(wave, expected, atol=1e-12)


def test_synthesis_refuses_rather_than_clips():
    plan = plan_period(30.0, 4800.0, (1, 2, 3))
    peak = np.max(np.abs(synthesize(PHASORS, plan, limit_v=10.0)))
    with pytest.raises(ValueError, match=r"peak 0\.8\d* V exceeds .*limit_v = 0\.5 V"):
        synthesize(PHASORS, plan, limit_v=0.5)
    ok = synthesize(PHASORS, plan, limit_v=peak * (1 + 1e-12))
    assert np.max(np.abs(ok)) == pytest.approx(peak, rel=1e-15)
    with pytest.raises(ValueError, match="expected 3 phasors"):
        synthesize(PHASORS[:2], plan, limit_v=1.0)


def test_waveform_peak_bounds_every_sampled_version():
    rng = np.random.default_rng(3)
    orders = (1, 2, 3)
    for _ in range(20):
        phasors = rng.standard_normal(3) + 1j * rng.standard_normal(3)
        bound = waveform_peak_v(phasors, orders)
        t = np.linspace(0, 1, 200_001)  # a dense independent grid over one period (f = 1 Hz)
        dense_peak = np.max(np.abs(_direct_waveform(phasors, orders, 1.0, t)))
        assert dense_peak <= bound
        # Overestimate at most (pi / 64)^2 / 2 of sum |V_k| (the documented second-order bound).
        assert bound - dense_peak <= 0.5 * (np.pi / 64) ** 2 * np.sum(np.abs(phasors)) + 1e-12


def test_cosine_ramp_properties():
    w = cosine_ramp(64)
    assert w.shape == (64,)
    np.testing.assert_allclose(w + w[::-1], 1.0, atol=1e-15)
    assert np.all(np.diff(w) > 0)
    assert 0 < w[0] < 1e-3 and 1 - 1e-3 < w[-1] < 1
    assert cosine_ramp(0).size == 0
    with pytest.raises(ValueError, match="n_samples"):
        cosine_ramp(-1)


def test_crossfade_between_periodic_waveforms():
    old = np.sin(2 * np.pi * np.arange(50) / 50)
    new = 2 * np.cos(2 * np.pi * np.arange(40) / 40)
    fade = crossfade(old, new, 200)
    w = cosine_ramp(200)
    idx = np.arange(200)
    np.testing.assert_allclose(fade, (1 - w) * old[idx % 50] + w * new[idx % 40], atol=1e-15)
    # A fade of a waveform into itself leaves it unchanged.
    np.testing.assert_allclose(crossfade(old, old, 120), old[np.arange(120) % 50], atol=1e-15)
    # Ramp-down to zero ends near zero.
    assert abs(crossfade(old, np.zeros(1), 100)[-1]) < 1e-3
