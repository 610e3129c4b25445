"""The paper's calibration method end to end on simulated runs of the ``reference`` truth.

The simulated random test and stepped-sine run are made first with the rig's own commands
(``rig linear``, ``rig run paper``: not timed). Then the analysis part is timed from the files to
the validated model: linear calibration, pretest planning of all 14 700 configurations, Latin
hypercube starts and Levenberg-Marquardt, 9-fold cross-validation, validation at 8 N;
``calibrate_total_s`` is the nonlinear calibration alone as ``rig workflow`` runs it (``analysis
calibrate``: the starts, LM, the joint refinement and the folds, on a local process pool; see
:func:`nonlinear_calibration`). Errors are
signed, relative to the truth's parameter values; ``z`` is each error over its stated sigma
(``std``: the reported one, with the held values' uncertainty and the folds' evidence;
``std_noise`` and ``cv_std_ratio`` the noise-only one and the folds' scatter over it).
``linear_max_rel_err`` is taken over the linear parameters the linear calibration fits; those
it holds at their prior are ``linear_held``.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from analysis.calibration.crossval import cross_validate
from analysis.calibration.linear import calibrate_linear
from analysis.calibration.nonlinear import CalibrationSettings, calibrate_nonlinear
from analysis.calibration.uncertainty import held_for_run
from analysis.calibration.validation import validate
from analysis.executors import open_executor
from analysis.measurement_file import read_measurement
from analysis.model import load_model
from analysis.planning import plan_tests
from sim_backend.truth import load_truth

LINEAR = ("E_frame", "E_corner", "E_beam", "rho_corner", "k_mount")


def _make_runs(folder: Path, seed: int, quick: bool) -> tuple[Path, Path]:
    lin, paper = folder / "linear.h5", folder / "paper.h5"
    common = [
        "--backend",
        "sim",
        "--truth",
        "reference",
        "--seed",
        str(seed),
        "--quiet",
        "--overwrite",
        "--lock-dir",
        str(folder / "locks"),
    ]
    for argv in (["linear", "--out", str(lin)], ["run", "paper", "--out", str(paper)]):
        r = subprocess.run(
            [sys.executable, "-m", "rig", *argv, *common], capture_output=True, text=True
        )
        if r.returncode != 0:
            raise RuntimeError(f"rig {' '.join(argv)} failed:\n{r.stderr[-2000:]}")
    return lin, paper


def nonlinear_calibration(model, data, held, n_starts: int = 100):
    """The nonlinear calibration as ``rig workflow`` runs it (``analysis calibrate``): Latin
    hypercube starts, LM, the joint refinement with the held values and the cross-validation
    widening the intervals, on a local process pool of every CPU.

    Returns ``(calibration, cross-validation, wall seconds)``."""
    st = CalibrationSettings(n_starts=n_starts, seed=0)
    t0 = time.perf_counter()
    with open_executor(None) as ex:
        cal = calibrate_nonlinear(model, data, st, executor=ex, held=held)
        cv = cross_validate(model, data, cal, executor=ex)
        cal.widen_with_folds(cv.std_ratio, [cv.folds[j] for j in cv.misfit_folds()])
    return cal, cv, time.perf_counter() - t0


def calibrate_total_s(seed: int = 7) -> float:
    """Wall time of :func:`nonlinear_calibration` (100 starts) on the paper run of the
    ``reference`` truth (the simulated runs and the linear calibration made first, not
    timed)."""
    with tempfile.TemporaryDirectory() as tmp:
        lin_path, paper_path = _make_runs(Path(tmp), seed=seed, quick=False)
        lin = calibrate_linear(load_model(), read_measurement(lin_path))
        data = read_measurement(paper_path)
        held = held_for_run(lin.to_json(), lin.model, data, source="the linear result")
        return nonlinear_calibration(lin.model, data, held)[2]


def run(quick: bool = False) -> dict:
    truth = load_truth("reference").model.values()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        t0 = time.perf_counter()
        lin_path, paper_path = _make_runs(folder, seed=7, quick=quick)
        print(f"simulated runs made in {time.perf_counter() - t0:.1f} s (not timed below)")
        nominal = load_model()
        t_total = time.perf_counter()
        t0 = time.perf_counter()
        lin = calibrate_linear(nominal, read_measurement(lin_path))
        linear_s = time.perf_counter() - t0
        model = lin.model
        t0 = time.perf_counter()
        plan = plan_tests(model, executor=None if quick else "process")
        planning_s = time.perf_counter() - t0
        data = read_measurement(paper_path)
        n_starts = 20 if quick else 100
        # as `analysis calibrate` does it: the linear result's uncertainty held, the folds
        # widening the intervals
        held = held_for_run(lin.to_json(), model, data, source="the linear result")
        cal, cv, nonlinear_s = nonlinear_calibration(model, data, held, n_starts)
        cv_s = cv.seconds
        val = validate(model, data, cal)
        total_s = time.perf_counter() - t_total
    p = cal.parameters
    rel = {k: p[k] / truth[k] - 1 for k in ("gap", "k_c", "v_c")}
    lin_err = {k: lin.parameters[k] / truth[k] - 1 for k in LINEAR}
    fitted = [k for k in LINEAR if lin.status.get(k, "fitted") == "fitted"]
    print(
        f"linear calibration {linear_s:.1f} s: "
        + ", ".join(f"{k} {100 * v:+.2f} %" for k, v in lin_err.items())
    )
    for line in lin.identifiability_notes():
        print(line)
    print(f"planning {planning_s:.1f} s; best: {plan.top[0] if plan.top else None}")
    print(
        f"nonlinear: LHS {cal.timings['lhs_s']:.1f} s, LM {cal.timings['lm_s']:.1f} s "
        f"({cal.lm.nit} iterations); gap {100 * rel['gap']:+.2f} %, k_c {100 * rel['k_c']:+.2f}"
        f" %, v {100 * rel['v_c']:+.2f} %; chi2/dof {cal.chi2_per_dof:.2f}"
    )
    print(f"nonlinear calibration as the workflow runs it: {nonlinear_s:.1f} s")
    print(f"cross-validation {cv_s:.1f} s: std ratio {np.round(cv.std_ratio, 2).tolist()}")
    for line in cv.notes():
        print(f"  {line}")
    print(val.summary())
    print(f"analysis total {total_s:.1f} s")
    return {
        "planning_s": round(planning_s, 3),
        "linear_s": round(linear_s, 3),
        "lhs_s": round(cal.timings["lhs_s"], 3),
        "lm_s": round(cal.timings["lm_s"], 3),
        "lm_iterations": cal.lm.nit,
        "cv_s": round(cv_s, 3),
        "calibrate_total_s": round(nonlinear_s, 3),
        "total_s": round(total_s, 3),
        "gap_rel_err": rel["gap"],
        "kc_rel_err": rel["k_c"],
        "v_rel_err": rel["v_c"],
        "linear_max_rel_err": max(abs(lin_err[k]) for k in fitted),
        "linear_rel_err": lin_err,
        "linear_held": list(lin.held()),
        "linear_undetermined": lin.undetermined(),
        "cv_std_ratio": [float(x) for x in cv.std_ratio],
        "std_noise": cal.std_noise,
        "std": cal.std,
        "z": {k: (p[k] - truth[k]) / cal.std[k] for k in ("gap", "k_c", "v_c")},
        "chi2_per_dof": cal.chi2_per_dof,
        "validation_passed": val.passed,
        "validation_chi2_per_dof": val.chi2_per_dof,
        "n_starts": n_starts,
    }
