"""Folds and peaks located on a branch, and curvature-controlled steps."""

import numpy as np
from scipy.optimize import fsolve

from analysis.elements import make_element
from analysis.linear.receptance import DirectLinearModel
from analysis.mhb.continuation import ContinuationSettings, continue_branch
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.mhb.solver import solve_point

from .systems import duffing

K3, C, F = 0.5, 0.05, 0.1


def _duffing_relation(a, w):
    """Single-harmonic Duffing: R(a, w) = 0 is the amplitude-frequency relation."""
    b = 1 - w * w + 0.75 * K3 * a * a
    return (b * b + (C * w) ** 2) * a * a - F * F, b


def _analytic_fold(a0, w0):
    """R = 0 and dR/da = 0 (a vertical tangent of a(w))."""

    def eqs(x):
        a, w = x
        R, b = _duffing_relation(a, w)
        dRda = 2 * a * (b * b + (C * w) ** 2) + a * a * 2 * b * 1.5 * K3 * a
        return [R / F**2, dRda / F**2]

    return fsolve(eqs, [a0, w0], xtol=1e-12)


def _analytic_peak(a0, w0):
    """R = 0 and dR/dw = 0 (a horizontal tangent): b = c^2 / 2."""

    def eqs(x):
        a, w = x
        R, b = _duffing_relation(a, w)
        return [R / F**2, b - C * C / 2]

    return fsolve(eqs, [a0, w0], xtol=1e-12)


def test_duffing_folds_and_peak_are_located_to_the_newton_tolerance():
    # H = 1 with 16 samples balances the cubic exactly: the first-order relation is the
    # reference, and the located points should agree to the Newton tolerance (1e-10), not to
    # a step length.
    pb = duffing(k3=K3, c=C, n_harmonics=1, n_time=16)
    br = continue_branch(pb, 0.8, 1.8, np.array([F]), ContinuationSettings(stability=False))
    folds = br.turning_points()
    assert [f.kind for f in folds] == ["fold", "fold"]
    assert [f.after + 1 for f in folds] == br.folds
    for f in folds:
        assert f.point.converged and f.point.residual < 1e-10
        a, w = _analytic_fold(f.amplitude, f.omega)
        assert abs(f.omega / w - 1) < 1e-9
        assert abs(f.amplitude / a - 1) < 1e-8
    # the upper fold lies above the peak, on the other side of the bend
    (peak,) = br.peaks()
    a, w = _analytic_peak(peak.amplitude, peak.omega)
    assert abs(peak.omega / w - 1) < 1e-9 and abs(peak.amplitude / a - 1) < 1e-9
    assert peak.omega < folds[0].omega and peak.amplitude > folds[0].amplitude


def test_every_turning_point_of_a_four_mode_curve_is_a_fold():
    # a 4-DOF chain with a hardening cubic spring at every DOF, driven hard enough that each
    # of its four resonances bends over: eight turning points, each a singular balance
    # Jacobian at fixed frequency (an independent check of what a fold is)
    n = 4
    M, K = np.eye(n), 2 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    K[-1, -1] = 1.0
    lin = DirectLinearModel(M, 0.01 * M + 0.002 * K, K)
    atts = [Attachment(make_element("cubic_spring", k3=1.0), d, None, f"c{d}") for d in range(n)]
    pb = HarmonicProblem(lin, atts, [0], list(range(n)), orders=(1,), n_harmonics=1, n_time=16)
    settings = ContinuationSettings(ds=0.1, ds_max=0.5, max_points=5000, stability=False)
    br = continue_branch(pb, 0.2, 2.5, np.array([[0.05]]), settings)
    folds = br.turning_points()
    assert len(folds) == 8 and br.message == "reached the end frequency"
    assert np.all(np.diff([f.after for f in folds]) > 0)

    def smallest_singular_ratio(p):
        J = np.eye(pb.basis.size * n) - p.lin["prep"]["G"] @ p.lin["dF"]
        s = np.linalg.svd(J, compute_uv=False)
        return s[-1] / s[0]

    for f in folds:
        assert smallest_singular_ratio(f.point) < 1e-8
        assert smallest_singular_ratio(br.points[f.after]) > 1e-6
    # per mode: the resonance bent to higher frequency, then the jump-up fold below it, and
    # the next mode's folds above both
    w = np.array([f.omega for f in folds])
    assert np.all(w[0::2] > w[1::2]) and np.all(w[2::2] > w[1:-1:2])


def _chord_distance(br, pb, force):
    """Largest distance, in plot units (frequency span and peak amplitude = 1), between the
    solution at each interval's mid frequency and the straight line between its points."""
    amp, w, T = np.abs(br.outputs()[:, 0, 0]), br.omega, br.tangents
    span, top = w.max() - w.min(), amp.max()
    worst = 0.0
    for i in range(len(w) - 1):
        if np.sign(T[i][-1]) != np.sign(T[i + 1][-1]):
            continue  # the interval holds a fold: no single solution at its mid frequency
        wm = 0.5 * (w[i] + w[i + 1])
        p = solve_point(pb, wm, force, 0.5 * (br.points[i].X + br.points[i + 1].X))
        assert p.converged
        d = np.array([(w[i + 1] - w[i]) / span, (amp[i + 1] - amp[i]) / top])
        n = np.array([-d[1], d[0]]) / np.hypot(*d)
        q = np.array([(wm - w[i]) / span, (abs(p.outputs()[0, 0]) - amp[i]) / top])
        worst = max(worst, abs(q @ n))
    return worst


def test_curvature_control_keeps_the_curve_between_its_points():
    pb = duffing(k3=K3, c=C, n_harmonics=3, n_time=32)
    force = np.array([F])
    kw = {"ds": 0.02, "ds_max": 0.5, "stability": False}
    plain = continue_branch(pb, 0.5, 2.0, force, ContinuationSettings(**kw))
    bent = continue_branch(pb, 0.5, 2.0, force, ContinuationSettings(**kw, max_angle=0.05))
    assert bent.message == "reached the end frequency"
    # turns of at most 0.05 rad between points put the curve within 5e-4 of the plot's size
    # from every chord (measured 2.6e-4); steps sized by the corrector alone miss by 3e-3
    assert _chord_distance(bent, pb, force) < 5e-4
    assert _chord_distance(plain, pb, force) > 1e-3
    turns = np.arccos(np.clip(np.sum(bent.tangents[1:] * bent.tangents[:-1], axis=1), -1, 1))
    assert turns.max() <= 0.05
