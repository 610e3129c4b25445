"""The analysis writes a tie's separating measurement as a plan file; the rig reads it."""

from __future__ import annotations

from fractions import Fraction
from types import SimpleNamespace

import numpy as np
import pytest

from analysis.diagnosis.separate import write_separating_plan
from rig.config.plans import SteppedSinePlan, load_plan


def _data(orders=(1, 2, 3), ratios=(1.0, 0.02, 0.02j)):
    # the three fields the plan is made from: the drive's orders and ratios, the sensors
    return SimpleNamespace(
        orders=np.array(orders, dtype=object),
        force_targets=np.array([[2.0 * r for r in ratios]]),
        channels=[SimpleNamespace(point=p) for p in (3, 6, 7)],
    )


RECOMMENDATION = {
    "best": {
        "sensor": 2,
        "level_n": 6.0,
        "range": "141-160",
        "start_hz": 141.0,
        "stop_hz": 160.0,
        "step_hz": 1.0,
        "power": 15.4,
    },
    "candidates": ["quadratic_damper at point 4", "quadratic_damper at point 5"],
}


def test_the_rigs_reader_accepts_the_separating_plan(tmp_path) -> None:
    path = write_separating_plan(tmp_path / "separate.toml", RECOMMENDATION, _data())
    plan = load_plan(path)
    assert isinstance(plan, SteppedSinePlan)
    assert plan.name == "separate"
    assert plan.points == (2, 3, 6, 7)  # the file's sensors and the proposed one
    ex = plan.excitation
    assert ex.levels_n == (6.0,)
    assert ex.orders == (Fraction(1), Fraction(2), Fraction(3))
    assert ex.relative_amplitudes == pytest.approx((1.0, 0.02, 0.02))
    assert ex.phases_deg == pytest.approx((0.0, 0.0, 90.0))
    (rng,) = plan.frequencies.ranges
    assert (rng.start_hz, rng.stop_hz, rng.step_hz) == (141.0, 160.0, 1.0)
    assert "quadratic_damper at point 4" in plan.description


def test_a_fractional_order_is_written_as_the_plan_format_spells_it(tmp_path) -> None:
    data = _data(orders=(Fraction(1, 2), 1), ratios=(0.1, 1.0))
    plan = load_plan(write_separating_plan(tmp_path / "half.toml", RECOMMENDATION, data))
    assert plan.excitation.orders == (Fraction(1, 2), Fraction(1))


def test_a_recommendation_without_a_range_is_refused(tmp_path) -> None:
    bad = {"best": {"sensor": 2, "level_n": 6.0}}
    with pytest.raises(ValueError, match="lacks start_hz, stop_hz, step_hz"):
        write_separating_plan(tmp_path / "x.toml", bad, _data())
