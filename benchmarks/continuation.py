"""``python -m benchmarks continuation``: the example curves of ``examples/`` and how exactly
their folds, peaks and chords are placed.

Figures: the wall time and points of each example's curve (as its script computes it), the
folds and peak of the single-harmonic Duffing oscillator against its closed-form relation,
the largest distance of the curve from its chords with curvature control, and the share of
failed single-point solves near a stiff stop that the robust solve recovers. ``--quick``: the
Duffing oscillator only.
"""

from __future__ import annotations

import importlib.util
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
from scipy.optimize import fsolve

from analysis.elements import make_element
from analysis.linear.receptance import DirectLinearModel
from analysis.mhb.continuation import ContinuationSettings, continue_branch
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.mhb.robust import solve_point_robust
from analysis.mhb.solver import solve_point

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
K3, C, F = 0.5, 0.05, 0.1  # examples/duffing.toml


def load_example(name: str):
    """The script ``examples/NAME.py`` as a module."""
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _closed_form(a0: float, w0: float, kind: str) -> tuple[float, float]:
    """Fold (dR/da = 0) or peak (dR/dw = 0) of the single-harmonic Duffing relation R = 0."""

    def eqs(x):
        a, w = x
        b = 1 - w * w + 0.75 * K3 * a * a
        R = ((b * b + (C * w) ** 2) * a * a - F * F) / F**2
        if kind == "fold":
            return [R, (2 * a * (b * b + (C * w) ** 2) + 3 * K3 * a**3 * b) / F**2]
        return [R, b - C * C / 2]

    a, w = fsolve(eqs, [a0, w0], xtol=1e-12)
    return a, w


def _located_errors() -> float:
    _, branch = load_example("duffing").curve(n_harmonics=1)
    errors = []
    for loc in branch.turning_points() + branch.peaks():
        _, w = _closed_form(loc.amplitude, loc.omega, loc.kind)
        errors.append(abs(loc.omega / w - 1))
    return max(errors)


def _chord_distance(max_angle: float | None) -> tuple[float, int]:
    """Largest distance (plot units) of the solution at each mid frequency from the chord."""
    lin = DirectLinearModel([[1.0]], [[C]], [[1.0]])
    att = Attachment(make_element("cubic_spring", k3=K3), 0, None, "cubic")
    pb = HarmonicProblem(lin, [att], [0], [0], orders=(Fraction(1),), n_harmonics=3, n_time=32)
    settings = ContinuationSettings(ds=0.02, ds_max=0.5, stability=False, max_angle=max_angle)
    br = continue_branch(pb, 0.5, 2.0, np.array([F]), settings)
    amp, w, T = np.abs(br.outputs()[:, 0, 0]), br.omega, br.tangents
    span, top, worst = w.max() - w.min(), amp.max(), 0.0
    for i in range(len(w) - 1):
        if np.sign(T[i][-1]) != np.sign(T[i + 1][-1]):
            continue
        wm = 0.5 * (w[i] + w[i + 1])
        p = solve_point(pb, wm, np.array([F]), 0.5 * (br.points[i].X + br.points[i + 1].X))
        d = np.array([(w[i + 1] - w[i]) / span, (amp[i + 1] - amp[i]) / top])
        n = np.array([-d[1], d[0]]) / np.hypot(*d)
        q = np.array([(wm - w[i]) / span, (abs(p.outputs()[0, 0]) - amp[i]) / top])
        worst = max(worst, abs(q @ n))
    return worst, len(w)


def _robust_recovery() -> tuple[int, int]:
    lin = DirectLinearModel([[1.0]], [[0.02]], [[1.0]])
    att = Attachment(make_element("gap_spring", k=20.0, gap=0.5), 0, None, "stop")
    pb = HarmonicProblem(lin, [att], [0], [0], orders=(Fraction(1),), n_harmonics=9, n_time=256)
    force = np.array([0.1])
    br = continue_branch(pb, 0.85, 1.1, force, ContinuationSettings(max_angle=0.1, stability=False))
    failed = [p for p in br.points if not solve_point(pb, p.omega, force).converged]
    return sum(solve_point_robust(pb, p.omega, force).converged for p in failed), len(failed)


def run(quick: bool = False) -> dict:
    figures: dict = {}
    names = ["duffing"] if quick else ["duffing", "two_dof_hertz", "cantilever_tip_contact"]
    for name in names:
        t0 = time.perf_counter()
        _, branch = load_example(name).curve()
        folds = branch.turning_points()
        wall = time.perf_counter() - t0
        figures[f"{name}_s"] = round(wall, 3)
        figures[f"{name}_points"] = len(branch.points)
        figures[f"{name}_folds"] = len(folds)
        print(f"{name}: {len(branch.points)} points, {len(folds)} folds in {wall:.2f} s")
    figures["located_max_rel_err"] = _located_errors()
    print(f"Duffing H = 1: folds and peak vs closed form {figures['located_max_rel_err']:.2g}")
    if not quick:
        for angle in (None, 0.1, 0.05):
            dist, n = _chord_distance(angle)
            key = "chord_distance_" + ("plain" if angle is None else f"{angle:g}_rad")
            figures[key] = dist
            print(f"max_angle {angle}: {n} points, curve within {dist:.2g} of its chords")
        ok, failed = _robust_recovery()
        figures["robust_recovered"] = f"{ok}/{failed}"
        print(f"robust single-point solve near a stiff stop: {ok} of {failed} failures recovered")
    return figures
