"""The equalized log-magnitude deviation: analytic Jacobian, exact recovery of model targets."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.calibration.linear import METHODS, EqualizedFRFObjective, metric_frequencies
from analysis.calibration.parameters import ParameterSpace
from analysis.model import load_model
from tests.analysis.calibration_linear.synthetic import SENSOR_MASS_KG, TRUE_VALUES

ZETA0 = 0.01


def _objective(use_phase: bool = False, target_values=TRUE_VALUES) -> EqualizedFRFObjective:
    """Points 1-8 and 11 against the model's own equalized FRFs at ``target_values``."""
    model = load_model().add_masses({p: SENSOR_MASS_KG for p in range(1, 14)})
    names = model.parameter_names("linear", True)
    space = ParameterSpace.from_model(model, names)
    asm = model.assemble()
    rows = [asm.point_dof(p) for p in (1, 2, 3, 4, 5, 6, 7, 8, 11)]
    col = asm.point_dof(3)
    truth = model.with_values(target_values)
    f_modes, _ = truth.assemble().normal_modes(7)
    freq = metric_frequencies(f_modes, ZETA0, 5)
    placeholder = np.ones((freq.size, len(rows)), complex)
    obj = EqualizedFRFObjective(
        model, space, rows, col, freq, placeholder, ZETA0, 5000.0, use_phase
    )
    x_true = space.to_theta(np.array([target_values[n] for n in names]))
    target, _ = obj.frf(x_true)
    return EqualizedFRFObjective(model, space, rows, col, freq, target, ZETA0, 5000.0, use_phase)


def _fd_jacobian(obj, x, h=5e-3, n=9):
    """Slopes of cubic fits to the residuals at ``n`` steps in ``[-h, h]`` per parameter.

    The eigen-solution's round-off (about 1e-5 in log10 |H| near the mount modes) makes plain
    differences with small steps noisy; the fit averages it out.
    """
    s = np.linspace(-h, h, n)
    V = np.vander(s, 4, increasing=True)
    J = np.empty((obj.n_residuals, x.size))
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = 1.0
        R = np.array([obj.residuals(x + si * e) for si in s])
        J[:, j] = np.linalg.lstsq(V, R, rcond=None)[0][1]
    return J


@pytest.mark.parametrize("use_phase", [False, True])
def test_jacobian_matches_finite_differences(use_phase: bool) -> None:
    obj = _objective(use_phase)
    x0 = obj.space.to_theta(np.array([load_model().parameters[n].value for n in obj.space.names]))
    x = 0.5 * (x0 + obj.space.to_theta(np.array([TRUE_VALUES[n] for n in obj.space.names])))
    r, J = obj(x)
    assert r.shape == (obj.n_residuals,) and J.shape == (obj.n_residuals, 5)
    Jfd = _fd_jacobian(obj, x)
    err = np.linalg.norm(J - Jfd, axis=0) / np.linalg.norm(Jfd, axis=0)
    assert np.all(err < 1e-2), err


def test_model_target_recovered_from_nominal() -> None:
    """Without identification error LM finds the target's parameters (to 1e-5) in one stage."""
    obj = _objective()
    space = obj.space
    x0 = space.to_theta(np.array([space.nominal[i] for i in range(space.size)]))
    sol = METHODS["lm"](obj, x0, space.theta_bounds(), 100)
    p = space.to_physical(sol.x)
    expected = np.array([TRUE_VALUES[n] for n in space.names])
    np.testing.assert_allclose(p, expected, rtol=1e-5)
    assert sol.cost < 1e-8  # round-off of the eigen-solution


def test_a_point_evaluated_again_for_its_jacobian_reuses_its_eigensolution(monkeypatch) -> None:
    """A fit evaluates its accepted trial once more with the Jacobian: the eigensolution is
    taken from the evaluation before (one decomposition, not two), and the residuals and
    Jacobian are those of a fresh objective bit for bit; another point decomposes again."""
    import analysis.linear.receptance as receptance

    calls = []
    real = receptance.modal_analysis
    monkeypatch.setattr(
        receptance, "modal_analysis", lambda *a, **k: calls.append(1) or real(*a, **k)
    )
    obj, fresh = _objective(), _objective()
    calls.clear()
    x = obj.space.to_theta(np.array([TRUE_VALUES[n] for n in obj.space.names])) + 0.01
    obj(x, False)
    r, J = obj(x, True)
    assert len(calls) == 1
    r0, J0 = fresh(x, True)
    assert np.array_equal(r, r0) and np.array_equal(J, J0)
    obj(x + 0.01, False)
    assert len(calls) == 3
