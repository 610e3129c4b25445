"""The rig with the paper's contact: balance against time integration, and convergence in H.

Both solve one model: the calibrated rig (Table 2 linear values, Table 5 contact with the measured
gap) with modes to 600 Hz plus residual static shapes. The balance uses the analysis defaults
(``DEFAULT_HARMONICS``, ``DEFAULT_TIME_SAMPLES``). Acceptance (per order k = 1..3):
``|Q_k^MHB - Q_k^TI| <= 0.01 |Q_1|`` and, where ``|Q_k| > 0.01 |Q_1|``,
``|Q_k^MHB - Q_k^TI| <= 0.05 |Q_k|``.
"""

import numpy as np
import pytest

from analysis.mhb.sweep import solve_steps
from analysis.mhb.time_integration import (
    integrate_steady_state,
    state_from_balance,
    time_domain_model,
)
from analysis.model import load_model
from analysis.system import build_linear, build_problem

PAPER = {
    "E_frame": 205e9,
    "E_corner": 128e9,
    "E_beam": 201e9,
    "rho_corner": 5175.0,
    "k_mount": 57989.0,
    "k_c": 4.51e5,
    "gap": 0.60e-3,
    "v_c": 25.21,
}


@pytest.fixture(scope="module")
def rig():
    model = load_model().with_values(PAPER)
    return model, build_linear(model, f_max_hz=600.0)


def _force(level):
    return np.array([level, 0.02 * level, 0.02 * level])


def _check(q_mhb, q_ti):
    fund = abs(q_mhb[0])
    for k in range(3):
        d = abs(q_mhb[k] - q_ti[k])
        assert d <= 0.01 * fund, (k, d / fund)
        if abs(q_mhb[k]) > 0.01 * fund:
            assert d <= 0.05 * abs(q_mhb[k]), (k, d / abs(q_mhb[k]))


@pytest.mark.slow
@pytest.mark.parametrize(
    "level, freqs_hz",
    [(2.0, (25.5, 26.8, 28.5)), (8.0, (26.0, 28.8, 32.0))],
    ids=["2N", "8N"],
)
def test_rig_balance_matches_time_integration(rig, level, freqs_hz):
    """Below, at and above the contact resonance, stepping up as a test does."""
    model, lin = rig
    pb = build_problem(model, linear=lin, output_points=(3, 6, 7))
    mdl = time_domain_model(pb)
    F = _force(level)
    grid = np.arange(24.0, max(freqs_hz) + 1e-9, 0.2)
    grid = np.unique(np.round(np.concatenate([grid, freqs_hz]), 6))
    sweep = solve_steps(pb, 2 * np.pi * grid, F)
    assert sweep.converged.all()
    closed = False
    for f in freqs_hz:
        i = int(np.flatnonzero(np.isclose(grid, f))[0])
        p = sweep.points[i]
        # start where a stepped test starts: the steady state of the previous step (0.2 Hz below)
        state = state_from_balance(pb, sweep.points[i - 1], mdl)
        ti = integrate_steady_state(pb, 2 * np.pi * f, F, state, model=mdl, rtol=1e-8)
        assert ti.converged
        closed |= pb.basis.to_time(p.X)[:, 0].min() < -PAPER["gap"]
        for j in range(3):  # every sensor
            _check(p.outputs()[:, j], ti.outputs()[:, j])
    assert closed  # the contact was closed at one of the checked steps at least


def test_convergence_in_the_number_of_harmonics(rig):
    """Orders 1-3 converge with H; the default is within 5e-3 of the fundamental of H = 25."""
    model, lin = rig
    grid = 2 * np.pi * np.arange(25.0, 29.01, 0.25)
    F = _force(8.0)
    out = {}
    for H, N in ((3, 64), (5, 64), (9, 128), (15, 512), (25, 1024)):
        pb = build_problem(model, linear=lin, n_harmonics=H, n_time=N)
        r = solve_steps(pb, grid, F)
        assert r.converged.all()
        out[H] = r.outputs()
    ref = out.pop(25)
    fund = np.abs(ref[:, 0, :]).max()
    err = {H: np.abs(o - ref).max() / fund for H, o in out.items()}
    assert err[3] > err[9] and err[5] > err[9]
    assert err[9] < 5e-3
    assert err[15] < 5e-3
