"""Candidate sets, frequency plans and the noise model: counts and validation messages."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.planning import (
    Candidates,
    Configuration,
    FrequencyRange,
    NoiseModel,
    paper_candidates,
    quick_candidates,
)


def test_paper_candidates_give_the_papers_14700_configurations():
    cand = paper_candidates()
    assert cand.n_configurations == 14700
    assert [r.label for r in cand.ranges] == [
        "[21-40]",
        "[41-60]",
        "[61-80]",
        "[81-100]",
        "[101-120]",
        "[121-140]",
        "[141-160]",
    ]
    np.testing.assert_allclose(cand.force(4.0), [4.0, 0.08, 0.08])
    assert quick_candidates().n_configurations == 35 * 3 * 3 * 2


def test_frequency_plan_and_refinement():
    coarse = FrequencyRange(21.0, 40.0, 1.0)
    f = coarse.frequencies_hz()
    assert f.size == 20 and f[0] == 21.0 and f[-1] == 40.0
    fine = coarse.refined((24.0, 28.0), 0.1)
    g = fine.frequencies_hz()
    # 20 coarse steps + 41 fine ones, of which 24..28 coincide: the paper's 56 steps
    assert g.size == 56
    assert np.all(np.diff(g) > 0)
    assert set(np.round(f, 6)) <= set(g)
    assert fine.label == "[21-40] + 0.1 Hz in 24-28"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"sensors": (1, 1, 2)}, "Candidates.sensors: duplicate"),
        ({"n_sensors": 8}, "Candidates.n_sensors"),
        ({"levels_n": (1.0, -2.0)}, "Candidates.levels_n: must be > 0"),
        ({"ranges": ()}, "Candidates.ranges"),
        ({"side_harmonic_ratio": -0.1}, "Candidates.side_harmonic_ratio"),
        ({"parameters": ("k_c", "k_c")}, "Candidates.parameters"),
    ],
)
def test_candidates_name_the_bad_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Candidates(**kwargs)


def test_noise_model_validation_and_floors():
    n = NoiseModel(sensor_floors={7: 0.05})
    assert n.floor_at(7) == 0.05 and n.floor_at(3) == 0.01 and n.unit == "m/s^2"
    assert NoiseModel.uniform_frf(2.0).floor == 2.0
    with pytest.raises(ValueError, match="NoiseModel.floor"):
        NoiseModel(floor=0.0)
    with pytest.raises(ValueError, match="NoiseModel.quantity"):
        NoiseModel(quantity="velocity")
    with pytest.raises(ValueError, match="FrequencyRange.stop_hz"):
        FrequencyRange(40.0, 21.0)
    with pytest.raises(ValueError, match="Configuration.levels_n"):
        Configuration(3, (3, 6, 7), (), FrequencyRange(21.0, 40.0))
