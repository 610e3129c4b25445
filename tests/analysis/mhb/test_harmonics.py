from fractions import Fraction

import numpy as np
import pytest

from analysis.mhb.harmonics import HarmonicBasis, base_denominator, order_indices


def test_aft_round_trip_is_exact_for_band_limited_signals():
    b = HarmonicBasis(7, 32)
    c = np.random.default_rng(0).standard_normal((b.size, 3))
    assert np.allclose(b.from_time(b.to_time(c)), c, atol=1e-13)


def test_complex_phasors_follow_the_measurement_file_convention():
    b = HarmonicBasis(4, 20)
    c = np.random.default_rng(1).standard_normal(b.size)
    X = b.to_complex(c)
    x = np.real(sum(X[k] * np.exp(1j * k * b.tau) for k in range(5)))
    assert np.allclose(x, b.to_time(c), atol=1e-13)
    assert np.allclose(b.from_complex(X), c)


def test_rate_is_the_analytic_derivative():
    b = HarmonicBasis(3, 16)
    c = np.zeros(b.size)
    c[3] = 2.0  # a2: 2 cos(2 tau)
    w = 5.0
    assert np.allclose(b.rate_to_time(c, w), -2.0 * 2 * w * np.sin(2 * b.tau), atol=1e-12)


def test_time_shift_delays_the_signal():
    b = HarmonicBasis(3, 64)
    c = np.random.default_rng(2).standard_normal(b.size)
    x = b.to_time(c)
    shifted = b.to_time(b.time_shift_matrix(2 * np.pi * 5 / 64) @ c)
    assert np.allclose(shifted, np.roll(x, 5), atol=1e-12)


def test_sub_harmonic_orders_map_to_base_harmonics():
    orders = (Fraction(1, 2), Fraction(1), Fraction(2))
    d = base_denominator(orders)
    assert d == 2
    assert list(order_indices(orders, d)) == [1, 2, 4]


def test_bad_sampling_is_refused():
    with pytest.raises(ValueError, match="n_time"):
        HarmonicBasis(10, 15)
