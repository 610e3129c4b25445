"""2-DOF chain with a unilateral Hertz contact (two_dof_hertz.toml): the first resonance
bent over by the stop, through its folds.

    python examples/two_dof_hertz.py [OUTPUT_FOLDER]

writes two_dof_hertz.csv, two_dof_hertz.located.csv and two_dof_hertz.png.
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
FORCE_N = (30.0, 0.0, 0.0)  # at orders 1, 2, 3 (the higher orders kept for their responses)
RANGE_HZ = (15.0, 35.0)


def curve(values: dict | None = None):
    """The continued branch and its problem (``values`` overrides model parameters)."""
    model = load_model(HERE / "two_dof_hertz.toml")
    model = model.with_values(values) if values else model
    asm = model.assemble()
    # the contact's stiffness and its jumps need many harmonics and samples
    pb = build_problem_dofs(
        model,
        [asm.point_dof(1)],
        [asm.point_dof(1), asm.point_dof(2)],
        orders=[1, 2, 3],
        n_harmonics=12,
        n_time=512,
    )
    w0, w1 = (2 * np.pi * f for f in RANGE_HZ)
    settings = ContinuationSettings(max_angle=0.1)
    return pb, continue_branch(pb, w0, w1, np.array(FORCE_N, dtype=complex), settings)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0] if argv else "two_dof_hertz-output")
    pb, branch = curve()
    saved = save_curve(
        branch,
        pb,
        ["m1/x", "m2/x"],
        out / "two_dof_hertz.csv",
        out / "two_dof_hertz.png",
        title=f"2-DOF chain with a Hertz stop, F = {FORCE_N[0]} N",
    )
    for r in saved["located"]:
        print(
            f"{r['kind']:5s} at {r['frequency_hz']:.6f} Hz (output {r['output']}), "
            f"amplitude {r['amplitude_m']:.6g} m"
        )
    print("wrote", ", ".join(saved["files"] + [saved["figure"]]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
