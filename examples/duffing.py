"""Duffing oscillator (duffing.toml): the frequency-response curve through its two folds.

    python examples/duffing.py [OUTPUT_FOLDER]

writes duffing.csv (the curve: frequency, stability, amplitude and phase), duffing.located.csv
(the two folds and the peak, located to the solver's tolerance) and duffing.png.
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
FORCE_N = 0.1
RANGE_RAD_S = (0.5, 2.0)


def curve(values: dict | None = None, force: float = FORCE_N, n_harmonics: int = 5):
    """The continued branch and its problem (``values`` overrides model parameters)."""
    model = load_model(HERE / "duffing.toml")
    model = model.with_values(values) if values else model
    dof = model.assemble().point_dof(1)
    # a cubic spring needs N >= 4 H + 1 samples for an exact balance of its harmonics
    pb = build_problem_dofs(
        model, [dof], [dof], orders=[1], n_harmonics=n_harmonics, n_time=8 * n_harmonics + 8
    )
    settings = ContinuationSettings(max_angle=0.1)
    return pb, continue_branch(pb, *RANGE_RAD_S, np.array([force]), settings)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0] if argv else "duffing-output")
    pb, branch = curve()
    saved = save_curve(
        branch,
        pb,
        ["mass/x"],
        out / "duffing.csv",
        out / "duffing.png",
        "rad/s",
        title=f"Duffing oscillator, F = {FORCE_N} N",
    )
    for r in saved["located"]:
        print(f"{r['kind']:5s} at {r['omega_rad_s']:.8f} rad/s, amplitude {r['amplitude_m']:.6g} m")
    print("wrote", ", ".join(saved["files"] + [saved["figure"]]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
