"""Metric frequencies and the equalized test FRFs."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.calibration.linear import equalize, fit_poles, metric_frequencies


def test_metric_frequencies_fill_the_half_power_bands_at_equal_log_steps() -> None:
    f = metric_frequencies(np.array([150.0, 25.0]), 0.01, 5)
    assert f.shape == (10,)
    bands = f.reshape(2, 5)
    for fr, band in zip((25.0, 150.0), bands, strict=True):
        assert band[0] == pytest.approx(fr * 0.99) and band[-1] == pytest.approx(fr * 1.01)
        steps = np.diff(np.log(band))
        np.testing.assert_allclose(steps, steps[0], rtol=1e-12)


@pytest.mark.parametrize("zeta0, n", [(0.0, 5), (0.6, 5), (0.01, 1)])
def test_metric_frequencies_reject_bad_settings(zeta0: float, n: int) -> None:
    with pytest.raises(ValueError):
        metric_frequencies(np.array([10.0]), zeta0, n)


def test_equalize_changes_only_the_damping() -> None:
    """Two modes of 2 % and 0.5 % re-synthesised at 1 % equal the modal sum at 1 %."""
    f = np.linspace(5.0, 60.0, 2000)
    w = 2 * np.pi * f[:, None]
    wr = 2 * np.pi * np.array([20.0, 40.0])
    A = np.array([[1.0, -2.0], [0.5, 3.0]]) * wr[:, None] ** 2 * 1e-6

    def modal_sum(zeta, w):
        return (1 / (wr**2 - w**2 + 2j * np.asarray(zeta) * wr * w)) @ A

    fit = fit_poles(f, modal_sum([0.02, 0.005], w), [20.1, 39.8], [0.01, 0.01])
    eq = equalize(fit, 0.01, 7)
    assert eq.H.shape == (14, 2) and eq.zeta0 == 0.01
    expected = modal_sum([0.01, 0.01], 2 * np.pi * eq.frequency_hz[:, None])
    np.testing.assert_allclose(eq.H, expected, rtol=1e-8)
