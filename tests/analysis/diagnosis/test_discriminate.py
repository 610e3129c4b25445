"""The measurement that separates tied candidates."""

from __future__ import annotations

from types import SimpleNamespace

from analysis.diagnosis.candidates import default_candidates
from analysis.diagnosis.discriminate import discriminate
from analysis.planning.candidates import FrequencyRange


def test_the_separating_sensor_and_band_are_found(runs, reference_model) -> None:
    data = runs("damper_p5")
    cands = {c.label: c for c in default_candidates(reference_model)}
    group = []
    for label, c2 in (("quadratic_damper at point 5", 6.0), ("quadratic_damper at point 6", 2.6)):
        model, _ = cands[label].apply(reference_model, {"c2": c2})
        group.append(
            SimpleNamespace(
                candidate=cands[label], verified=SimpleNamespace(model_toml=model.to_toml())
            )
        )
    out = discriminate(
        group,
        data,
        levels_n=(8.0,),
        ranges=(FrequencyRange(24.0, 28.0, 0.5), FrequencyRange(141, 160, 2.0)),
    )
    best = out["best"]
    assert best["power"] > 0 and best["sensor"] in reference_model.points
    assert out["table"][0] == best and "standard errors" in out["text"]
