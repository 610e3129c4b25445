"""Signature tests read the physics from the data."""

from __future__ import annotations

from analysis.diagnosis import BranchMatchedPredictor, compare, find_signatures
from analysis.diagnosis.diagnose import _linear_steps


def _evidence(model, data):
    pred = BranchMatchedPredictor(model, data)
    cmp = compare(model, data, predictor=pred)
    _, s = pred.measured()
    return find_signatures(cmp, data, s, _linear_steps(pred))


def test_a_second_stop_shows_as_a_resonance_moving_up(runs, reference_model) -> None:
    ev = _evidence(reference_model, runs("two_sided_stop"))
    shift = next(f for f in ev.findings if f.name == "resonance_shift")
    assert shift.significant and "upwards" in shift.text
    assert "hardening" in ev.families


def test_the_true_model_shows_nothing(runs, reference_model) -> None:
    ev = _evidence(reference_model, runs("reference"))
    assert not [f.name for f in ev.findings if f.significant]
    assert ev.families == ()
    assert "evidence in the data" in ev.summary()
