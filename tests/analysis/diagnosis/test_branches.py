"""Predictions on the measured branch."""

from __future__ import annotations

import numpy as np

from analysis.diagnosis import BranchMatchedPredictor, compare


def test_the_true_model_fits_its_own_run_at_the_noise(runs, reference_model) -> None:
    data = runs("reference")
    cmp = compare(reference_model, data, predictor=BranchMatchedPredictor(reference_model, data))
    assert 0.7 < cmp.rms_over_noise < 1.3  # tolerance: noise of about 300 FRF values
    grid, levels = cmp.map_sensor_order_level()
    assert grid.shape == (3, 3, 3) and levels == [2.0, 5.0, 8.0]


def test_derivatives_are_those_of_the_chosen_solutions(runs, reference_model) -> None:
    data = runs("two_sided_stop")
    pred = BranchMatchedPredictor(reference_model, data)
    p0 = pred.predict(params=["gap"])
    h = 1e-8
    p1 = pred.predict({"gap": reference_model.parameters["gap"].value + h})
    ok = p0.converged & p1.converged
    fd = (p1.frf[ok] - p0.frf[ok]) / h
    err = np.abs(fd - p0.d_frf["gap"][ok]) / np.abs(fd).max()
    assert np.nanpercentile(err, 95) < 1e-2  # away from switches the derivative is exact
