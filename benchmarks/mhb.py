"""MHB speed and accuracy on the paper's sweep.

The whole paper sweep (21-40 Hz in 1 Hz plus 0.1 Hz in 24-28 Hz, overlaps removed, stepping up;
levels 2/4/6/8 N; force orders 1-3 with the 2nd and 3rd at 2 %) on the calibrated rig, with the
analysis defaults for harmonics and AFT samples. Time integration (shooting to periodic steady
state, as in the validation test) on a sample of steps gives ``ti_ratio`` and ``max_rel_diff``.
"""

from __future__ import annotations

import time

import numpy as np

from analysis.mhb.sweep import solve_steps
from analysis.mhb.time_integration import (
    integrate_steady_state,
    state_from_balance,
    time_domain_model,
)
from analysis.model import load_model
from analysis.paper import MEASURED_GAP_M, PAPER_CALIBRATED, paper_frequencies_hz
from analysis.system import DEFAULT_HARMONICS, DEFAULT_TIME_SAMPLES, build_linear, build_problem

#: The paper's calibrated model with the gap it measured (0.60 mm) rather than calibrated.
PAPER_VALUES = {**PAPER_CALIBRATED, "gap": MEASURED_GAP_M}
LEVELS_N = (2.0, 4.0, 6.0, 8.0)
TI_POINTS = {2.0: (25.5, 27.2, 30.0), 8.0: (26.0, 29.0, 32.0)}  # below, at, above resonance


def _force(level: float) -> np.ndarray:
    return np.array([level, 0.02 * level, 0.02 * level])


def _paper_problem():
    """The calibrated rig's linear model and balance problem (analysis defaults)."""
    model = load_model().with_values(PAPER_VALUES)
    lin = build_linear(model, f_max_hz=600.0)
    return lin, build_problem(model, linear=lin)


def _time_sweeps(pb, repeats: int):
    """The paper sweep at every level ``repeats`` times: (the last sweeps, median wall time)."""
    omega = 2 * np.pi * paper_frequencies_hz()
    solve_steps(pb, omega[:5], _force(2.0))  # warm-up (imports, caches)
    sweeps, times = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        sweeps = [solve_steps(pb, omega, _force(level)) for level in LEVELS_N]
        times.append(time.perf_counter() - t0)
    return sweeps, float(np.median(times))


def paper_sweep_s(repeats: int = 3) -> float:
    """Wall time of the paper sweep (median of ``repeats``): the machine's present speed at
    the balance, for other benchmarks to state their times against."""
    return _time_sweeps(_paper_problem()[1], repeats)[1]


def run(quick: bool = False) -> dict:
    t0 = time.perf_counter()
    lin, pb = _paper_problem()
    setup_s = time.perf_counter() - t0
    freqs = paper_frequencies_hz()
    repeats = 1 if quick else 5
    sweeps, sweep_s = _time_sweeps(pb, repeats)
    n_points = sum(len(s.points) for s in sweeps)
    converged = sum(int(s.converged.sum()) for s in sweeps)
    print(
        f"paper sweep: {n_points} points, H={DEFAULT_HARMONICS}, N={DEFAULT_TIME_SAMPLES}, "
        f"{len(lin.modes)} modes + residual flexibility"
    )
    print(
        f"  sweep wall time (median of {repeats}): {sweep_s:.3f} s "
        f"({1e3 * sweep_s / n_points:.2f} ms/point), converged {converged}/{n_points}"
    )

    mdl = time_domain_model(pb)
    ti_time, mhb_time, n_ti, max_diff = 0.0, 0.0, 0, 0.0
    items = list(TI_POINTS.items())[: 1 if quick else None]
    print("  time integration vs MHB (relative to the fundamental, orders 1-3, sensors 3/6/7):")
    for level, pts in items:
        sweep = sweeps[LEVELS_N.index(level)]
        for f in pts[: 1 if quick else None]:
            i = int(np.flatnonzero(np.isclose(freqs, f))[0])
            t0 = time.perf_counter()
            p = solve_steps(pb, [2 * np.pi * f], _force(level), X0=sweep.points[i - 1].X).points[0]
            mhb_time += time.perf_counter() - t0
            # started where a stepped test starts: the previous step's steady state
            state = state_from_balance(pb, sweep.points[i - 1], mdl)
            t0 = time.perf_counter()
            ti = integrate_steady_state(
                pb, 2 * np.pi * f, _force(level), state, model=mdl, rtol=1e-8
            )
            ti_time += time.perf_counter() - t0
            n_ti += 1
            fund = np.abs(p.outputs()[0]).max()
            d = float(np.abs(ti.outputs() - p.outputs()).max() / fund)
            max_diff = max(max_diff, d)
            print(f"    {level:.0f} N {f:5.1f} Hz: diff {d:.2e}, {ti.periods} periods integrated")
    per_point_mhb = sweep_s / n_points
    ti_ratio = (ti_time / n_ti) / per_point_mhb
    print(
        f"  time integration: {ti_time / n_ti:.2f} s/point; MHB {1e3 * per_point_mhb:.2f} ms/point"
        f" in the sweep -> ratio {ti_ratio:.0f}"
    )
    return {
        "sweep_s": round(sweep_s, 4),
        "ms_per_point": round(1e3 * per_point_mhb, 3),
        "converged_fraction": converged / n_points,
        "ti_ratio": round(ti_ratio, 1),
        "max_rel_diff": float(f"{max_diff:.3e}"),
        "n_points": n_points,
        "n_harmonics": DEFAULT_HARMONICS,
        "n_time": DEFAULT_TIME_SAMPLES,
        "setup_s": round(setup_s, 3),
        "ti_points": n_ti,
    }
