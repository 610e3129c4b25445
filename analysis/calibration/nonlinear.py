"""Nonlinear calibration: Latin hypercube starts, then Levenberg-Marquardt (the paper's method).

>>> result = calibrate_nonlinear(model, data)            # doctest: +SKIP
>>> result.parameters["gap"], result.std["gap"]           # doctest: +SKIP
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from analysis.calibration.lhs import Distribution, latin_hypercube, paper_distributions
from analysis.calibration.lm import LeastSquaresResult, least_squares_lm
from analysis.calibration.modal_damping import DampedPredictor, damped_space, with_values
from analysis.calibration.objective import FRFObjective
from analysis.calibration.parameters import ParameterSpace
from analysis.calibration.uncertainty import (
    ADEQUATE_RMS,
    HeldParameters,
    Propagation,
    adequate,
    noise_scale,
    propagate_held,
)
from analysis.events import Iteration, Listener, StageDone, UnitDone, iterations
from analysis.measurement_file import SteppedSineData, read_measurement
from analysis.model import Model
from analysis.predict import SteppedSinePredictor
from analysis.predict_branches import BranchMatchedPredictor

__all__ = [
    "LHS_STAGE",
    "CalibrationSettings",
    "NonlinearCalibration",
    "bounded_costs",
    "calibrate_nonlinear",
    "fitted_rows",
    "level_rows",
    "make_predictor",
    "screen_costs",
]

log = logging.getLogger(__name__)

#: The stage name of the Latin hypercube starts in the calibration's events.
LHS_STAGE = "Latin hypercube starts"


@dataclass(frozen=True)
class CalibrationSettings:
    """Settings of a nonlinear calibration.

    Parameters
    ----------
    parameters : tuple of str
        Calibrated model parameters.
    calibration_levels_n : tuple of float, optional
        Force levels [N] used (default: all but ``validation_level_n``).
    validation_level_n : float or None
        Level kept out for validation (default: the highest level of the file when it has at
        least two; ``0`` keeps none out).
    channels : tuple of str, optional
        Response channels compared (default: every motion channel but the drive force).
    weighting : {"uncertainty", "identity"}
    n_starts : int
        Latin hypercube realisations (the paper: 100).
    n_lm_starts : int
        Best candidates refined by LM (the paper: 1).
    seed : int
    distributions : mapping name -> Distribution, optional
        Default: the paper's (k_c, gap, v_c).
    max_iterations : int
    n_harmonics, n_time : int
    match_branches : bool
        Predict on the branch the test was on
        (:class:`~analysis.predict_branches.BranchMatchedPredictor`): where the rig left a
        resonant branch before its fold, the model's forward continuation would not, and those
        few steps would misfit by hundreds of standard errors whatever the parameters. False
        gives the plain forward continuation of the measured sweep order.
    include_unconverged : bool
        Also fit the steps the file marks as not converged under force control (their force
        is off target and the response may not have settled).
    joint : bool
        With held values of known uncertainty (``held``), refine the calibrated parameters
        jointly with them under their covariance as a Gaussian prior (the linear test's
        posterior): the stepped sine then corrects what it can of the held values and the
        stated intervals are the joint posterior's marginals. False: the held values stay
        where they are and their uncertainty is only carried through the sensitivities.
    """

    parameters: tuple[str, ...] = ("k_c", "gap", "v_c")
    calibration_levels_n: tuple[float, ...] | None = None
    validation_level_n: float | None = None
    channels: tuple[str, ...] | None = None
    weighting: str = "uncertainty"
    n_starts: int = 100
    n_lm_starts: int = 1
    seed: int = 0
    distributions: Mapping[str, Distribution] | None = None
    max_iterations: int = 50
    n_harmonics: int = 9
    n_time: int = 128
    match_branches: bool = True
    include_unconverged: bool = False
    joint: bool = True

    def __post_init__(self) -> None:
        if not self.parameters:
            raise ValueError("CalibrationSettings.parameters: name at least one parameter")
        if self.n_starts < 1 or self.n_lm_starts < 1 or self.n_lm_starts > self.n_starts:
            raise ValueError("CalibrationSettings: need 1 <= n_lm_starts <= n_starts")
        if self.weighting not in ("uncertainty", "identity"):
            raise ValueError("CalibrationSettings.weighting: 'uncertainty' or 'identity'")

    def to_json(self) -> dict:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "distributions"}
        d["distributions"] = (
            None
            if self.distributions is None
            else {k: v.to_json() for k, v in self.distributions.items()}
        )
        return d


def level_rows(data: SteppedSineData, levels_n: Sequence[float]) -> np.ndarray:
    """Row indices of the steps at the given target levels."""
    idx = [int(np.argmin(np.abs(data.levels_n - lv))) for lv in levels_n]
    for lv, i in zip(levels_n, idx, strict=True):
        if not np.isclose(data.levels_n[i], lv, rtol=1e-6):
            raise ValueError(f"{data.path}: no level {lv} N (levels: {list(data.levels_n)})")
    return np.flatnonzero(np.isin(data.level_index, idx))


def fitted_rows(
    data: SteppedSineData, levels_n: Sequence[float], include_unconverged: bool = False
) -> np.ndarray:
    """Row indices of the steps at the given levels that a calibration fits: those converged
    under force control (every step with ``include_unconverged``)."""
    rows = level_rows(data, levels_n)
    if include_unconverged:
        return rows
    return rows[np.asarray(data.control_converged, bool)[rows]]


def make_predictor(
    model: Model, data: SteppedSineData, settings: CalibrationSettings
) -> SteppedSinePredictor:
    """The predictor a calibration with ``settings`` uses (see ``match_branches``)."""
    kind = BranchMatchedPredictor if settings.match_branches else SteppedSinePredictor
    return kind(
        model,
        data,
        channels=settings.channels,
        n_harmonics=settings.n_harmonics,
        n_time=settings.n_time,
    )


def split_levels(data: SteppedSineData, settings: CalibrationSettings):
    """(calibration levels, validation level or None) for a file."""
    levels = sorted(float(x) for x in data.levels_n)
    val = settings.validation_level_n
    if val is None:
        val = levels[-1] if len(levels) >= 2 else None
    elif val == 0:
        val = None
    cal = settings.calibration_levels_n
    if cal is None:
        cal = tuple(lv for lv in levels if val is None or not np.isclose(lv, val))
    return tuple(cal), val


@dataclass
class NonlinearCalibration:
    """Result of :func:`calibrate_nonlinear`.

    Attributes
    ----------
    parameters : dict name -> float
        Calibrated values (physical units).
    cov : ndarray, shape (n, n)
        The reported covariance (physical units): the noise's ``cov_noise`` scaled per
        parameter by ``noise_scale``, plus ``held_cov``, what the held values' uncertainty
        does to the fitted ones (:mod:`analysis.calibration.uncertainty`).
    cov_noise : ndarray, shape (n, n)
        The noise-only covariance, the inverse Fisher information: ``(J^T W J)^-1`` for
        uncertainty weighting, scaled by the residual variance for identity weighting.
    std, correlation
        From ``cov``.
    chi2_per_dof : float
        ``2 cost / (m - n)``.
    starts : ndarray, shape (n_starts, n)
        Latin hypercube candidates; ``start_costs`` their metric.
    start_exact : ndarray of bool, shape (n_starts,)
        Where ``start_costs`` is the metric itself; elsewhere it is a lower bound above the
        ``n_lm_starts``-th best cost (the start's prediction was stopped there:
        :func:`screen_costs`).
    lm : LeastSquaresResult
        The refinement (scaled coordinates) with its history.
    held : HeldParameters or None
        The values held fixed and their uncertainty (None: held as exact).
    held_cov : ndarray, shape (n, n)
    held_gain : ndarray, shape (n, k)
        ``d parameter / d held value`` at the optimum.
    noise_scale : ndarray, shape (n,)
        Factor on each noise-only standard deviation: the Birge ratio, or the folds' scatter
        over the noise-only figure once a cross-validation widened it (``fold_ratio``).
    """

    parameters: dict[str, float]
    cov: np.ndarray
    chi2_per_dof: float
    n_residuals: int
    starts: np.ndarray
    start_costs: np.ndarray
    lm: LeastSquaresResult
    space: ParameterSpace
    settings: CalibrationSettings
    calibration_levels_n: tuple[float, ...]
    validation_level_n: float | None
    timings: dict[str, float] = field(default_factory=dict)
    start_exact: np.ndarray | None = None
    cov_noise: np.ndarray | None = None
    held: HeldParameters | None = None
    held_cov: np.ndarray | None = None
    held_gain: np.ndarray | None = None
    noise_scale: np.ndarray | None = None
    fold_ratio: np.ndarray | None = None
    fold_misfit: list[str] = field(default_factory=list)
    held_posterior: dict[str, float] | None = None
    joint_names: tuple[str, ...] | None = None
    cov_joint: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = self.space.size
        if self.cov_noise is None:
            self.cov_noise = np.array(self.cov, dtype=float)
        if self.held_cov is None:
            self.held_cov = np.zeros((n, n))
        if self.noise_scale is None:
            self.noise_scale = np.ones(n)
        if self.start_exact is None:
            self.start_exact = np.ones(len(self.start_costs), bool)

    @property
    def std(self) -> dict[str, float]:
        return dict(zip(self.space.names, np.sqrt(np.diag(self.cov)).tolist(), strict=True))

    @property
    def std_noise(self) -> dict[str, float]:
        return dict(zip(self.space.names, np.sqrt(np.diag(self.cov_noise)).tolist(), strict=True))

    @property
    def correlation(self) -> np.ndarray:
        s = np.sqrt(np.diag(self.cov))
        return self.cov / np.outer(s, s)

    @property
    def rms_over_noise(self) -> float:
        """Root of the chi-square per degree of freedom of the fit."""
        return float(np.sqrt(self.chi2_per_dof))

    @property
    def misfit(self) -> list[str]:
        """Why the model misfits its calibration data beyond :data:`ADEQUATE_RMS` of the
        noise (the intervals are then not to be trusted); empty when it is adequate."""
        out = []
        if self.settings.weighting == "uncertainty" and not adequate(self.rms_over_noise):
            out.append(
                f"the calibrated model misfits its calibration data by {self.rms_over_noise:.3g}"
                f" x the noise (adequate up to {ADEQUATE_RMS:g})"
            )
        return out + list(self.fold_misfit)

    def combine(self) -> None:
        """Set ``cov`` from its parts (after ``noise_scale`` or ``held_cov`` changed)."""
        k = np.asarray(self.noise_scale, dtype=float)
        self.cov = self.cov_noise * np.outer(k, k) + self.held_cov

    def widen_with_folds(self, std_ratio, misfit_folds: list[str]) -> None:
        """Take a cross-validation's evidence into the stated intervals: each parameter's
        noise part widened by the folds' scatter where it exceeds the Birge ratio, and the
        folds the model misfits named among :attr:`misfit`."""
        self.fold_ratio = np.asarray(std_ratio, dtype=float)
        self.noise_scale = noise_scale(self.chi2_per_dof, self.fold_ratio)
        self.fold_misfit = (
            [f"the cross-validation finds a systematic misfit in {', '.join(misfit_folds[:3])}"]
            if misfit_folds
            else []
        )
        self.combine()

    def contributions(self) -> dict[str, dict[str, float]]:
        """Per parameter, the standard deviation each source contributes (they add in
        quadrature to ``std``): ``noise``, ``misfit`` (what the noise scale adds to it) and
        one entry per held value."""
        names = self.space.names
        sd_noise = np.sqrt(np.diag(self.cov_noise))
        k = np.asarray(self.noise_scale, dtype=float) * np.ones(len(names))
        out: dict[str, dict[str, float]] = {}
        for i, n in enumerate(names):
            row = {
                "noise": float(sd_noise[i]),
                "misfit": float(sd_noise[i] * np.sqrt(max(k[i] ** 2 - 1, 0.0))),
            }
            if self.cov_joint is not None:  # jointly refined: what is left of them together
                row["held values"] = float(np.sqrt(max(self.held_cov[i, i], 0.0)))
            elif self.held is not None and self.held_gain is not None:
                for j, h in enumerate(self.held.names):
                    row[h] = float(abs(self.held_gain[i, j]) * np.sqrt(self.held.cov[j, j]))
            out[n] = row
        return out

    def conditioned(self, model: Model) -> Model:
        """``model`` with the held values the calibration ended at (the joint refinement's;
        unchanged without one): the model its parameters are calibrated for."""
        return with_values(model, self.held_posterior) if self.held_posterior else model

    def calibrated_model(self, model: Model) -> Model:
        """``model`` with the calibrated values (and the held values the calibration ended
        at)."""
        return self.conditioned(model).with_values(self.parameters)

    def joint_covariance(self) -> tuple[tuple[str, ...], np.ndarray]:
        """Names and covariance of the calibrated parameters with the held values (as
        reported: the calibrated block is ``cov``); the calibrated block alone when there is
        no joint refinement."""
        if self.cov_joint is None or self.joint_names is None:
            return tuple(self.space.names), self.cov
        C = np.array(self.cov_joint, dtype=float)
        n = self.space.size
        C[:n, :n] = self.cov
        return self.joint_names, C

    def to_json(self) -> dict:
        names = list(self.space.names)
        std = self.std
        return {
            "parameters": self.parameters,
            "std": std,
            "interval_95": {
                n: [self.parameters[n] - 1.96 * std[n], self.parameters[n] + 1.96 * std[n]]
                for n in names
            },
            "cov": self.cov.tolist(),
            "correlation": self.correlation.tolist(),
            "std_noise": self.std_noise,
            "cov_noise": self.cov_noise.tolist(),
            "uncertainty": {
                "estimator": UNCERTAINTY_ESTIMATOR,
                "noise_scale": np.asarray(self.noise_scale, float).tolist(),
                "fold_ratio": None if self.fold_ratio is None else self.fold_ratio.tolist(),
                "held": None if self.held is None else self.held.to_json(),
                "held_cov": np.asarray(self.held_cov).tolist(),
                "held_gain": None if self.held_gain is None else self.held_gain.tolist(),
                "contributions": self.contributions(),
                "notes": [] if self.held is None else list(self.held.notes),
                "held_posterior": self.held_posterior,
                "joint_names": None if self.joint_names is None else list(self.joint_names),
                "cov_joint": None if self.cov_joint is None else self.cov_joint.tolist(),
            },
            "rms_over_noise": self.rms_over_noise,
            "adequate_rms": ADEQUATE_RMS,
            "misfit": self.misfit,
            "fold_misfit": self.fold_misfit,
            "names": names,
            "chi2_per_dof": self.chi2_per_dof,
            "n_residuals": self.n_residuals,
            "calibration_levels_n": list(self.calibration_levels_n),
            "validation_level_n": self.validation_level_n,
            "best_start": dict(
                zip(names, self.starts[int(np.argmin(self.start_costs))].tolist(), strict=True)
            ),
            "starts": self.starts.tolist(),
            "start_costs": [None if not np.isfinite(c) else float(c) for c in self.start_costs],
            "start_cost_exact": np.asarray(self.start_exact, bool).tolist(),
            "lm": {
                "success": self.lm.success,
                "message": self.lm.message,
                "nit": self.lm.nit,
                "nfev": self.lm.nfev,
                "cost": self.lm.cost,
                "history": [
                    {
                        **h,
                        "parameters": dict(
                            zip(
                                names,
                                self.space.to_physical(np.array(h["x"])).tolist(),
                                strict=True,
                            )
                        ),
                    }
                    for h in self.lm.history
                ],
            },
            "settings": self.settings.to_json(),
            "timings": self.timings,
        }


UNCERTAINTY_ESTIMATOR = (
    "noise: inverse Fisher information (J^T W J)^-1 of the uncertainty-weighted metric at the "
    "optimum with the held values fixed, each standard deviation scaled by the larger of the "
    "Birge ratio sqrt(chi2/dof) and the cross-validation folds' scatter over it; plus what the "
    "held linear parameters and modal damping ratios add: the joint posterior's marginal under "
    "the linear test's posterior as prior (without a joint refinement: G C_b G^T, their "
    "covariance C_b carried through the sensitivities G); docs/calibration.md"
)


# -- objective construction, also inside worker processes -------------------------------
@dataclass(frozen=True)
class ObjectiveSpec:
    """Everything needed to rebuild an :class:`FRFObjective` in another process (picklable)."""

    model_toml: str
    data_path: str
    names: tuple[str, ...]
    mask: np.ndarray
    weighting: str
    channels: tuple[str, ...] | None
    n_harmonics: int
    n_time: int
    match_branches: bool = True

    def build(self) -> FRFObjective:
        model = Model.from_toml_text(self.model_toml, source="<calibration model>")
        data = read_measurement(self.data_path)
        if not isinstance(data, SteppedSineData):
            raise ValueError(
                f"{self.data_path}: a stepped-sine run is needed (a random test given)"
            )
        settings = CalibrationSettings(
            channels=self.channels,
            n_harmonics=self.n_harmonics,
            n_time=self.n_time,
            match_branches=self.match_branches,
        )
        pred = make_predictor(model, data, settings)
        return FRFObjective(
            pred, ParameterSpace.from_model(model, self.names), self.mask, self.weighting
        )


_WORKER_CACHE: dict[int, FRFObjective] = {}


def _objective_in_worker(spec: ObjectiveSpec) -> FRFObjective:
    """The objective of ``spec``, built once per worker process."""
    key = hash(
        (
            spec.model_toml,
            spec.data_path,
            spec.names,
            spec.mask.tobytes(),
            spec.weighting,
            spec.channels,
        )
    )
    obj = _WORKER_CACHE.get(key)
    if obj is None:
        _WORKER_CACHE.clear()
        obj = _WORKER_CACHE[key] = spec.build()
    return obj


def _evaluate_chunk(spec: ObjectiveSpec, thetas: np.ndarray) -> list[float]:
    obj = _objective_in_worker(spec)
    return [obj.cost(t) for t in thetas]


def _screen_chunk(spec: ObjectiveSpec, thetas, offsets, keep: int | None, known: list[float]):
    """:func:`bounded_costs` of one chunk in a worker."""
    return bounded_costs(_objective_in_worker(spec), thetas, offsets, keep, known)


def bounded_costs(
    obj: FRFObjective,
    thetas,
    offsets,
    keep: int | None,
    known,
    on_each: Callable[[float], None] | None = None,
) -> tuple[list[float], list[bool]]:
    """Costs of ``thetas`` over ``obj``'s selection, in turn: ``(costs, exact)``.

    ``offsets`` are the points' costs over the rest of the selection (already scored), and a
    point's total is its offset plus its cost here. With ``keep``, each point is stopped once
    its total provably exceeds the ``keep``-th smallest exact total known (``known``, then
    those of this chunk), and the cost here is then a lower bound (``exact`` False): the
    ``keep`` smallest totals, and which points have them, are those of scoring every point
    whole. ``on_each(cost)`` after each point.
    """
    known = list(known)
    costs, exact = [], []
    for t, off in zip(thetas, offsets, strict=True):
        kth = sorted(known)[keep - 1] if keep is not None and len(known) >= keep else None
        if not np.isfinite(off):  # no solution in the part already scored
            c, ok = np.inf, True
        elif kth is not None and off > kth * (1.0 + 1e-9):
            c, ok = 0.0, False
        else:
            # an absolute margin on the rest's limit: the rounding of the total, not the rest's
            c, ok = obj.bounded_cost(t, None if kth is None else kth - off + 1e-9 * kth)
        costs.append(c)
        exact.append(ok)
        if ok and np.isfinite(c):
            known.append(off + c)
        if on_each:
            on_each(c)
    return costs, exact


def _screen_all(spec, local, thetas, offsets, keep, executor, tick):
    """:func:`bounded_costs` of every point, in chunks on ``executor`` (in order, as many in
    flight as workers, each later chunk starting with every exact total known by then)."""
    if executor is None:
        c, e = bounded_costs(local or spec.build(), thetas, offsets, keep, [], lambda _: tick())
        return np.array(c, dtype=float), np.array(e, bool)
    workers = max(1, getattr(executor, "_max_workers", 2) or 2)
    parts = [
        (t, o) for t, o in zip(_chunks(thetas, workers), _chunks(offsets, workers), strict=True)
    ]
    costs: list = [None] * len(parts)
    exact: list = [None] * len(parts)
    known: list[float] = []
    running: dict = {}
    nxt = 0
    while nxt < len(parts) or running:
        while nxt < len(parts) and len(running) < workers:
            t, o = parts[nxt]
            running[executor.submit(_screen_chunk, spec, t, o, keep, list(known))] = nxt
            nxt += 1
        finished, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
        for f in finished:
            i = running.pop(f)
            costs[i], exact[i] = f.result()
            o = parts[i][1]
            known += [
                off + c
                for c, ok, off in zip(costs[i], exact[i], o, strict=True)
                if ok and c < np.inf
            ]
            if tick:
                for _ in costs[i]:
                    tick()
    return np.concatenate(costs).astype(float), np.concatenate(exact).astype(bool)


def screen_costs(
    spec: ObjectiveSpec,
    thetas: np.ndarray,
    keep: int,
    executor: cf.Executor | None = None,
    local: FRFObjective | None = None,
    on_done: Callable[[int, int], None] | None = None,
    first: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The metric at many scaled points where it can matter to the ``keep`` best.

    The metric is a sum of non-negative terms, one per step. With ``first`` (steps, a part of
    the selection's), every point is scored on those steps first; that part of its metric is a
    lower bound of the whole. The points are then finished in increasing order of it, and each
    is stopped once the sum of its steps' final terms exceeds the ``keep``-th smallest metric
    already known: the point cannot be among the ``keep`` best, and its metric is returned as
    that lower bound. The sweeps are independent (each starts from its first step's linear
    response), so scoring a part first changes no step's solution: the ``keep`` smallest
    metrics, and which points have them, are those of :func:`evaluate_costs` (to the rounding
    of a sum taken in two parts).

    Returns
    -------
    costs : ndarray, shape (n,)
        Exact costs, or lower bounds where ``exact`` is False (``inf``: no solution).
    exact : ndarray of bool, shape (n,)
    """
    n = len(thetas)
    if keep < 1:
        raise ValueError(f"screen_costs: keep must be >= 1, got {keep}")
    done = [0]

    def tick() -> None:  # a point scored in two parts counts half each time
        done[0] += 1
        if on_done:
            on_done(done[0] // passes, n)

    if on_done:
        on_done(0, n)  # the clock starts here: chunks run side by side
    sel = spec.mask.any(axis=1)
    part = None if first is None else np.asarray(first, bool) & sel
    passes = 2 if part is not None and part.any() and (sel & ~part).any() else 1
    if passes == 1:
        return _screen_all(spec, local, thetas, np.zeros(n), keep, executor, tick)
    specs, objs = [], []
    for rows in (part, sel & ~part):
        m = spec.mask & rows[:, None]
        specs.append(dataclasses.replace(spec, mask=m))
        objs.append(
            None if local is None else FRFObjective(local.predictor, local.space, m, spec.weighting)
        )
    lead, _ = _screen_all(specs[0], objs[0], thetas, np.zeros(n), None, executor, tick)
    order = np.argsort(lead, kind="stable")
    rest, exact = _screen_all(specs[1], objs[1], thetas[order], lead[order], keep, executor, tick)
    costs = np.empty(n)
    ok = np.empty(n, bool)
    costs[order] = lead[order] + rest
    ok[order] = exact
    return costs, ok


def _chunks(thetas: np.ndarray, workers: int) -> list[np.ndarray]:
    """Chunks of the points for ``workers`` processes (four each: progress and balance)."""
    n_chunks = max(1, min(len(thetas), 4 * workers))
    return [c for c in np.array_split(thetas, n_chunks) if len(c)]


def evaluate_costs(
    spec: ObjectiveSpec,
    thetas: np.ndarray,
    executor: cf.Executor | None = None,
    local: FRFObjective | None = None,
    on_done: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """Metric at many scaled points, on ``executor`` if given (chunks per worker);
    ``on_done(done, total)`` as points are finished (progress)."""
    total = len(thetas)
    if on_done:
        on_done(0, total)  # the clock starts here: chunks run side by side
    if executor is None:
        obj = local or spec.build()
        costs = []
        for t in thetas:
            costs.append(obj.cost(t))
            if on_done:
                on_done(len(costs), total)
        return np.array(costs)
    chunks = _chunks(thetas, getattr(executor, "_max_workers", 2) or 2)
    futures = {executor.submit(_evaluate_chunk, spec, c): len(c) for c in chunks}
    if on_done:
        done = 0
        for f in cf.as_completed(futures):
            done += futures[f]
            on_done(done, total)
    return np.concatenate([f.result() for f in futures])


def _lowest_level(data: SteppedSineData, rows: np.ndarray) -> np.ndarray:
    """The fitted steps at the lowest fitted level, shape (n_steps,) of bool: the cheapest part
    to score every start on first (the contact's nonlinearity grows with the level)."""
    lv = data.levels_n[data.level_index]
    out = np.zeros(data.n_steps, bool)
    out[rows] = True
    return out & np.isclose(lv, lv[rows].min())


def _last(stage: str, res: LeastSquaresResult) -> Iteration:
    """Where an optimisation stopped, as its last :class:`Iteration`."""
    return Iteration(stage, res.nit, float(res.cost), tuple(map(float, res.x)), last=True)


def _best_lm(objective, starts, bounds, st: CalibrationSettings, progress):
    """Levenberg-Marquardt from each of ``starts`` (the best Latin hypercube points); the
    result of least cost."""
    best: LeastSquaresResult | None = None
    for theta in starts:
        res = least_squares_lm(
            objective,
            theta,
            bounds=bounds,
            max_iterations=st.max_iterations,
            callback=iterations("Levenberg-Marquardt", progress),
            trial_cost=objective.bounded_cost,
        )
        if best is None or res.cost < best.cost:
            best = res
    if progress:
        progress(_last("Levenberg-Marquardt", best))
    return best


def calibrate_nonlinear(
    model: Model,
    data: SteppedSineData,
    settings: CalibrationSettings | None = None,
    *,
    executor: cf.Executor | None = None,
    progress: Listener | None = None,
    held: HeldParameters | None = None,
) -> NonlinearCalibration:
    """Calibrate nonlinear parameters on multi-harmonic FRFs (paper sec. 2.3).

    Parameters
    ----------
    model : Model
        The model with its linear part calibrated (sensor masses come from the file).
    data : SteppedSineData
        A stepped-sine measurement file (read with ``read_measurement``).
    settings : CalibrationSettings, optional
    executor : concurrent.futures.Executor, optional
        Runs the Latin hypercube evaluations (a process pool, or a Dask client's executor).
    progress : callable, optional
        Receives the calibration's :mod:`analysis.events`: a :class:`UnitDone` per Latin
        hypercube start (stage ``"Latin hypercube starts"``), a :class:`StageDone` when they
        are scored, an :class:`Iteration` per Levenberg-Marquardt iteration (stage ``"lm"``,
        then ``"joint"`` for the joint refinement; ``last`` where each stopped).
    held : HeldParameters, optional
        The uncertainty of the values the calibration holds (the linear parameters, the
        modal damping): carried into the reported covariance. None: they are held as exact.
    """
    st = settings or CalibrationSettings()
    cal_levels, val_level = split_levels(data, st)
    rows = fitted_rows(data, cal_levels, st.include_unconverged)
    space = ParameterSpace.from_model(model, st.parameters)
    predictor = make_predictor(model, data, st)
    mask = np.zeros((data.n_steps, len(predictor.channel_indices)), bool)
    mask[rows] = True
    objective = FRFObjective(predictor, space, mask, st.weighting)
    spec = ObjectiveSpec(
        model.to_toml(),
        str(data.path),
        space.names,
        mask,
        st.weighting,
        st.channels,
        st.n_harmonics,
        st.n_time,
        st.match_branches,
    )
    dists = dict(st.distributions or {})
    if not dists and set(st.parameters) <= {"k_c", "gap", "v_c"}:
        gap_nominal = model.parameters["gap"].nominal if "gap" in model.parameters else 1e-3
        dists = paper_distributions(gap_nominal)
    t0 = time.perf_counter()
    starts = latin_hypercube(dists, st.n_starts, st.seed, space.names)
    lo_t, hi_t = space.theta_bounds()
    thetas = np.clip(space.to_theta(starts), lo_t, hi_t)
    tick = (lambda k, n: progress(UnitDone(LHS_STAGE, k, n))) if progress else None
    costs, exact = screen_costs(
        spec, thetas, st.n_lm_starts, executor, objective, tick, first=_lowest_level(data, rows)
    )
    lhs_s = time.perf_counter() - t0
    if not np.isfinite(costs).any():
        raise RuntimeError("no Latin hypercube start gave a converged model response")
    order = np.argsort(costs)
    if progress:
        progress(StageDone(LHS_STAGE, count=len(costs), cost=float(costs[order[0]]), seconds=lhs_s))
    t0 = time.perf_counter()
    best = _best_lm(objective, thetas[order[: st.n_lm_starts]], (lo_t, hi_t), st, progress)
    lm_s = time.perf_counter() - t0
    m, n = best.fun.size, space.size
    dof = max(m - n, 1)
    chi2 = 2 * best.cost / dof
    D = np.diag(space.dp_dtheta(best.x))
    cov = D @ best.cov @ D
    if objective.weighting == "identity":
        cov = cov * chi2
    p = space.to_physical(best.x)
    log.info("calibrated %s (chi2/dof %.3g)", space.as_dict(p), chi2)
    result = NonlinearCalibration(
        parameters=space.as_dict(p),
        cov=cov,
        chi2_per_dof=float(chi2),
        n_residuals=m,
        starts=starts,
        start_costs=costs,
        start_exact=exact,
        lm=best,
        space=space,
        settings=st,
        calibration_levels_n=cal_levels,
        validation_level_n=val_level,
        timings={"lhs_s": lhs_s, "lm_s": lm_s},
        cov_noise=cov,
        held=held,
    )
    if held is not None and held.names:
        t0 = time.perf_counter()
        if st.joint and objective.weighting == "uncertainty":
            _joint_refinement(result, model, data, objective, progress)
        else:
            prop: Propagation = propagate_held(
                objective, best.x, best.jac, model.with_values(result.parameters), held
            )
            result.held_cov, result.held_gain = prop.cov, prop.gain
        result.timings["held_s"] = time.perf_counter() - t0
    if objective.weighting == "uncertainty":
        result.noise_scale = noise_scale(result.chi2_per_dof) * np.ones(n)
    result.combine()
    return result


class _GaussianPrior:
    """Residuals with a Gaussian prior on the last ``k`` coordinates appended:
    ``L^-1 (theta_b - theta_b0)`` with ``L L^T`` their prior covariance, so the cost is the
    negative log posterior (the data residuals are already unit-variance)."""

    def __init__(self, objective, n_free: int, center: np.ndarray, cov: np.ndarray) -> None:
        self.objective, self.n = objective, n_free
        self.center = np.asarray(center, dtype=float)
        self.whiten = np.linalg.inv(np.linalg.cholesky(cov))

    def __call__(self, theta, want_jac: bool = True):
        r, J = self.objective(theta, want_jac)
        rp = self.whiten @ (np.asarray(theta, dtype=float)[self.n :] - self.center)
        if not np.all(np.isfinite(r)):
            return np.full(r.size + rp.size, np.nan), None
        r = np.concatenate([r, rp])
        if J is None:
            return r, None
        Jp = np.zeros((rp.size, J.shape[1]))
        Jp[:, self.n :] = self.whiten
        return r, np.vstack([J, Jp])


def _joint_refinement(result, model, data, objective, progress) -> None:
    """Refine the calibrated parameters jointly with the held values under their covariance as
    a prior (the linear test's posterior): the stepped sine corrects what it can of them, and
    the calibrated parameters' covariance is the joint posterior's marginal. ``cov_noise``
    becomes the noise-only covariance at the joint optimum with the held values fixed (what the
    folds' scatter compares with), ``held_cov`` what the held values' uncertainty adds."""
    st, space, held = result.settings, result.space, result.held
    k = space.size
    names = (*space.names, *held.names)
    start = {**result.parameters, **held.values}
    pred = DampedPredictor(
        model, data, channels=st.channels, n_harmonics=st.n_harmonics, n_time=st.n_time
    )
    sp = damped_space(model, names)
    obj = FRFObjective(pred, sp, objective.mask, objective.weighting)
    obj.sigma, obj._weight = objective.sigma, objective._weight
    x0 = sp.to_theta([start[nm] for nm in names])
    lo, hi = sp.theta_bounds()
    x0 = np.clip(x0, lo, hi)
    Db = sp.dp_dtheta(x0)[k:]
    prior = _GaussianPrior(obj, k, x0[k:], held.cov / np.outer(Db, Db))
    res = least_squares_lm(
        prior,
        x0,
        bounds=(lo, hi),
        max_iterations=st.max_iterations,
        callback=iterations("joint refinement", progress),
    )
    if progress:
        progress(_last("joint refinement", res))
    nb = len(held.names)
    J = res.jac[:-nb]
    D = sp.dp_dtheta(res.x)
    cov_joint = res.cov * np.outer(D, D)
    Ja = J[:, :k]
    cov_noise = np.linalg.pinv(Ja.T @ Ja) * np.outer(D[:k], D[:k])
    values = sp.as_dict(sp.to_physical(res.x))
    m = J.shape[0]
    data_cost = 0.5 * float(res.fun[:-nb] @ res.fun[:-nb])
    result.parameters = {nm: values[nm] for nm in space.names}
    result.held_posterior = {nm: values[nm] for nm in held.names}
    result.joint_names, result.cov_joint = names, cov_joint
    result.cov_noise = cov_noise
    result.held_cov = cov_joint[:k, :k] - cov_noise
    # d calibrated / d held at fixed data, from the joint normal equations without the prior
    result.held_gain = -np.linalg.lstsq(J[:, :k] / D[:k], J[:, k:] / D[k:], rcond=None)[0]
    result.chi2_per_dof = float(2 * data_cost / max(m - k, 1))
    result.lm = dataclasses.replace(
        result.lm,
        x=res.x[:k],
        cost=data_cost,
        nit=result.lm.nit + res.nit,
        history=[
            *result.lm.history,
            *({**h, "x": list(np.asarray(h["x"])[:k]), "joint": True} for h in res.history),
        ],
    )
    log.info("joint refinement: %s (chi2/dof %.3g)", values, result.chi2_per_dof)
