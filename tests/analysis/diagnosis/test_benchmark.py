"""The diagnosis benchmark's plan and its figures' form (the full run is the benchmark)."""

from __future__ import annotations

from fractions import Fraction

import pytest

from benchmarks.diagnose import (
    TRUE_EFFECTS,
    benchmark_plan,
    cache_dir,
    record_blocks,
)
from tests.analysis.diagnosis.conftest import truth_as_model


def test_the_plan_is_the_papers_with_the_force_held_clean() -> None:
    plan = benchmark_plan()
    ex = plan.excitation
    assert ex.orders == tuple(Fraction(k) for k in range(1, 9))
    assert ex.relative_amplitudes[:3] == (1.0, 0.02, 0.02)
    assert all(a == 0.0 for a in ex.relative_amplitudes[3:])
    assert ex.levels_n == (2.0, 4.0, 6.0, 8.0) and plan.points == (3, 6, 7)
    assert plan.acquisition.record_blocks == 48  # the paper plan's
    quick = benchmark_plan(quick=True)
    assert quick.excitation.levels_n == (2.0, 5.0, 8.0) and quick.name != plan.name


def test_every_hidden_effect_names_a_library_candidate(
    reference_model, tmp_path, monkeypatch
) -> None:
    from analysis.diagnosis import default_candidates

    cands = default_candidates(reference_model, scope="structure")
    # a truth's place is a candidate's own or one that moves as it (candidates.SAME_MOTION)
    places = {name: c.location for c in cands for name in (c.location.name, *c.location.moves_as)}
    labels = {
        (c.law.kind, name, c.law.options.get("side"))
        for c in cands
        for name in (c.location.name, *c.location.moves_as)
    }
    for truth, effect in TRUE_EFFECTS.items():
        assert effect in labels, truth
    # the names are the places the truths put their effects at
    for truth, (kind, where, _) in TRUE_EFFECTS.items():
        if where != places[where].name:
            continue  # folded into a place that moves as it: tested in test_candidates
        hidden = [s for s in truth_as_model(truth).nonlinear if s.name != "bump_stop"]
        placed = {
            (at.node, at.direction, to and (to.node, to.direction))
            for at, to in places[where].incidences
        }
        for spec in hidden:  # none for a mass
            to = spec.to and (spec.to.node, spec.to.direction)
            assert (spec.at.node, spec.at.direction, to) in placed, (truth, spec.name)
            assert spec.kind == kind, truth
    monkeypatch.setenv("CLEARANCE_RIG_CACHE", str(tmp_path))
    assert cache_dir() == tmp_path


def test_longer_records_are_a_setting(monkeypatch) -> None:
    monkeypatch.delenv("CLEARANCE_RIG_RECORD_BLOCKS", raising=False)
    assert record_blocks() is None
    monkeypatch.setenv("CLEARANCE_RIG_RECORD_BLOCKS", "192")
    assert record_blocks() == 192
    assert benchmark_plan(blocks=192).acquisition.record_blocks == 192
    monkeypatch.setenv("CLEARANCE_RIG_RECORD_BLOCKS", "many")
    with pytest.raises(ValueError, match="CLEARANCE_RIG_RECORD_BLOCKS.*'many'"):
        record_blocks()


def test_a_tie_is_settled_by_the_separating_run(tmp_path) -> None:
    from types import SimpleNamespace

    import numpy as np

    from analysis.diagnosis.result import DiagnosisSettings
    from analysis.measurement_file import read_measurement
    from benchmarks.diagnose import separate

    reference = truth_as_model("reference")
    softer = reference.with_values({"E_beam": 0.92 * reference.parameters["E_beam"].value})

    def tied(label, model):
        return SimpleNamespace(
            candidate=SimpleNamespace(label=label),
            verified=SimpleNamespace(model_toml=model.to_toml()),
        )

    diag = SimpleNamespace(
        group=[tied("softer beam", softer), tied("the truth", reference)],
        recommendation={
            "best": {
                "sensor": 5,
                "level_n": 2.0,
                "start_hz": 23.0,
                "stop_hz": 24.0,
                "step_hz": 1.0,
            },
            "candidates": ["softer beam", "the truth"],
        },
        settings=DiagnosisSettings(),
    )
    data = SimpleNamespace(
        orders=np.array([1, 2, 3]),
        force_targets=np.array([[2.0, 0.04, 0.04]]),
        channels=[SimpleNamespace(point=p) for p in (3, 6, 7)],
    )
    best, sep, seconds = separate("reference", diag, data, tmp_path)
    assert best.candidate.label == "the truth" and sep.resolved and seconds > 0
    # the plan the analysis wrote is the one the rig ran: point 5 recorded
    assert (tmp_path / "reference-separate.plan.toml").exists()
    (run,) = tmp_path.glob("reference-separate-*.h5")
    assert 5 in {ch.point for ch in read_measurement(run).channels}
    again = separate("reference", diag, data, tmp_path)
    assert again[2] == 0.0  # the separating run is cached like the others
