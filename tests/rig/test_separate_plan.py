"""The analysis writes a tie's separating measurement as a plan file; the rig reads it."""

from __future__ import annotations

from fractions import Fraction
from types import SimpleNamespace

import numpy as np
import pytest

from analysis.diagnosis.discriminate import discriminate
from analysis.diagnosis.separate import write_separating_plan
from analysis.measurement_file import read_measurement
from analysis.model import Model
from analysis.planning.candidates import FrequencyRange, NoiseModel
from rig.config.plans import SteppedSinePlan, load_plan
from rig.config.setup import load_setup
from rig.run.session import TestRun, open_rig


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
        "loop_check_hz": 150.0,
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
    # the loop check where the sensors respond, not at the range's first step
    assert plan.pretest.loop_check_frequency_hz == 150.0


def test_a_fractional_order_is_written_as_the_plan_format_spells_it(tmp_path) -> None:
    data = _data(orders=(Fraction(1, 2), 1), ratios=(0.1, 1.0))
    plan = load_plan(write_separating_plan(tmp_path / "half.toml", RECOMMENDATION, data))
    assert plan.excitation.orders == (Fraction(1, 2), Fraction(1))


def test_a_recommendation_without_a_range_is_refused(tmp_path) -> None:
    bad = {"best": {"sensor": 2, "level_n": 6.0}}
    with pytest.raises(ValueError, match="lacks start_hz, stop_hz, step_hz"):
        write_separating_plan(tmp_path / "x.toml", bad, _data())


def _damper_at(point: int, c2: float):
    """The rig's own model with the quadratic damper of truth damper_p4 moved to ``point``."""
    from tests.analysis.diagnosis.conftest import truth_as_model

    text = truth_as_model("damper_p4").to_toml()
    model = Model.from_toml_text(text.replace("point = 4 }", f"point = {point} }}"), "<moved>")
    return model.with_values({"c2_p4": c2})


@pytest.mark.slow
def test_the_separating_level_is_one_the_simulated_rig_can_drive(tmp_path) -> None:
    """At the beam's second bending mode (152 Hz) the drive point moves so much that 6 N needs
    about 5 A of coil current, the simulated amplifier's limit: the discrimination must pick a
    level the amplifier can give, and the rig must then run the plan to the end."""
    setup = load_setup("reference")
    group = [
        SimpleNamespace(
            candidate=SimpleNamespace(label=f"quadratic_damper at point {p}"),
            verified=SimpleNamespace(model_toml=_damper_at(p, c2).to_toml()),
        )
        for p, c2 in ((4, 10.0), (5, 3.45))
    ]
    data = SimpleNamespace(
        levels_n=np.array([4.0, 6.0]),
        orders=np.array([1, 2, 3], dtype=object),
        force_targets=np.array([[4.0, 0.08, 0.08], [6.0, 0.12, 0.12]]),
        actuator=SimpleNamespace(point=3),
        channels=[
            SimpleNamespace(point=c.point, mass_kg=c.mass_kg)
            for c in setup.channels
            if c.name in ("force3", "acc3", "acc6", "acc7")
        ],
        setup=setup.to_dict(),
    )
    band = FrequencyRange(151.0, 153.0, 1.0)  # the resonance's peak, in three steps
    # the file's fields the drive's current needs (no standard errors: the planning noise)
    rec = discriminate(group, data, ranges=(band,), noise=NoiseModel())
    best = rec["best"]
    assert best["level_n"] == 4.0
    # (F + m a) / Bl at 4 N: about 3.3 A of the 5 A limit (within 15 %)
    assert best["current_a"] == pytest.approx(3.3, rel=0.15)
    assert rec["excluded"] and rec["excluded"][0]["level_n"] == 6.0
    assert rec["excluded"][0]["current_a"] > 0.8 * setup.amplifier.current_limit_a
    plan = load_plan(write_separating_plan(tmp_path / "separate.toml", rec, data))
    out = tmp_path / "separate.h5"
    options = {"truth": "damper_p4", "seed": 3, "sensor_masses_kg": setup.sensor_masses_kg()}
    with open_rig("sim", setup, backend_options=options, lock_dir=tmp_path / "locks") as rig:
        TestRun(rig.backend, plan, setup, out, amplifier=rig.amplifier).execute()
    run = read_measurement(out)
    assert run.exit_status == "success", run.exit_message
    assert run.n_steps == 3


@pytest.mark.slow
def test_a_level_the_amplifier_cannot_give_stops_with_its_cause_and_keeps_the_steps(
    tmp_path,
) -> None:
    """7 N toward the second bending mode: about 4.3 A at 150.6 Hz, 5.8 A at 152.4 Hz, over
    the simulated amplifier's 5 A: it trips, and the rig says why and keeps the step before."""
    setup = load_setup("reference")
    rec = {"best": {"sensor": 2, "level_n": 7.0, "start_hz": 150.0, "stop_hz": 152.0}}
    rec["best"]["step_hz"] = 1.0
    plan = load_plan(write_separating_plan(tmp_path / "too-high.toml", rec, _data()))
    out = tmp_path / "too-high.h5"
    options = {"truth": "damper_p4", "seed": 3, "sensor_masses_kg": setup.sensor_masses_kg()}
    with open_rig("sim", setup, backend_options=options, lock_dir=tmp_path / "locks") as rig:
        TestRun(rig.backend, plan, setup, out, amplifier=rig.amplifier).execute()
    run = read_measurement(out)
    assert run.exit_status == "aborted"
    assert "no force at the drive point" in run.exit_message
    assert "most likely its overload protection tripped" in run.exit_message
    assert "of the amplifier's 5 A limit" in run.exit_message
    assert run.n_steps >= 1  # the steps before the trip are on disk
