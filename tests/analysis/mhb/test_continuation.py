"""Continuation through folds and stability of the branches."""

import numpy as np
import pytest
from scipy.optimize import fsolve

from analysis.mhb.continuation import ContinuationSettings, continue_branch
from analysis.mhb.stability import floquet_exponents

from .systems import duffing


def _analytic_fold(a0, w0, k3=0.5, c=0.05, F=0.1):
    """Fold of the single-harmonic Duffing relation: R(a, w) = 0 and dR/da = 0."""

    def eqs(x):
        a, w = x
        b = 1 - w * w + 0.75 * k3 * a * a
        R = (b * b + (c * w) ** 2) * a * a - F * F
        dRda = 2 * a * (b * b + (c * w) ** 2) + a * a * 2 * b * 1.5 * k3 * a
        return [R / F**2, dRda / F**2]

    a, w = fsolve(eqs, [a0, w0], xtol=1e-13)
    assert np.allclose(eqs([a, w]), 0, atol=1e-9)
    return a, w


def test_continuation_passes_both_folds_and_finds_the_unstable_middle_branch():
    pb = duffing(k3=0.5, c=0.05, n_harmonics=1, n_time=16)
    br = continue_branch(
        pb, 0.8, 1.8, np.array([0.1]), ContinuationSettings(ds=0.02, stability=False)
    )
    assert br.message == "reached the end frequency"
    assert len(br.folds) == 2
    amp = np.abs(br.outputs()[:, 0, 0])
    i1, i2 = br.folds
    # Hill's matrix at the balance's own truncation (H = 1), whose real exponent crosses zero
    # at the branch's folds: the default's seven harmonics follow the exact linearisation of
    # this single-harmonic orbit, which changes stability some points past its folds
    stable = np.array([floquet_exponents(pb, p, method="hill_full").stable for p in br.points])
    # peak fold at the top, jump-up fold at the bottom; the part between is unstable
    assert amp[i1] > amp[i2]
    assert stable[: i1 - 1].all() and stable[i2 + 2 :].all()
    assert not stable[i1 + 2 : i2 - 1].any()
    # both fold frequencies agree with the analytic relation (the continuation steps past a
    # fold by one arclength step at most: 2e-3 relative)
    for i in (i1, i2):
        a_an, w_an = _analytic_fold(amp[i], br.omega[i])
        assert abs(br.omega[i] / w_an - 1) < 2e-3
        assert abs(amp[i] / a_an - 1) < 5e-2


def test_hill_exponents_agree_with_the_monodromy_matrix():
    pb = duffing(k3=0.5, c=0.05, n_harmonics=5, n_time=256)
    br = continue_branch(
        pb, 1.0, 1.6, np.array([0.1]), ContinuationSettings(ds=0.05, stability=False)
    )
    for p in br.points[:: max(1, len(br.points) // 8)]:
        h = floquet_exponents(pb, p, method="hill")
        m = floquet_exponents(pb, p, method="monodromy")
        assert h.stable == m.stable
        # piecewise-constant monodromy is first order in 1/N: 2 % of the damping rate
        assert abs(h.max_real - m.max_real) < 0.02 * 0.05 + 0.02 * abs(m.max_real)


@pytest.mark.parametrize("case", ["contact chain", "paper model", "half order"])
def test_the_residuals_frequency_derivative_equals_central_differences(case):
    """The continuation's ``dR/domega`` (receptances differentiated exactly, forces by
    differences) against central differences of the whole residual (Richardson-extrapolated
    from two steps, error O(h^4)), to 1e-6 of its largest, at a solution in contact: on a
    direct model, on the paper's model (modal, behind the shaker's static support) and with
    a half order (the base frequency half the fundamental)."""
    from fractions import Fraction

    from analysis.mhb.continuation import _System
    from analysis.mhb.solver import solve_point

    from .systems import contact_chain

    if case == "paper model":
        from analysis.model import load_model
        from analysis.system import build_problem

        pb, w, force = build_problem(load_model()), 2 * np.pi * 26.0, np.array([8.0, 0.16, 0.16])
    elif case == "contact chain":
        pb, w, force = contact_chain(), 130.0, np.array([20.0, 0.4, 0.4])
    else:
        pb = duffing(k3=0.5, orders=(Fraction(1, 2), Fraction(1)), n_harmonics=6)
        w, force = 1.3, np.array([0.05, 0.3])
    p = solve_point(pb, w, force)
    assert p.converged and np.abs(p.f_nl).max() > 0  # the element acts
    sysm = _System(pb, force)
    exact = sysm.d_omega(p.X, w)

    def central(h):
        return (sysm.residual(p.X, w + h, False)[0] - sysm.residual(p.X, w - h, False)[0]) / (2 * h)

    h = 1e-5 * w
    fd = (4 * central(h) - central(2 * h)) / 3
    assert np.abs(exact - fd).max() <= 1e-6 * np.abs(fd).max()
