"""Time histories of any DOF from a balanced solution, against time integration."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from analysis.elements import make_element
from analysis.linear.receptance import DirectLinearModel
from analysis.mhb.histories import time_history
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.mhb.solver import solve_point

M = np.diag([1.0, 1.0, 0.5])
K = np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]])
C = 0.02 * M + 0.01 * K
K3, F, W = 2.0, 0.5, 0.9


def _problem():
    """3-DOF chain, a cubic spring from DOF 1 to ground, force on DOF 0, output DOF 0 only:
    DOF 2 is neither in the balance nor an output."""
    att = Attachment(make_element("cubic_spring", k3=K3), 1, None, "cubic")
    lin = DirectLinearModel(M, C, K)
    return HarmonicProblem(lin, [att], [0], [0], orders=(1,), n_harmonics=9, n_time=64)


def _integrate(q0, v0, periods):
    """The same equations by DOP853: M q'' + C q' + K q + k3 q1^3 e1 = F cos(W t) e0."""
    Minv = np.linalg.inv(M)

    def rhs(t, y):
        q, v = y[:3], y[3:]
        f = np.array([F * np.cos(W * t), -K3 * q[1] ** 3, 0.0])
        return np.concatenate([v, Minv @ (f - C @ v - K @ q)])

    T = 2 * np.pi / W
    t_eval = (periods - 1) * T + np.arange(128) * T / 128
    sol = solve_ivp(
        rhs,
        (0, periods * T),
        np.concatenate([q0, v0]),
        "DOP853",
        t_eval=t_eval,
        rtol=1e-12,
        atol=1e-14,
    )
    acc = np.array([rhs(t, y)[3:] for t, y in zip(sol.t, sol.y.T, strict=True)])
    return sol.y[:3].T, sol.y[3:].T, acc


def test_time_histories_of_every_dof_match_time_integration():
    pb = _problem()
    p = solve_point(pb, W, np.array([F]))
    assert p.converged
    dofs = [0, 1, 2]
    _, q = p.time_history(pb, dofs, 128)
    _, v = time_history(pb, p, dofs, 128, "velocity")
    _, a = time_history(pb, p, dofs, 128, "acceleration")
    # started on the orbit, 30 periods on: what is left of a start off the orbit (the
    # truncation at 9 harmonics) has decayed; the orbit is stable (it persists)
    q_ti, v_ti, a_ti = _integrate(q[0], v[0], 30)
    for hb, ti in ((q, q_ti), (v, v_ti), (a, a_ti)):
        # 1e-7 of the largest value: the truncation of the balance, not the integration
        assert np.abs(hb - ti).max() < 1e-7 * np.abs(ti).max()
    assert np.abs(q[:, 1]).max() > 0.3  # the cubic spring is well into its nonlinear range


def test_time_history_errors_name_the_argument():
    pb = _problem()
    p = solve_point(pb, W, np.array([F]))
    with pytest.raises(ValueError, match="dofs: expected DOF indices in 0..2"):
        time_history(pb, p, [3])
    with pytest.raises(ValueError, match="quantity: expected one of"):
        time_history(pb, p, 0, quantity="jerk")
