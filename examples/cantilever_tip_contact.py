"""Cantilever with a tip contact (cantilever_tip_contact.toml, 8 beam elements): the first
bending resonance hardened by the stop, through its folds.

    python examples/cantilever_tip_contact.py [OUTPUT_FOLDER]

writes cantilever_tip_contact.csv, .located.csv and .png.
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
FORCE_N = 0.3  # at the tip, order 1
RANGE_HZ = (30.0, 60.0)


def curve(
    values: dict | None = None,
    force: float = FORCE_N,
    range_hz=RANGE_HZ,
    stability: bool = True,
    n_harmonics: int = 9,
):
    """The continued branch and its problem (``values`` overrides model parameters)."""
    model = load_model(HERE / "cantilever_tip_contact.toml")
    model = model.with_values(values) if values else model
    tip = model.assemble().point_dof(1)
    # 512 samples: at 128 the Hertz law's onset between samples puts small wiggles, with a
    # pair of extra folds, near the upper fold
    pb = build_problem_dofs(model, [tip], [tip], orders=[1], n_harmonics=n_harmonics, n_time=512)
    w0, w1 = (2 * np.pi * f for f in range_hz)
    settings = ContinuationSettings(max_angle=0.1, stability=stability)
    return pb, continue_branch(pb, w0, w1, np.array([force], dtype=complex), settings)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0] if argv else "cantilever_tip_contact-output")
    pb, branch = curve()
    name = "cantilever_tip_contact"
    saved = save_curve(
        branch,
        pb,
        ["tip/y"],
        out / f"{name}.csv",
        out / f"{name}.png",
        title=f"Cantilever with a tip contact, F = {FORCE_N} N at the tip",
    )
    for r in saved["located"]:
        print(f"{r['kind']:5s} at {r['frequency_hz']:.6f} Hz, amplitude {r['amplitude_m']:.6g} m")
    print("wrote", ", ".join(saved["files"] + [saved["figure"]]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
