"""Oscillator against a stop (impact_oscillator.toml): a curve that crosses two
period-doubling points, with the stability of every point.

    python examples/impact_oscillator.py [OUTPUT_FOLDER]

writes impact_oscillator.csv (frequency, stability, amplitude and phase) and
impact_oscillator.png, and prints the frequencies where the period-1 orbit loses and regains
stability.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from analysis.continuation_cli import save_curve
from analysis.mhb.continuation import ContinuationSettings, continue_branch
from analysis.model import load_model
from analysis.system import build_problem_dofs

HERE = Path(__file__).resolve().parent
FORCE_N = 0.9
RANGE_RAD_S = (3.0, 1.6)


def curve(n_harmonics: int = 15, stability: bool = True):
    """The continued branch (downwards in frequency) and its problem."""
    model = load_model(HERE / "impact_oscillator.toml")
    dof = model.assemble().point_dof(1)
    pb = build_problem_dofs(model, [dof], [dof], orders=[1], n_harmonics=n_harmonics, n_time=256)
    settings = ContinuationSettings(ds=0.05, ds_max=0.2, stability=stability)
    return pb, continue_branch(pb, *RANGE_RAD_S, np.array([FORCE_N]), settings)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0] if argv else "impact_oscillator-output")
    pb, branch = curve()
    saved = save_curve(
        branch,
        pb,
        ["mass/x"],
        out / "impact_oscillator.csv",
        out / "impact_oscillator.png",
        "rad/s",
        title=f"Impact oscillator, F = {FORCE_N} N",
    )
    changes = np.flatnonzero(np.diff(branch.stable.astype(int)))
    for i in changes:
        lost = bool(branch.stable[i])
        w = 0.5 * (branch.omega[i] + branch.omega[i + 1])
        print(f"stability {'lost' if lost else 'regained'} near {w:.3f} rad/s")
    print("wrote", ", ".join(saved["files"] + [saved["figure"]]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
