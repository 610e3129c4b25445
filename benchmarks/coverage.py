"""Do the calibration's stated intervals hold the truth? Many noise seeds, the user's workflow.

For noise seeds 1 to 8 of the simulated ``reference`` rig (and 3 seeds of ``mass_loading``, a
truth with an effect the model lacks), the rig's own commands make the random test and the
paper's stepped sine (``rig linear``, ``rig run paper``: made once and cached, keyed by the truth
file, the plans, the seed and the code that makes the data, :func:`make_runs`); then the
analysis part of ``rig workflow`` runs on them exactly as the workflow calls it
(:func:`rig.cli.workflow.analyse_runs`: linear calibration, planning, nonlinear calibration,
cross-validation, validation, report and summary). A run that fails counts as a miss.

Judged pairs: (seed, parameter) for k_c, gap, v_c and every linear parameter (a held one with
its prior interval), with the stated 95 % interval ``value +- 1.96 sigma`` of the reported
(widened) covariance. Figures (last JSON line): ``seeds``, ``gap_abs_rel_err_max``,
``kc_abs_rel_err_max``, ``v_abs_rel_err_max``, ``coverage_95``, ``z_abs_max``, ``z_rms``,
``gap_sigma_rel_median``, ``linear_held`` (per seed), ``undetermined_named``,
``misfit_flagged`` ({truth: [bool per seed]}), ``calibration_s_median``; per seed the details.
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.diagnose import FRONT_ENDS, _code_version, _key
from sim_backend.truth import TRUTH_DIR

ROOT = Path(__file__).resolve().parent.parent
REFERENCE_SEEDS = tuple(range(1, 9))
MISFIT_SEEDS = (1, 2, 3)
NONLINEAR = ("k_c", "gap", "v_c")
#: Two cases at a time: the machine has two cores and each case is mostly one process.
PARALLEL = 2


def cache_dir() -> Path:
    """Where the simulated runs are kept (``$CLEARANCE_RIG_CACHE/coverage``)."""
    base = os.environ.get("CLEARANCE_RIG_CACHE")
    return (Path(base) if base else Path.home() / ".cache" / "clearance-rig") / "coverage"


def _run_key(truth: str, seed: int) -> str:
    plans = [(ROOT / "rig" / "plans" / f"{n}.toml").read_text() for n in ("linear", "paper")]
    setup = (ROOT / "rig" / "setups" / "reference.toml").read_text()
    text = (TRUTH_DIR / f"{truth}.toml").read_text()
    return _key(text, *plans, setup, str(seed), _code_version(FRONT_ENDS))


def _rig(argv: list[str], log_file: Path, timeout: float | None = None) -> None:
    with log_file.open("a") as fh:
        r = subprocess.run(
            [sys.executable, "-m", "rig", *argv], stdout=fh, stderr=fh, cwd=ROOT, timeout=timeout
        )
    if r.returncode != 0:
        raise RuntimeError(f"rig {' '.join(argv[:2])} failed (exit {r.returncode}): see {log_file}")


def make_runs(truth: str, seed: int) -> tuple[Path, Path, float]:
    """``(linear.h5, paper.h5, seconds spent making them)`` of one case, from the cache when
    the same code made them before. Made with the rig's own commands, as a user would."""
    folder = cache_dir() / f"{truth}-{seed}-{_run_key(truth, seed)}"
    lin, paper = folder / "linear.h5", folder / "paper.h5"
    done = folder / "complete"
    if done.exists():
        return lin, paper, 0.0
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    t0 = time.perf_counter()
    common = sim_arguments(truth, seed, folder)
    _rig(["linear", "linear", "--out", str(lin), *common], folder / "rig.log")
    _rig(["run", "paper", "--out", str(paper), *common], folder / "rig.log")
    done.write_text("")
    return lin, paper, time.perf_counter() - t0


def sim_arguments(truth: str, seed: int, folder: Path) -> list[str]:
    """The rig command line's options for a quiet run of the simulated rig."""
    return [
        "--backend",
        "sim",
        "--truth",
        truth,
        "--seed",
        str(seed),
        "--quiet",
        "--overwrite",
        "--lock-dir",
        str(folder / "locks"),
    ]


def paper_run_s(truth: str, seed: int, folder: Path, timeout: float | None = None) -> float:
    """Wall time of ``rig run paper`` on the simulated rig of ``truth`` (written to
    ``folder``, never cached); ``subprocess.TimeoutExpired`` after ``timeout`` seconds."""
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    argv = ["run", "paper", "--out", str(folder / "paper.h5"), *sim_arguments(truth, seed, folder)]
    _rig(argv, folder / "rig.log", timeout)
    return time.perf_counter() - t0


def cases(quick: bool = False) -> list[tuple[str, int]]:
    """The (truth, seed) pairs of a run."""
    if quick:
        return [("reference", 1)]
    return [("reference", s) for s in REFERENCE_SEEDS] + [("mass_loading", s) for s in MISFIT_SEEDS]


def make_all(quick: bool = False) -> dict[tuple[str, int], tuple[Path, Path, float]]:
    """Every case's runs, two at a time."""
    with cf.ThreadPoolExecutor(PARALLEL) as ex:
        futures = {c: ex.submit(make_runs, *c) for c in cases(quick)}
        out = {}
        for c, f in futures.items():
            try:
                out[c] = f.result()
            except RuntimeError as exc:
                print(f"{c[0]} seed {c[1]}: {exc}", file=sys.stderr)
        return out


