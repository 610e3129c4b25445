"""The folds of a cross-validation start from the full calibration's residuals and Jacobian at
the optimum: a fold's residuals are a subset of the full ones, picked by ``residual_index``."""

import numpy as np

from analysis.calibration.crossval import _Started, residual_index
from analysis.calibration.objective import FRFObjective


def _stacked(z: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """:meth:`FRFObjective._stack` with unit weights (the objective's own code)."""
    obj = object.__new__(FRFObjective)
    obj._weight, obj.mask = np.ones(z.shape), mask
    return obj._stack(z)


def test_a_folds_residuals_are_picked_from_the_full_ones():
    rng = np.random.default_rng(4)
    n, C, K = 7, 3, 2
    z = rng.normal(size=(n, C, K)) + 1j * rng.normal(size=(n, C, K))
    full = rng.random((n, C)) < 0.8
    fold = full.copy()
    fold[2:6, 1] = False  # one channel of some steps left out
    picked = _stacked(z, full)[residual_index(full, fold, K)]
    assert picked.size == 2 * fold.sum() * K
    assert np.array_equal(picked, _stacked(z, fold))


def test_the_given_start_is_used_at_the_start_only():
    calls = []

    def objective(theta, want_jac=True):
        calls.append(theta.copy())
        return np.array([2.0]), (np.ones((1, 1)) if want_jac else None)

    r0, J0 = np.array([1.0]), np.zeros((1, 1))
    fun = _Started(objective, np.array([0.5]), r0, J0)
    assert fun(np.array([0.5]))[0] is r0 and fun(np.array([0.5]))[1] is J0
    assert fun(np.array([0.5]), False)[1] is None
    assert not calls
    assert fun(np.array([0.6]))[0][0] == 2.0 and len(calls) == 1
