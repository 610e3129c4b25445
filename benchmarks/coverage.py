"""Do the calibration's stated intervals hold the truth? Many noise seeds, the user's workflow.

For noise seeds 1 to 8 of the simulated ``reference`` rig (and 3 seeds of ``mass_loading``, a
truth with an effect the model lacks), the rig's own commands make the random test and the
paper's stepped sine (``rig linear``, ``rig run paper``: made once and cached, keyed by the truth
file, the plans, the seed and the code that makes the data, :func:`make_runs`); then the
analysis part of ``rig workflow`` runs on them exactly as the workflow calls it
(:func:`rig.workflow.analyse_runs`: linear calibration, planning, nonlinear calibration,
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


def _rig(argv: list[str], log_file: Path) -> None:
    with log_file.open("a") as fh:
        r = subprocess.run([sys.executable, "-m", "rig", *argv], stdout=fh, stderr=fh, cwd=ROOT)
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
    common = ["--backend", "sim", "--truth", truth, "--seed", str(seed), "--quiet",
              "--overwrite", "--lock-dir", str(folder / "locks")]  # fmt: skip
    _rig(["linear", "linear", "--out", str(lin), *common], folder / "rig.log")
    _rig(["run", "paper", "--out", str(paper), *common], folder / "rig.log")
    done.write_text("")
    return lin, paper, time.perf_counter() - t0


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


if __name__ == "__main__":
    made = make_all()
    print(json.dumps({f"{t}-{s}": round(v[2], 1) for (t, s), v in made.items()}))