def _reference(truth: str, seed: int, path: Path) -> Path:
    """The truth's values as the workflow writes them (``rig reference``)."""
    _rig(
        [
            "reference",
            "--truth",
            truth,
            "--seed",
            str(seed),
            "--out",
            str(path),
            "--overwrite",
            "--json",
        ],
        path.with_suffix(".log"),
    )
    return path


def analyse(case: tuple[str, int], runs, folder: Path) -> dict:
    """The workflow's analysis of one case's runs; the figures of its summary."""
    from rig.cli.workflow import analyse_runs

    truth, seed = case
    out = folder / f"{truth}-{seed}"
    out.mkdir(parents=True, exist_ok=True)
    ref = _reference(truth, seed, out / "truth.json")
    lin, paper, _ = runs
    t0 = time.perf_counter()
    summary = analyse_runs(
        out,
        lin,
        paper,
        quiet=True,
        reference=ref,
        title=f"the {truth!r} simulated rig, seed {seed}",
    )
    held = list(summary["linear"].get("held", {}))
    text = (out / "summary.md").read_text()
    stages = {st["stage"]: st["seconds"] for st in summary["stages"]}
    return {
        "truth": truth,
        "seed": seed,
        "comparison": summary["comparison"],
        "held": held,
        "held_named": all(name in text for name in held),
        "misfit": summary["verdict"]["misfit"],
        "misfit_reasons": summary["verdict"]["reasons"],
        "chi2_per_dof": summary["calibration"]["chi2_per_dof"],
        "crossval_std_ratio": summary["crossval"].get("std_ratio"),
        "validation_passed": summary["validation"]["passed"],
        "calibration_s": stages.get("nonlinear calibration"),
        "analysis_s": time.perf_counter() - t0,
    }


def _figures(results: dict, failed: dict) -> dict:
    ref = [r for r in results.values() if r["truth"] == "reference"]
    n_failed_ref = sum(1 for c in failed if c[0] == "reference")
    pairs = [row for r in ref for row in r["comparison"].values()]
    n_judged = len(pairs) + n_failed_ref * (len(NONLINEAR) + 5)  # a failed run: all missed
    inside = sum(1 for row in pairs if row["inside_95"])
    z = np.array([row["z"] for row in pairs if row["z"] is not None], dtype=float)

    def err_max(name: str) -> float | None:
        if n_failed_ref:
            return None
        return max(abs(r["comparison"][name]["error_rel"]) for r in ref)

    gap_rel_sd = [r["comparison"]["gap"]["std"] / r["comparison"]["gap"]["value"] for r in ref]
    by_truth: dict[str, list[bool]] = {}
    for (t, _), r in sorted(results.items()):
        by_truth.setdefault(t, []).append(r["misfit"])
    cal_s = [r["calibration_s"] for r in ref if r["calibration_s"] is not None]
    return {
        "seeds": len(ref) + n_failed_ref,
        "failed": [f"{t} seed {s}: {why}" for (t, s), why in failed.items()],
        "gap_abs_rel_err_max": err_max("gap"),
        "kc_abs_rel_err_max": err_max("k_c"),
        "v_abs_rel_err_max": err_max("v_c"),
        "coverage_95": inside / n_judged if n_judged else None,
        "pairs": n_judged,
        "z_abs_max": float(np.max(np.abs(z))) if z.size else None,
        "z_rms": float(np.sqrt(np.mean(z**2))) if z.size else None,
        "gap_sigma_rel_median": float(np.median(gap_rel_sd)) if gap_rel_sd else None,
        "linear_held": {str(r["seed"]): r["held"] for r in ref},
        "undetermined_named": all(r["held_named"] for r in ref),
        "misfit_flagged": {t: by_truth.get(t, []) for t in ("mass_loading", "reference")},
        "calibration_s_median": float(np.median(cal_s)) if cal_s else None,
    }


def run(quick: bool = False) -> dict:
    t0 = time.perf_counter()
    made = make_all(quick)
    data_s = time.perf_counter() - t0
    failed = {c: "its runs could not be made" for c in cases(quick) if c not in made}
    results: dict[tuple[str, int], dict] = {}
    folder = cache_dir().parent / "coverage-analysis"
    shutil.rmtree(folder, ignore_errors=True)
    with cf.ThreadPoolExecutor(PARALLEL) as ex:
        futures = {c: ex.submit(analyse, c, runs, folder) for c, runs in made.items()}
        for c, f in futures.items():
            try:
                results[c] = f.result()
            except Exception as exc:  # a failed analysis counts as a miss
                failed[c] = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    for (t, s), r in sorted(results.items()):
        z = {k: row["z"] for k, row in r["comparison"].items()}
        print(
            f"{t} seed {s}: misfit {r['misfit']}, held {r['held']}, z "
            + ", ".join(f"{k} {v:+.2f}" for k, v in z.items() if v is not None)
        )
    figures = _figures(results, failed)
    figures["data_s"] = round(data_s, 1)
    figures["total_s"] = round(time.perf_counter() - t0, 1)
    figures["analysis_folder"] = str(folder)
    figures["details"] = {f"{t}-{s}": r for (t, s), r in sorted(results.items())}
    return figures


if __name__ == "__main__":
    made = make_all()
    print(json.dumps({f"{t}-{s}": round(v[2], 1) for (t, s), v in made.items()}))
