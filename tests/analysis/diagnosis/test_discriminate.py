"""The measurement that separates tied candidates."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

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
    # the rig's loop check runs at a swept frequency where the plan's sensors respond
    swept = [24.0 + 0.5 * i for i in range(9)] + [141.0 + 2 * i for i in range(10)]
    assert min(abs(best["loop_check_hz"] - f) for f in swept) < 1e-9


def test_bands_around_the_modes_below_the_paper_ranges(reference_model) -> None:
    """Each mode of the structure below the ranges' top that no range holds gets a band of
    +-15 % around it (overlapping bands merged); modes inside a range get none."""
    from analysis.diagnosis.discriminate import MODE_BAND, mode_ranges
    from analysis.planning.candidates import PAPER_RANGES

    freqs, _ = reference_model.assemble().normal_modes()
    bands = mode_ranges(reference_model, PAPER_RANGES)
    below = [f for f in freqs if 0 < f < PAPER_RANGES[0].start_hz]
    assert below and bands
    for f in below:  # each uncovered mode inside a band, with room on both sides
        assert any(
            b.start_hz <= (1 - 0.9 * MODE_BAND) * f
            and f * (1 + 0.9 * MODE_BAND) <= b.stop_hz + 1e-9
            for b in bands
        ), f
    for a, b in zip(bands, bands[1:], strict=False):
        assert a.stop_hz < b.start_hz  # merged: no overlap
    assert mode_ranges(reference_model, (FrequencyRange(0.5, 200.0, 1.0),)) == []


def test_the_noise_is_the_files_per_sensor(runs) -> None:
    """Each accelerometer's floor is the median of the file's standard errors over sqrt(2) (per
    real part); a point the file does not measure gets the median of the file's sensors; a
    sensor made noisier in the file is noisier in the model, the others unchanged."""
    import dataclasses

    import numpy as np

    from analysis.diagnosis.discriminate import file_noise

    data = runs("damper_p5")
    noise = file_noise(data)
    acc = [c for c, ch in enumerate(data.channels) if ch.quantity == "acceleration"]
    assert acc and set(noise.sensor_floors) == {int(data.channels[c].point) for c in acc}
    for c in acc:
        expect = float(np.median(data.response_std[:, c, :])) / np.sqrt(2)
        assert noise.floor_at(int(data.channels[c].point)) == pytest.approx(expect, rel=1e-12)
    assert noise.floor == pytest.approx(float(np.median(list(noise.sensor_floors.values()))))
    assert noise.relative == 0.02  # the planning default's proportional part
    loud = acc[-1]
    std = data.response_std.copy()
    std[:, loud, :] *= 10.0
    louder = file_noise(dataclasses.replace(data, response_std=std))
    point = int(data.channels[loud].point)
    assert louder.floor_at(point) == pytest.approx(10 * noise.floor_at(point))
    for c in acc[:-1]:
        p = int(data.channels[c].point)
        assert louder.floor_at(p) == noise.floor_at(p)
    # a file without accelerometers: the planning default
    force_only = [dataclasses.replace(ch, quantity="force") for ch in data.channels]
    from analysis.planning.candidates import NoiseModel

    assert file_noise(dataclasses.replace(data, channels=tuple(force_only))) == NoiseModel()
