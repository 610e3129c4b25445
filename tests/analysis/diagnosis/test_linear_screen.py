"""The linear screen on the linear random test: a hidden spring found by the test that sees it."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis.candidates import default_candidates
from analysis.diagnosis.linear_screen import linear_screen, local_stiffness
from benchmarks.diagnose import simulate_linear_test
from sim_backend.truth import TRUTH_DIR


def _truth_with_spring(folder, node: str, direction: str, k: float):
    """The reference truth with a hidden spring to ground (a cable, a support that touches)."""
    text = (TRUTH_DIR / "reference.toml").read_text()
    spring = (
        f'\n[[springs]]\nname = "hidden"\nnode = "{node}"\ndirection = "{direction}"\nk = {k!r}\n'
    )
    i = text.index("\n[truth]")
    path = folder / "truth_spring.toml"
    path.write_text(text[:i] + spring + text[i:])
    return path


def test_a_hidden_spring_is_named_by_the_linear_test(reference_model, tmp_path) -> None:
    """A spring to ground at point 5 of a fifth of the structure's stiffness there: the linear
    test's best candidate is that spring, its stiffness within 1 % (2 % noise on the FRFs),
    ahead of the spring at the neighbouring points and of a mass (a spring stiffens every
    mode, a mass softens them)."""
    cands = {
        c.label: c
        for c in default_candidates(reference_model)
        if c.law.kind in ("linear_spring", "mass")
    }
    five = cands["linear_spring at point 5"]
    k_true = 0.2 * local_stiffness(reference_model, five)
    path = _truth_with_spring(tmp_path, "p5", "y", k_true)
    run = simulate_linear_test(str(path), tmp_path / "linear.h5", seed=3)
    tried = [cands[f"linear_spring at point {p}"] for p in (4, 5, 6)] + [cands["mass at point 5"]]
    base, fits = linear_screen(reference_model, run, tried)
    best = fits[0]
    assert best.candidate == five
    assert best.values["k_linear_spring_point_5"] == pytest.approx(k_true, rel=0.01)
    assert best.cost < 0.05 * base.cost and best.delta_bic < -1000
    # every candidate's fit is its own: none equals the model's alone
    assert all(not np.isclose(f.cost, base.cost, rtol=1e-9) for f in fits)
