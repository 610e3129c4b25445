"""Predictions on the measured branch."""

from __future__ import annotations

import numpy as np
import pytest

from analysis import predict_branches
from analysis.diagnosis import BranchMatchedPredictor, compare
from analysis.measurement_file import Actuator, StepRecord, create_stepped_sine, read_measurement
from analysis.mhb.continuation import continue_branch
from analysis.mhb.solver import solve_point
from analysis.system import build_problem_dofs
from tests.analysis.synthetic_runs import channels


def test_the_true_model_fits_its_own_run_at_the_noise(runs, reference_model) -> None:
    data = runs("reference")
    cmp = compare(reference_model, data, predictor=BranchMatchedPredictor(reference_model, data))
    assert 0.7 < cmp.rms_over_noise < 1.3  # tolerance: noise of about 300 FRF values
    grid, levels = cmp.map_sensor_order_level()
    assert grid.shape == (3, 3, 3) and levels == [2.0, 5.0, 8.0]


def test_derivatives_are_those_of_the_chosen_solutions(runs, reference_model) -> None:
    data = runs("two_sided_stop")
    pred = BranchMatchedPredictor(reference_model, data)
    p0 = pred.predict(params=["gap"])
    h = 1e-8
    p1 = pred.predict({"gap": reference_model.parameters["gap"].value + h})
    ok = p0.converged & p1.converged
    fd = (p1.frf[ok] - p0.frf[ok]) / h
    err = np.abs(fd - p0.d_frf["gap"][ok]) / np.abs(fd).max()
    assert np.nanpercentile(err, 95) < 1e-2  # away from switches the derivative is exact


def test_the_same_model_at_the_same_steps_is_solved_once(runs, reference_model, monkeypatch):
    """A fit evaluates its accepted iterate once more for the derivatives: that second call
    reuses the solutions (the answer a fresh predictor gives, bit for bit); another value,
    other steps or another damping is solved anew."""
    import dataclasses

    data = runs("two_sided_stop")
    sweeps = []
    real = predict_branches.solve_steps
    monkeypatch.setattr(
        predict_branches, "solve_steps", lambda *a, **k: sweeps.append(1) or real(*a, **k)
    )
    pred = BranchMatchedPredictor(reference_model, data)
    gap = reference_model.parameters["gap"].value
    rows = np.arange(data.n_steps // 2)
    pred.predict({"gap": 1.1 * gap}, rows=rows)
    n = len(sweeps)
    assert n > 0
    again = pred.predict({"gap": 1.1 * gap}, ["gap"], rows=rows)
    assert len(sweeps) == n
    fresh = BranchMatchedPredictor(reference_model, data).predict(
        {"gap": 1.1 * gap}, ["gap"], rows=rows
    )
    np.testing.assert_array_equal(again.frf, fresh.frf)
    np.testing.assert_array_equal(again.d_frf["gap"], fresh.d_frf["gap"])
    for values, at in (({"gap": 1.2 * gap}, rows), ({"gap": 1.2 * gap}, rows[:-1])):
        k = len(sweeps)
        pred.predict(values, rows=at)
        assert len(sweeps) > k
    k = len(sweeps)
    damping = dataclasses.replace(reference_model.damping, default_zeta=0.02)
    pred.solve(pred.model.with_values({"gap": 1.2 * gap}).with_damping(damping), rows=rows[:-1])
    assert len(sweeps) > k


def _fold_run(path, model, force: np.ndarray) -> tuple[object, int]:
    """A noise-free up-sweep at constant ``force`` whose last step before the jump sits on the
    branch past the fold (where a voltage-driven rig can hold a force-driven model's unstable
    state). Returns the file's data and the position of that step."""
    chans = channels()
    masses = {ch.point: ch.mass_kg for ch in chans if ch.mass_kg}
    truth = model.add_masses(masses)
    asm = truth.assemble()
    pb = build_problem_dofs(truth, [asm.point_dof(3)], [asm.point_dof(c.point) for c in chans[1:]])
    F = force[:, None]
    # the reference: one continuation from well below the resonance, through the fold and on
    branch = continue_branch(pb, 2 * np.pi * 24.0, 2 * np.pi * 32.0, F)
    assert branch.folds, "the sweep must fold"
    om, fold = branch.omega, branch.folds[0]
    w_fold = om[fold]
    # upper branch, a point on the turned-back branch just below the fold, the lower branch
    picks = [(w, "upper") for w in np.linspace(om[0], w_fold - 2 * np.pi * 0.1, 9)]
    picks += [(w_fold - 2 * np.pi * 0.01, "past"), (w_fold + 2 * np.pi * 0.2, "lower")]
    points = []
    for w, part in picks:
        cross = np.flatnonzero(np.diff(np.sign(om - w)) != 0)
        i = cross[0] if part == "upper" else cross[1] if part == "past" else cross[-1]
        p = solve_point(pb, w, F, X0=branch.points[i + 1].X)
        assert p.converged
        points.append(p)
    writer = create_stepped_sine(
        path,
        channels=chans,
        actuator=Actuator(3, "y"),
        levels_n=[abs(force[0])],
        orders_num=[1, 2, 3],
        orders_den=[1, 1, 1],
        force_targets=[force],
        config={},
        setup={},
    )
    with writer:
        for j, ((w, _), p) in enumerate(zip(picks, points, strict=True)):
            acc = (-((w * np.arange(1, 4)) ** 2))[:, None] * p.outputs()
            resp = np.concatenate([force[None, :], acc.T])
            std = 1e-6 * np.abs(resp[:, :1]) * np.ones(3)
            writer.append_step(
                StepRecord(
                    j,
                    0,
                    1,
                    w / (2 * np.pi),
                    w / (2 * np.pi),
                    force,
                    std[0],
                    resp,
                    std,
                    0.1 * force,
                    8,
                    1,
                    True,
                    0.0,
                )
            )
        writer.finish("success")
    return read_measurement(path), len(picks) - 2


@pytest.mark.slow
def test_a_step_held_past_the_fold_is_predicted_on_the_turned_back_branch(
    tmp_path, reference_model, monkeypatch
) -> None:
    data, past = _fold_run(tmp_path / "fold.h5", reference_model, np.array([4.0, 0.08, 0.08]))
    misses, default = {}, predict_branches.FOLD_STEPS
    for steps in (default, 0):  # 0: without the search past the fold
        monkeypatch.setattr(predict_branches, "FOLD_STEPS", steps)
        pred = BranchMatchedPredictor(reference_model, data)
        H, _ = pred.measured()
        frf = pred.predict().frf
        misses[steps] = np.abs(frf - H).max(axis=(1, 2)) / np.abs(H[:, :, 0]).max(axis=1)
    with_search, without = misses[default], misses[0]
    # same model, same balance: every step is reproduced to the Newton tolerance
    assert with_search.max() < 1e-6, with_search
    # the forward continuation alone stays on the stable branch there and misses by per cents
    assert without[past] > 1e-2, without
    assert np.delete(without, past).max() < 1e-6, without
