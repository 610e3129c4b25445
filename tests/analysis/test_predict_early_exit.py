"""A start whose prediction fails at a fitted step is scored ``inf`` without solving the rest,
and one whose cost provably exceeds the best known is stopped there.

The early exits (``stop_at_failure``, a :class:`~analysis.predict.CostBound`) must leave the
selected start and the calibrated values exactly as they were, every start cost the
calibration ranks by exact (the others lower bounds above the best), and solve fewer steps.
"""

import numpy as np
import pytest

import analysis.calibration.nonlinear as nonlinear
from analysis.calibration.lhs import Distribution, latin_hypercube, paper_distributions
from analysis.calibration.nonlinear import LHS_STAGE, CalibrationSettings, calibrate_nonlinear
from analysis.calibration.objective import FRFObjective
from analysis.calibration.parameters import ParameterSpace
from analysis.events import StageDone
from analysis.measurement_file import read_measurement
from analysis.mhb.sweep import solve_steps
from analysis.model import load_model
from analysis.predict import SteppedSinePredictor, sweeps_of
from analysis.predict_branches import MAX_SUBSTEP_DEPTH, _iter_steps

from .calibration.test_nonlinear import FREQS, LINEAR, TRUTH
from .synthetic_runs import write_synthetic_run

#: Starts that reach far stiffer contacts than the paper's distribution: on this file one in
#: eight has no solution at some fitted step (as the paper's do on the simulated rig).
DISTRIBUTIONS = {
    **paper_distributions(1e-3),
    "k_c": Distribution("uniform", 7e6, 3e7),
    "gap": Distribution("uniform", 0.3e-3, 1.8e-3),
}
SETTINGS = CalibrationSettings(n_starts=8, seed=1, distributions=DISTRIBUTIONS, max_iterations=8)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    path = tmp_path_factory.mktemp("early_exit") / "synthetic.h5"
    truth = load_model().with_values({**LINEAR, **TRUTH})
    write_synthetic_run(path, truth, frequencies_hz=FREQS, seed=3)
    return load_model().with_values(LINEAR), read_measurement(path)


def _calibrate(model, data, monkeypatch, early_exit: bool):
    """The calibration, and the steps its Latin hypercube stage solved."""
    made = []

    def keep(*args):
        made.append(make(*args))
        return made[-1]

    make = nonlinear.make_predictor
    with monkeypatch.context() as m:
        m.setattr(nonlinear, "make_predictor", keep)
        if not early_exit:  # every start scored in full, without stopping
            cost = FRFObjective.cost
            m.setattr(FRFObjective, "cost", lambda self, t: cost(self, t, stop_at_failure=False))

            def score_all(spec, thetas, keep, executor, local, on_done, first=None):
                costs = nonlinear.evaluate_costs(spec, thetas, executor, local, on_done)
                return costs, np.ones(len(costs), bool)

            m.setattr(nonlinear, "screen_costs", score_all)
        at_lhs = {}

        def seen(event) -> None:  # the steps solved when the starts are all scored
            if isinstance(event, StageDone):
                at_lhs.setdefault(event.stage, made[0].steps_solved)

        res = calibrate_nonlinear(model, data, SETTINGS, progress=seen)
    return res, at_lhs[LHS_STAGE]


@pytest.mark.slow
def test_early_exit_keeps_every_start_cost_and_the_calibration(run, monkeypatch):
    model, data = run
    new, steps_new = _calibrate(model, data, monkeypatch, early_exit=True)
    old, steps_old = _calibrate(model, data, monkeypatch, early_exit=False)
    assert np.isinf(old.start_costs).any() and np.isfinite(old.start_costs).any()
    assert old.start_exact.all()
    # where exact, the cost (inf where inf); elsewhere a lower bound of it above the best one
    ex = new.start_exact
    # the starts are scored on the lowest level first: a sum in two parts
    assert np.allclose(new.start_costs[ex], old.start_costs[ex], rtol=1e-12, atol=0.0)
    best = old.start_costs.min()
    assert np.all(new.start_costs[~ex] > best)
    assert np.all(new.start_costs[~ex] <= old.start_costs[~ex] * (1 + 1e-12))
    assert np.argmin(new.start_costs) == np.argmin(old.start_costs)
    assert new.lm.cost == old.lm.cost
    assert new.parameters == old.parameters
    assert steps_new < steps_old


@pytest.mark.slow
def test_plain_predictor_stops_at_the_first_failed_fitted_step(run):
    model, data = run
    space = ParameterSpace.from_model(model, SETTINGS.parameters)
    starts = latin_hypercube(DISTRIBUTIONS, SETTINGS.n_starts, SETTINGS.seed, space.names)
    lo, hi = space.theta_bounds()
    thetas = np.clip(space.to_theta(starts), lo, hi)
    obj = FRFObjective(SteppedSinePredictor(model, data), space)
    costs, steps = {}, {}
    for stop in (False, True):
        before = obj.predictor.steps_solved
        costs[stop] = np.array([obj.cost(t, stop_at_failure=stop) for t in thetas])
        steps[stop] = obj.predictor.steps_solved - before
    assert np.isinf(costs[False]).any()
    assert np.array_equal(costs[True], costs[False])
    assert steps[True] < steps[False]


def _paper_objective(model, data, space):
    pred = nonlinear.make_predictor(model, data, CalibrationSettings())
    return FRFObjective(pred, space)


