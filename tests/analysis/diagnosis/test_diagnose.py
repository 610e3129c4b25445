"""Diagnosis end to end on reduced runs: nothing claimed at the noise, hidden effects found
and added, an effect outside the library reported unexplained."""

from __future__ import annotations

import pytest

from analysis.diagnosis import DiagnosisSettings, augment, default_candidates, diagnose

QUICK = DiagnosisSettings(n_verify=2, n_refine=4, n_starts=0, workers=2, verify_iterations=8)


def _subset(model, locations, kinds):
    return [c for c in default_candidates(model)
            if c.location.name in locations and c.law.kind in kinds]  # fmt: skip


def test_the_true_model_is_adequate_and_nothing_is_claimed(runs, reference_model) -> None:
    result = diagnose(reference_model, runs("reference"), settings=QUICK)
    assert result.verdict == "adequate"
    assert result.ranking == [] and result.best is None
    assert "nothing is claimed" in result.summary()
    assert result.to_json()["verdict"] == "adequate"


@pytest.mark.slow
def test_a_hidden_damper_is_found_added_and_the_error_falls(runs, reference_model, tmp_path):
    data = runs("damper_p5")
    cands = _subset(reference_model, ("point 5", "point 6", "point 7"),
                    ("quadratic_damper", "linear_damper", "cubic_spring"))  # fmt: skip
    result = diagnose(reference_model, data, candidates=cands, settings=QUICK)
    assert result.verdict == "explained", result.summary()
    best = result.group[0]
    assert best.candidate.law.kind == "quadratic_damper" and not best.candidate.is_linear
    added = augment(
        reference_model,
        data,
        best.candidate,
        values=best.screen.values,
        known=best.screen.known,
        n_starts=0,
        out=tmp_path / "augmented.toml",
    )
    assert added.residual_drop >= 5.0 and added.after.rms_over_noise <= 1.5, added.summary()
    assert (tmp_path / "augmented.toml").exists()
    assert [h["stage"] for h in added.history][-1] == "lm"
    assert added.history[-1]["chi2_per_dof"] < added.history[0]["chi2_per_dof"]


@pytest.mark.slow
def test_an_effect_outside_the_library_is_reported_unexplained(runs, reference_model) -> None:
    data = runs("hysteretic_joint")
    cands = _subset(
        reference_model,
        ("joint clamp rz", "point 7"),
        ("coulomb_friction", "joint_spring", "cubic_spring", "linear_damper"),
    )
    result = diagnose(reference_model, data, candidates=cands, settings=QUICK)
    assert result.verdict == "unexplained", result.summary()
    assert result.best is None
    assert "nothing in the element library explains" in result.summary()
