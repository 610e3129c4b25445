"""Recalibration on the measured branch: several starts, then Levenberg-Marquardt.

The calibration machinery of :mod:`analysis.calibration` (parameter scaling, the uncertainty-
weighted FRF metric, bounded LM) on a :class:`~analysis.predict_branches.BranchMatchedPredictor`,
so a step the test measured on the other branch of a jump does not dominate the metric. Used to
calibrate a base model the paper's way (Latin hypercube starts) and to recalibrate every
candidate model of a diagnosis (given starts: the screen's estimate and the current values).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from analysis.calibration.lhs import Distribution, latin_hypercube
from analysis.calibration.lm import OUT_OF_EVALUATIONS, LeastSquaresResult, least_squares_lm
from analysis.calibration.modal_damping import ZETA, DampedPredictor, damped_space
from analysis.calibration.nonlinear import bounded_costs
from analysis.calibration.objective import FRFObjective
from analysis.events import Listener, UnitDone, iterations
from analysis.measurement_file import SteppedSineData
from analysis.model import Model
from analysis.predict_branches import BranchMatchedPredictor

__all__ = ["FitLimits", "Refit", "Starts", "refit"]

log = logging.getLogger(__name__)


@dataclass
class Refit:
    """Result of :func:`refit`.

    Attributes
    ----------
    model : Model
        The input model at the fitted values.
    parameters : dict name -> float
    std : dict name -> float
        From ``(J^T J)^-1`` of the uncertainty-weighted metric.
    chi2_per_dof : float
        ``2 cost / (m - n)`` over the fitted steps.
    n_residuals : int
        Real residuals ``m`` (two per complex FRF value).
    history : list of dict
        Per accepted LM iteration of the best start: ``iteration``, ``chi2_per_dof``,
        ``parameters``.
    start_costs : list of float
        Metric of every start tried (``inf`` where the model did not converge; a lower bound
        above the best's where a start was stopped once it could not be the best).
    lm : LeastSquaresResult
    seconds : float
    evaluations : int
        Evaluations of the objective (the balance on every fitted step, with or without its
        Jacobian): the start model's, the starts' and Levenberg-Marquardt's, over every pass.
        The work the fit did, the same however busy the machine is.
    """

    model: Model
    parameters: dict[str, float]
    std: dict[str, float]
    chi2_per_dof: float
    n_residuals: int
    history: list[dict] = field(default_factory=list)
    start_costs: list[float] = field(default_factory=list)
    lm: LeastSquaresResult | None = None
    seconds: float = 0.0
    evaluations: int = 0


@dataclass(frozen=True)
class Starts:
    """Where a :func:`refit` starts: always the model's own values, then ``given`` values, then
    ``n_random`` Latin hypercube points from ``distributions`` (the paper's method); the
    ``n_lm`` best of them by the metric are refined by Levenberg-Marquardt.

    Attributes
    ----------
    given : sequence of mapping
        Further start values (missing names keep the model's value).
    distributions : mapping name -> Distribution, optional
        Where the Latin hypercube draws each parameter.
    n_random : int
    n_lm : int
    seed : int
        The Latin hypercube's seed.
    """

    given: Sequence[Mapping[str, float]] = ()
    distributions: Mapping[str, Distribution] | None = None
    n_random: int = 0
    n_lm: int = 1
    seed: int = 0


@dataclass(frozen=True)
class FitLimits:
    """When a :func:`refit`'s Levenberg-Marquardt stops besides its own criteria.

    Every limit counts work (iterations, evaluations of the objective), never time, so the
    same fit gives the same answer however busy the machine is.

    Attributes
    ----------
    max_iterations : int
    ftol : float
        Stop when an iteration lowers the metric by less than this fraction.
    max_evaluations : int or None
        Evaluations of the objective (the balance on every fitted step, with or without its
        Jacobian) allowed to Levenberg-Marquardt over all its starts: it stops before the
        first evaluation past them and returns the last accepted iterate.
    give_up_chi2 : float or None
        Stop (keeping the last iterate) when the last iteration lowered the chi-square per
        degree of freedom by less than half and it is still above this two or more iterations
        in, or above twice this after the first: a candidate that does no better than the
        model without it.
    reweight_passes : int
        Further Levenberg-Marquardt fits, each from the last one's values with the weights
        (the force's error through the model) recomputed there. The first fit weighs the
        steps by the start model's tangents, which can be far from the fitted model's near
        a jump. Of all passes, the fit whose own weights give it the lowest metric is kept;
        its ``history`` runs through the passes up to it (``"pass"`` numbers them, and each
        pass starts with the metric at the same values under the new weights). Each pass has
        ``max_evaluations`` of its own.
    reweight_drop : float or None
        Recompute the weights when an iteration stalls (lowers the metric by less than
        :data:`STALL`) at a metric ``reweight_drop`` times or more below the one they were
        computed at (the model has moved far from the start whose tangents they hold), and go
        on from there with the iterations and evaluations left; again at each such stall
        (Levenberg-Marquardt on stale weights stalls far above the noise: docs/diagnosis.md,
        the rules table).
    """

    max_iterations: int = 30
    ftol: float = 1e-6
    max_evaluations: int | None = None
    give_up_chi2: float | None = None
    reweight_passes: int = 0
    reweight_drop: float | None = None


def _objective(model, data, names, rows, n_harmonics, n_time) -> FRFObjective:
    cls = DampedPredictor if any(n.startswith(ZETA) for n in names) else BranchMatchedPredictor
    pred = cls(model, data, n_harmonics=n_harmonics, n_time=n_time)
    space = damped_space(model, names)
    mask = np.zeros((data.n_steps, len(pred.channel_indices)), bool)
    mask[rows] = True
    return FRFObjective(pred, space, mask, "uncertainty")


def _reweight(obj: FRFObjective, sigma: np.ndarray) -> None:
    """Weights from the residuals' standard errors at the start model (the force's error
    through the model, :meth:`BranchMatchedPredictor.response_sigma`), held during the fit."""
    if obj.weighting != "uncertainty":
        return
    positive = sigma[np.isfinite(sigma) & (sigma > 0)]
    if not positive.size:
        return
    obj.sigma = np.maximum(np.nan_to_num(sigma, nan=positive.max()), positive.min())
    obj._weight = np.sqrt(2) / obj.sigma


#: Why a fit stopped before Levenberg-Marquardt's own criteria (its result's ``message``).
OUT_OF_WORK = OUT_OF_EVALUATIONS
NO_BETTER = "stopped: no better than the bar it was given"
REWEIGH = "reweighted"
STOPPED = (OUT_OF_WORK, NO_BETTER, REWEIGH)

#: An iteration that lowers the metric by less than this share has stalled.
STALL = 0.05

#: The stage name of the refit's Levenberg-Marquardt iterations in its events.
LM_STAGE = "Levenberg-Marquardt"


@dataclass(frozen=True)
class StopRule:
    """When a fit stops before Levenberg-Marquardt's own criteria (see :func:`refit`).

    Parameters
    ----------
    give_up_chi2 : float, optional
        The chi-square per degree of freedom a fit that is no longer falling fast must get
        below (``refit``'s ``give_up_chi2``).
    reweigh_drop : float, optional
        Stop for the weights to be recomputed at a stall this many times below the start's
        metric (``refit``'s ``reweight_drop``).
    """

    give_up_chi2: float | None = None
    reweigh_drop: float | None = None

    def check(self, seen: Sequence[Mapping], dof: int) -> str | None:
        """Why the fit stops after the last of its iterations ``seen`` (Levenberg-Marquardt's
        history entries, with ``iteration`` and ``cost``; ``dof`` its degrees of freedom), or
        None to go on. Never at the start point."""
        h = seen[-1]
        if h["iteration"] < 1:
            return None
        stalled = h["cost"] > (1 - STALL) * seen[-2]["cost"]
        if (
            self.reweigh_drop is not None
            and stalled
            and h["cost"] * self.reweigh_drop < seen[0]["cost"]
        ):
            return REWEIGH
        if self.give_up_chi2 is not None:
            # still above the bar and no longer falling fast: hopeless two iterations in, or
            # one when at twice the bar (an iteration can take a verification's whole time)
            bar = self.give_up_chi2 if h["iteration"] >= 2 else 2 * self.give_up_chi2
            if 2 * h["cost"] / dof > bar and h["cost"] > 0.5 * seen[-2]["cost"]:
                return NO_BETTER
        return None


def _lm_until(
    obj: FRFObjective, theta, rule: StopRule, limits: FitLimits, progress: Listener | None
) -> LeastSquaresResult:
    """Bounded Levenberg-Marquardt from ``theta`` until its own criteria, its allowance of
    evaluations or ``rule`` stop it; the result's ``message`` says which (a stopped fit's is
    one of :data:`OUT_OF_WORK`, :data:`NO_BETTER`, :data:`REWEIGH`), and a stopped fit has no
    covariance (a Jacobian away from an optimum says nothing of the parameters' errors)."""
    n = obj.space.size
    res = least_squares_lm(
        obj,
        theta,
        bounds=obj.space.theta_bounds(),
        max_iterations=limits.max_iterations,
        ftol=limits.ftol,
        callback=iterations(LM_STAGE, progress),
        max_evaluations=limits.max_evaluations,
        stop=lambda seen, r: rule.check(seen, max(r.size - n, 1)),
        trial_cost=getattr(obj, "bounded_cost", None),
    )
    if res.message in STOPPED:
        res.cov = np.full((n, n), np.nan)
    return res


def _current(model: Model, name: str) -> float:
    if name.startswith(ZETA):
        return model.damping.per_mode.get(int(name[len(ZETA) :]), model.damping.default_zeta)
    return model.parameters[name].value


def _with_values(model: Model, values: Mapping[str, float]) -> Model:
    """The model at fitted values, modal damping ratios included."""
    zetas = {int(n[len(ZETA) :]): v for n, v in values.items() if n.startswith(ZETA)}
    out = model.with_values({n: v for n, v in values.items() if not n.startswith(ZETA)})
    if zetas:
        per_mode = {**out.damping.per_mode, **zetas}
        out = out.with_damping(dataclasses.replace(out.damping, per_mode=per_mode))
    return out


def refit(
    model: Model,
    data: SteppedSineData,
    parameters: Sequence[str],
    *,
    rows: np.ndarray | None = None,
    starts: Starts = Starts(),
    limits: FitLimits = FitLimits(),
    n_harmonics: int = 9,
    n_time: int = 128,
    progress: Listener | None = None,
) -> Refit:
    """Fit ``parameters`` of ``model`` to the stepped-sine FRFs of ``data``.

    Parameters
    ----------
    model : Model
        Start values are its current values (always one of the starts).
    data : SteppedSineData
    parameters : sequence of str
        Fitted parameters (any group); bounds and scaling from the model file. ``zeta_<n>``
        is the modal damping ratio of mode ``n`` (log scaled, 1e-4 to 0.2).
    rows : ndarray of int, optional
        Steps fitted (default: all). Steps where the start model does not converge are left out.
    starts : Starts
        Where the fits start and how many are refined.
    limits : FitLimits
        When Levenberg-Marquardt stops, and the passes with the weights recomputed.
    n_harmonics, n_time : int
        Balance settings of the predictions.
    progress : callable, optional
        Receives :mod:`analysis.events`: a :class:`~analysis.events.UnitDone` per start scored
        (stage ``"starts"``), an :class:`~analysis.events.Iteration` per Levenberg-Marquardt
        iteration (stage :data:`LM_STAGE`).

    Returns
    -------
    Refit
    """
    if limits.reweight_passes:
        again = functools.partial(
            refit,
            data=data,
            parameters=parameters,
            rows=rows,
            n_harmonics=n_harmonics,
            n_time=n_time,
            progress=progress,
        )
        first = again(model, starts=starts, limits=dataclasses.replace(limits, reweight_passes=0))
        # later passes start from one fit's values and give up on nothing
        later = dataclasses.replace(limits, reweight_passes=0, give_up_chi2=None)

        def next_pass(m: Model, max_iterations: int) -> Refit:
            return again(m, limits=dataclasses.replace(later, max_iterations=max_iterations))

        return _reweighted(first, next_pass, limits.reweight_passes, limits.max_iterations)
    t0 = time.perf_counter()
    names = tuple(parameters)
    rows = np.arange(data.n_steps) if rows is None else np.asarray(rows)
    obj, base, good = _converged_objective(model, data, names, rows, n_harmonics, n_time)
    space = obj.space
    p0 = np.array([_current(model, n) for n in names])
    thetas = _start_thetas(space, names, p0, starts)
    whole = good.size == rows.size
    costs, n_start_evaluations = _start_costs(
        obj, thetas, p0, base if whole else None, max(starts.n_lm, 1), progress
    )
    drop = limits.reweight_drop if starts.n_lm == 1 else None
    rule = StopRule(limits.give_up_chi2, drop)
    best, reweigh, n_lm_evaluations = _lm_from_starts(
        obj, thetas, costs, starts.n_lm, rule, limits, progress
    )
    if len(thetas) == 1 and best is not None and best.history:
        costs = np.array([best.history[0]["cost"]])
    out = _as_refit(model, names, space, best, costs, t0)
    # the start model's prediction, the starts' metrics, Levenberg-Marquardt's evaluations
    out.evaluations = 1 + n_start_evaluations + n_lm_evaluations
    cap = limits.max_evaluations
    left = None if cap is None else cap - n_lm_evaluations
    if not reweigh or best.nit >= limits.max_iterations or (left is not None and left <= 0):
        return out
    rest = dataclasses.replace(
        limits, max_iterations=limits.max_iterations - best.nit, max_evaluations=left
    )
    try:
        nxt = refit(
            out.model,
            data,
            parameters,
            rows=rows,
            limits=rest,
            n_harmonics=n_harmonics,
            n_time=n_time,
            progress=progress,
        )
    except (RuntimeError, ValueError) as exc:  # the fitted model fails on a fitted step
        log.info("no fit with the weights recomputed: %s", exc)
        return out
    return _joined(out, nxt, best.nit, t0)


def _converged_objective(model: Model, data, names, rows, n_harmonics: int, n_time: int):
    """The weighted objective on the fitted steps where the start model converges, the start
    model's prediction and those steps."""
    obj = _objective(model, data, names, rows, n_harmonics, n_time)
    base, sigma = obj.predictor.predict_with_sigma(rows=rows)
    good = rows[base.converged[rows]]
    if not good.size:
        raise RuntimeError("the start model converges at none of the fitted steps")
    if good.size < rows.size:
        log.info(
            "%d step(s) left out: the start model does not converge there", rows.size - good.size
        )
        obj = _objective(model, data, names, good, n_harmonics, n_time)
    _reweight(obj, sigma)
    return obj, base, good


def _start_thetas(space, names, p0, starts: Starts):
    """The starts in the fit's scaled coordinates, within its bounds: the model's values, the
    given starts, then the Latin hypercube's."""
    candidates = [p0]
    for s in starts.given:
        candidates.append(np.array([float(s.get(n, v)) for n, v in zip(names, p0, strict=True)]))
    if starts.n_random:
        dists = dict(starts.distributions or {})
        candidates += list(latin_hypercube(dists, starts.n_random, starts.seed, names))
    lo, hi = space.theta_bounds()
    return np.clip(np.array([space.to_theta(c) for c in candidates]), lo, hi)


def _start_costs(
    obj: FRFObjective, thetas, p0, base, keep: int, progress: Listener | None
) -> tuple[np.ndarray, int]:
    """The metric at each start and the evaluations that took; ``base`` is the start model's
    prediction when it holds on every fitted step (the first start's metric without a
    solve). Only the ``keep`` best starts are refined, so a start is stopped once its metric
    provably exceeds the ``keep``-th best known (:func:`bounded_costs`): its metric is then a
    lower bound, and the ``keep`` best, and their metrics, are those of scoring every start
    whole. A start far from the data, whose steps the balance struggles with, costs little."""
    if len(thetas) == 1:  # one start: its metric is Levenberg-Marquardt's first evaluation
        return np.array([np.nan]), 0
    space = obj.space
    costs: list[float] = []

    def done(cost: float) -> None:
        costs.append(cost)
        if progress:
            progress(UnitDone("starts", len(costs), len(thetas), cost=float(cost)))

    rest = thetas
    if base is not None and np.allclose(space.to_physical(thetas[0]), p0, rtol=1e-12, atol=0):
        done(obj.cost_of(base))  # the start model itself, predicted above
        rest = thetas[1:]
    known = [c for c in costs if np.isfinite(c)]
    bounded_costs(obj, rest, np.zeros(len(rest)), keep, known, done)
    out = np.array(costs)
    if not np.isfinite(out).any():
        raise RuntimeError("no start gives a converged model response on the fitted steps")
    return out, len(rest)


def _lm_from_starts(
    obj: FRFObjective,
    thetas,
    costs,
    n_lm_starts: int,
    rule: StopRule,
    limits: FitLimits,
    progress: Listener | None,
) -> tuple[LeastSquaresResult | None, bool, int]:
    """Levenberg-Marquardt from the ``n_lm_starts`` best starts, sharing the rule's allowance
    of evaluations; the best fit, whether it stopped for its weights to be recomputed, and the
    evaluations of every start's fit."""
    best: LeastSquaresResult | None = None
    reweigh = False
    evaluations = 0
    cap = limits.max_evaluations
    for k in np.argsort(costs)[:n_lm_starts]:
        if len(thetas) > 1 and not np.isfinite(costs[k]):
            continue
        if cap is not None and evaluations >= cap:
            break
        left = None if cap is None else cap - evaluations
        res = _lm_until(
            obj, thetas[k], rule, dataclasses.replace(limits, max_evaluations=left), progress
        )
        reweigh = reweigh or res.message == REWEIGH
        evaluations += res.nfev
        if best is None or res.cost < best.cost:
            best = res
    return best, reweigh, evaluations


def _as_refit(model: Model, names, space, best: LeastSquaresResult, costs, t0: float) -> Refit:
    """The fitted model, its standard errors and its history from the best fit."""
    m, n = best.fun.size, space.size
    dof = max(m - n, 1)
    values = space.as_dict(space.to_physical(best.x))
    fitted = _with_values(model, values)
    D = np.diag(space.dp_dtheta(best.x))
    std = np.sqrt(np.clip(np.diag(D @ best.cov @ D), 0, None))
    history = [
        {
            "iteration": h["iteration"],
            "chi2_per_dof": 2 * h["cost"] / dof,
            "parameters": space.as_dict(space.to_physical(np.array(h["x"]))),
        }
        for h in best.history
    ]
    return Refit(
        model=fitted,
        parameters=values,
        std=dict(zip(names, std.tolist(), strict=True)),
        chi2_per_dof=2 * best.cost / dof,
        n_residuals=m,
        history=history,
        start_costs=[float(c) for c in costs],
        lm=best,
        seconds=time.perf_counter() - t0,
    )


def _joined(out: Refit, nxt: Refit, nit: int, t0: float) -> Refit:
    """The fit continued with its weights recomputed (``nxt``) after ``out``'s ``nit``
    iterations, with the history of both."""
    # "pass" numbers the fits with their own weights
    later = [
        {**h, "iteration": h["iteration"] + nit, "pass": h.get("pass", 0) + 1} for h in nxt.history
    ]
    return dataclasses.replace(
        nxt,
        history=[{**h, "pass": 0} for h in out.history] + later,
        start_costs=out.start_costs,
        seconds=time.perf_counter() - t0,
        evaluations=out.evaluations + nxt.evaluations,
    )


def _reweighted(
    fit: Refit, again: Callable[[Model, int], Refit], passes: int, max_iterations: int
) -> Refit:
    """:func:`refit`'s further passes after ``fit``: ``again(model, max_iterations)`` fits from
    the model's values with the weights recomputed there."""
    t0 = time.perf_counter() - fit.seconds
    fits, own = [fit], []
    evaluations = fit.evaluations
    for k in range(1, passes + 2):
        # one start, the last fit's values: its first metric is the last fit's own one
        last = k > passes
        try:
            nxt = again(fits[-1].model, 0 if last else max_iterations)
        except (RuntimeError, ValueError) as exc:  # the fitted model fails on a fitted step
            log.info("reweighting stopped after pass %d: %s", k - 1, exc)
            own.append(np.inf)
            break
        evaluations += nxt.evaluations
        own.append(2 * nxt.start_costs[0] / max(nxt.n_residuals - len(nxt.parameters), 1))
        if last:
            break
        fits.append(nxt)
    kept = int(np.argmin(own))
    history, offset = [], 0
    for k, f in enumerate(fits[: kept + 1]):
        history += [{**h, "iteration": h["iteration"] + offset, "pass": k} for h in f.history]
        offset = history[-1]["iteration"]
    log.info("reweighted fits: own chi2/dof %s, kept pass %d", own, kept)
    return dataclasses.replace(
        fits[kept],
        history=history,
        start_costs=fit.start_costs,
        seconds=time.perf_counter() - t0,
        evaluations=evaluations,
    )