@pytest.mark.slow
def test_a_hopeless_start_is_stopped_and_the_best_is_not(run):
    """A start whose steps already cost more than the best start's whole prediction is stopped
    with a lower bound between the two; the best start, bounded by a worse one, is computed
    to the end, bit for bit."""
    model, data = run
    space = ParameterSpace.from_model(model, SETTINGS.parameters)
    starts = latin_hypercube(paper_distributions(1e-3), 6, 0, space.names)
    lo, hi = space.theta_bounds()
    thetas = np.clip(space.to_theta(starts), lo, hi)
    full = _paper_objective(model, data, space)
    exact = []
    for t in thetas:
        before = full.predictor.steps_solved
        exact.append((full.cost(t), full.predictor.steps_solved - before))
    costs = np.array([c for c, _ in exact])
    assert np.isfinite(costs).sum() >= 2
    best, worst = int(np.argmin(costs)), int(np.argmax(np.where(np.isfinite(costs), costs, -1)))
    assert costs[worst] > 2 * costs[best]
    # a fresh predictor: no solution of the full runs above is reused
    obj = _paper_objective(model, data, space)
    before = obj.predictor.steps_solved
    floor, is_exact = obj.bounded_cost(thetas[worst], costs[best])
    steps = obj.predictor.steps_solved - before
    assert not is_exact
    assert costs[best] < floor <= costs[worst] * (1 + 1e-12)
    assert steps < exact[worst][1]
    value, is_exact = obj.bounded_cost(thetas[best], costs[worst])
    assert is_exact
    assert value == costs[best]


@pytest.mark.slow
def test_screening_keeps_the_best_starts_and_their_costs(run):
    """``screen_costs`` ranks the starts as ``evaluate_costs`` does where it matters: the
    ``keep`` best exactly, every other start bounded above the ``keep``-th best."""
    model, data = run
    space = ParameterSpace.from_model(model, SETTINGS.parameters)
    starts = latin_hypercube(paper_distributions(1e-3), 6, 1, space.names)
    lo, hi = space.theta_bounds()
    thetas = np.clip(space.to_theta(starts), lo, hi)
    obj = _paper_objective(model, data, space)
    spec = nonlinear.ObjectiveSpec(
        model.to_toml(), str(data.path), space.names, obj.mask, "uncertainty", None, 9, 128
    )
    ref = nonlinear.evaluate_costs(spec, thetas, local=obj)
    keep = 2
    kth = np.sort(ref)[keep - 1]
    top = np.argsort(ref)[:keep]
    lowest = data.levels_n[data.level_index] == data.levels_n.min()
    for first in (None, lowest):
        costs, exact = nonlinear.screen_costs(spec, thetas, keep, local=obj, first=first)
        assert not exact.all()  # some start was stopped
        assert exact[top].all()
        # bit for bit in one pass; in two, to the rounding of a sum taken in two parts
        rtol = 0.0 if first is None else 1e-12
        assert np.allclose(costs[exact], ref[exact], rtol=rtol, atol=0.0)
        assert np.all(costs[~exact] > kth)
        assert np.all(costs[~exact] <= ref[~exact] * (1 + 1e-12))
        assert np.array_equal(np.argsort(costs)[:keep], top)


def test_stepping_one_step_at_a_time_is_solve_steps(run):
    """The backward pass of an early-exit prediction steps with ``_iter_steps``: the same
    solutions as ``solve_steps``, failures, sub-steps and force homotopies included."""
    model, data = run
    pred = SteppedSinePredictor(model, data)
    # a stiff contact: some steps of the highest level fail
    pb = nonlinear.make_predictor(
        model.with_values({"k_c": 2.5e7, "gap": 0.4e-3, "v_c": 10.0}),
        data,
        CalibrationSettings(),
    ).problem(model.with_values({"k_c": 2.5e7, "gap": 0.4e-3, "v_c": 10.0}))
    sweep = sweeps_of(data)[-1]
    w = 2 * np.pi * data.frequency_hz[sweep][::-1]
    F = (pred._force_sign * pred.drive_force[sweep][:, :, None])[::-1]
    ref = solve_steps(pb, w, F, max_substep_depth=MAX_SUBSTEP_DEPTH).points
    ours = list(_iter_steps(pb, w, F, max_substep_depth=MAX_SUBSTEP_DEPTH))
    assert len(ours) == len(ref)
    assert not all(p.converged for p in ref)
    for a, b in zip(ours, ref, strict=True):
        assert a.converged == b.converged
        assert np.array_equal(a.X, b.X)


def test_a_failing_trial_step_is_stopped_and_the_fit_is_the_same(run):
    """Levenberg-Marquardt's trial steps priced by ``bounded_cost`` (a trial only has to beat
    the current cost): every iterate, cost and evaluation count the same bit for bit as with
    every trial solved in full, and fewer steps solved, from a start whose first trials fail."""
    from analysis.calibration.lm import least_squares_lm

    model, data = run
    space = ParameterSpace.from_model(model, SETTINGS.parameters)
    start = space.to_theta([{**TRUTH, "k_c": 3 * TRUTH["k_c"]}[n] for n in space.names])
    fits, solved = [], []
    for bounded in (False, True):
        obj = _paper_objective(model, data, space)
        before = obj.predictor.steps_solved
        fits.append(
            least_squares_lm(
                obj,
                start,
                bounds=space.theta_bounds(),
                max_iterations=6,
                trial_cost=obj.bounded_cost if bounded else None,
            )
        )
        solved.append(obj.predictor.steps_solved - before)
    full, bounded = fits
    assert [h["x"] for h in bounded.history] == [h["x"] for h in full.history]
    assert [h["cost"] for h in bounded.history] == [h["cost"] for h in full.history]
    assert bounded.nfev == full.nfev > len(full.history)  # some trial failed
    assert solved[1] < solved[0]
