"""``python -m benchmarks speed``: where a user waits, against a fixed workload of this machine.

Figures (last JSON line):

- ``machine_ref_s``: a fixed numpy/LAPACK workload (dense 400 x 400 eigenvalues and solves,
  the same every run), timed in the same run, so that a slow phase of the machine shows.
- ``hill_over_solve`` {H: ratio}: on the cantilever with a tip stop
  (``examples/cantilever_tip_contact.py``, 30-60 Hz through its folds) at H = 5, 10, 20, the
  median over the curve's points of the Floquet exponents' time (the default method) over the
  solve's time per point (the continuation's wall time without stability over its points);
  ``solve_s_per_point`` {H: seconds}; ``hill_full_s`` {H: seconds}: Hill's matrix of the whole
  model at the curve's middle point, for comparison.
- ``stability_agrees``: the default method's stable/unstable verdict equals the monodromy
  matrix's at every point of those curves and of the impact oscillator's curve
  (``examples/impact_oscillator.py``, two period-doubling points); ``stability_disagree``
  counts the points that differ per curve; ``leading_multiplier_rel_err_max`` the largest
  relative difference of the leading Floquet multipliers.
- ``paper_sweep_s``: the paper sweep (224 steps, H = 9) as ``benchmarks mhb`` times it.
- ``sim_paper_run_s`` {truth: seconds}: ``rig run paper`` on the simulated rig of every
  shipped truth, two at a time; ``sim_slowest_over_reference``; a run over
  :data:`SIM_TIMEOUT_S` is stopped and reported as null.
- ``calibrate_total_s``: the nonlinear calibration as ``rig workflow`` calls it (Latin
  hypercube starts, Levenberg-Marquardt, the folds of the cross-validation) on the paper run
  of ``benchmarks calibrate``; ``diagnosis_s_max``: ``max_diagnosis_s`` of the last recorded
  ``benchmarks diagnose`` run (``diagnosis_code``: the code it measured), null without one.

``--quick``: H = 5 only, the monodromy matrix at every 16th beam point, one paper sweep, no
simulated runs and no calibration (null). ``python -m benchmarks.speed PART...`` runs some
parts only (``stability``, ``sweep``, ``sim``, ``calibrate``) and records nothing.
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from analysis.mhb.stability import cross_check, floquet_exponents
from benchmarks.continuation import load_example
from benchmarks.results import FOLDER

HARMONICS = (5, 10, 20)
#: a simulated paper run longer than this is stopped (the benchmark must end in 45 minutes)
SIM_TIMEOUT_S = 900.0
PARTS = ("stability", "sweep", "sim", "calibrate")


def machine_ref_s() -> float:
    """Wall time of a fixed dense workload: 3 times the eigenvalues and a solve of the same
    seeded 400 x 400 matrix."""
    rng = np.random.default_rng(0)
    A = rng.standard_normal((400, 400))
    B = rng.standard_normal((400, 40))
    t0 = time.perf_counter()
    for _ in range(3):
        np.linalg.eigvals(A)
        np.linalg.solve(A, B)
    return time.perf_counter() - t0


def _beam(n_harmonics: int, every: int, full_hill: bool) -> dict:
    """One beam curve: solve and stability times per point, the check against the monodromy
    matrix at every ``every``-th point."""
    t0 = time.perf_counter()
    pb, br = load_example("cantilever_tip_contact").curve(stability=False, n_harmonics=n_harmonics)
    solve_s = (time.perf_counter() - t0) / len(br.points)
    times = []
    for p in br.points:
        t0 = time.perf_counter()
        floquet_exponents(pb, p)
        times.append(time.perf_counter() - t0)
    check = cross_check(pb, br.points[::every])
    out = {
        "points": len(br.points),
        "solve_s": solve_s,
        "stability_s": statistics.median(times),
        "check": check,
    }
    if full_hill:
        t0 = time.perf_counter()
        floquet_exponents(pb, br.points[len(br.points) // 2], method="hill_full")
        out["hill_full_s"] = time.perf_counter() - t0
    return out


def stability_figures(quick: bool = False) -> dict:
    """The stability part: the beam curves and the period-doubling curve."""
    checks = {}
    ratio, solve, full = {}, {}, {}
    for H in HARMONICS[:1] if quick else HARMONICS:
        b = _beam(H, 16 if quick else 1, not quick)
        ratio[str(H)] = round(b["stability_s"] / b["solve_s"], 3)
        solve[str(H)] = round(b["solve_s"], 5)
        if "hill_full_s" in b:
            full[str(H)] = round(b["hill_full_s"], 3)
        checks[f"beam H={H}"] = b["check"]
        print(
            f"beam H = {H}: {b['points']} points, solve {1e3 * b['solve_s']:.2f} ms/point, "
            f"stability {1e3 * b['stability_s']:.2f} ms/point (ratio {ratio[str(H)]})"
            + (f", Hill's matrix of the whole model {b['hill_full_s']:.2f} s" if full else "")
        )
    pb, br = load_example("impact_oscillator").curve(stability=False)
    checks["impact oscillator"] = cross_check(pb, br.points)
    for name, c in checks.items():
        print(
            f"  {name}: {c.n_points} points checked, verdicts differ at {len(c.disagree)}, "
            f"leading multiplier within {c.multiplier_rel_err:.2e}"
        )
    return {
        "hill_over_solve": ratio,
        "solve_s_per_point": solve,
        "hill_full_s": full or None,
        "stability_agrees": all(c.agrees for c in checks.values()),
        "stability_disagree": {k: len(c.disagree) for k, c in checks.items()},
        "stability_points_checked": {k: c.n_points for k, c in checks.items()},
        "leading_multiplier_rel_err_max": max(c.multiplier_rel_err for c in checks.values()),
    }


def sweep_figures(quick: bool = False) -> dict:
    from benchmarks.mhb import paper_sweep_s

    s = paper_sweep_s(repeats=1 if quick else 3)
    print(f"paper sweep: {s:.3f} s")
    return {"paper_sweep_s": round(s, 4)}


def sim_figures(quick: bool = False) -> dict:
    """``rig run paper`` per shipped truth, two at a time (none with ``quick``)."""
    if quick:
        return {"sim_paper_run_s": None, "sim_slowest_over_reference": None}
    from benchmarks.coverage import PARALLEL, paper_run_s
    from sim_backend.truth import list_truths

    def timed(truth: str, folder: Path) -> float | None:
        try:
            s = round(paper_run_s(truth, 1, folder / truth, SIM_TIMEOUT_S), 1)
        except (RuntimeError, subprocess.TimeoutExpired) as exc:
            print(f"  {truth}: {exc}", file=sys.stderr)
            return None
        print(f"  simulated paper run, {truth}: {s} s", flush=True)
        return s

    with tempfile.TemporaryDirectory() as tmp, cf.ThreadPoolExecutor(PARALLEL) as ex:
        runs = {t: ex.submit(timed, t, Path(tmp)) for t in list_truths()}
        secs = {t: f.result() for t, f in runs.items()}
    done = [s for s in secs.values() if s is not None]
    ref = secs.get("reference")
    worst = None if None in secs.values() else max(done)
    return {
        "sim_paper_run_s": secs,
        "sim_slowest_over_reference": round(worst / ref, 2) if worst and ref else None,
    }


def calibrate_figures(quick: bool = False) -> dict:
    """The calibration part of ``benchmarks calibrate`` (none with ``quick``) and the last
    recorded diagnosis benchmark's longest case."""
    out: dict = {"calibrate_total_s": None}
    if not quick:
        from benchmarks.calibrate import run as calibrate

        f = calibrate()
        out["calibrate_total_s"] = round(f["lhs_s"] + f["lm_s"] + f["cv_s"], 2)
        out["calibrate_n_starts"] = f["n_starts"]
    path = FOLDER / "diagnose.json"
    if path.exists():
        doc = json.loads(path.read_text())
        out["diagnosis_s_max"] = doc["figures"].get("max_diagnosis_s")
        out["diagnosis_code"] = doc.get("code")
    else:
        out["diagnosis_s_max"] = None
        out["diagnosis_code"] = None
    return out


_PART_FUNCTIONS = {
    "stability": stability_figures,
    "sweep": sweep_figures,
    "sim": sim_figures,
    "calibrate": calibrate_figures,
}


def run(quick: bool = False, parts: tuple[str, ...] = PARTS) -> dict:
    t_start = time.perf_counter()
    figures: dict = {"machine_ref_s": round(machine_ref_s(), 3)}
    print(f"machine reference workload: {figures['machine_ref_s']} s")
    for part in parts:
        figures.update(_PART_FUNCTIONS[part](quick))
    figures["machine_ref_s_end"] = round(machine_ref_s(), 3)
    figures["total_s"] = round(time.perf_counter() - t_start, 1)
    return figures


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog="python -m benchmarks.speed", description=__doc__)
    parser.add_argument("parts", nargs="+", choices=PARTS)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    print(json.dumps(run(args.quick, tuple(args.parts)), default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
