"""Verification of screened candidates in the full model.

Each candidate is added to the model and everything it touches is recalibrated with the
multi-harmonic balance and Levenberg-Marquardt on the measured branch, on every level but the
highest of four or more (which validates: :func:`calibration_rows`;
:func:`analysis.diagnosis.refit.refit`): the candidate's parameters and the model's own
nonlinear parameters, from the screen's estimates and, for strong effects, several further
starts. A linear candidate is first recalibrated with the model's linear parameters on the
linear (random-excitation) test when one is given, the paper's way. The result carries the
per-step chi-square of the recalibrated model against the whole file, so candidates are
compared on the same steps.

Jobs are self-contained and picklable (:class:`VerifyJob`), so they run on any executor
(:func:`analysis.executors.open_executor`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from analysis.calibration.lhs import Distribution, paper_distributions
from analysis.calibration.nonlinear import fitted_rows
from analysis.diagnosis.candidates import Candidate
from analysis.diagnosis.compare import compare
from analysis.diagnosis.refit import FitLimits, Starts, refit
from analysis.measurement_file import read_measurement
from analysis.model import Model
from analysis.predict_branches import BranchMatchedPredictor

__all__ = [
    "VerifyJob",
    "Verified",
    "band_modes",
    "calibration_rows",
    "damping_parameters",
    "run_verify",
    "start_distributions",
]

#: Laws that act at rest (their tangent at zero motion is a damper): the linear test's modal
#: damping already holds their share, so a candidate with one recalibrates that damping too.
ACT_AT_REST = ("coulomb_friction", "linear_damper")

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VerifyJob:
    """One candidate to verify: picklable and self-contained.

    Parameters
    ----------
    model_toml, source : str
        The calibrated model as model-file text and where it came from.
    data_path : str
        The stepped-sine file.
    rows : tuple of int or None
        Steps fitted (None: :func:`calibration_rows`). The score is on the whole file.
    candidate : Candidate or None
        None: the model's own parameters recalibrated (the baseline of the ranking).
    values : dict
        Start values of the candidate's parameters (the screen's estimate).
    known : dict
        Start values of the model's own nonlinear parameters (the screen's refit).
    linear_run : str or None
        A random-excitation file for linear candidates.
    max_iterations : int
    n_starts : int
        Further Latin hypercube starts.
    seed : int
    start_toml : str or None
        The model with the candidate already added and its linear parameters recalibrated on
        the linear test (:mod:`analysis.diagnosis.linear_screen`); used instead of adding it.
    n_harmonics, n_time : int
        Balance settings.
    max_evaluations : int or None
        Evaluations of the objective allowed to the recalibration's Levenberg-Marquardt (the
        last accepted iterate is kept): :class:`~analysis.diagnosis.refit.FitLimits`.
    give_up_chi2 : float or None
        The recalibration stops early when it stays above this chi-square per degree of
        freedom (the model recalibrated without the candidate):
        :func:`~analysis.diagnosis.refit.refit`'s ``give_up_chi2``.
    reweight_passes : int
        Further fits with the weights recomputed at the last fit's values
        (:func:`~analysis.diagnosis.refit.refit`'s ``reweight_passes``).
    reweight_drop : float or None
        The weights recomputed during the fit when it stalls this many times below the metric
        they were computed at (:func:`~analysis.diagnosis.refit.refit`'s ``reweight_drop``).
    """

    model_toml: str
    source: str
    data_path: str
    rows: tuple[int, ...] | None
    candidate: Candidate | None
    values: Mapping[str, float]
    known: Mapping[str, float]
    linear_run: str | None = None
    max_iterations: int = 12
    n_starts: int = 0
    seed: int = 0
    start_toml: str | None = None
    n_harmonics: int = 9
    n_time: int = 128
    max_evaluations: int | None = None
    give_up_chi2: float | None = None
    reweight_passes: int = 0
    reweight_drop: float | None = None


@dataclass
class Verified:
    """A candidate recalibrated in the full model.

    Attributes
    ----------
    candidate : Candidate
    parameters : dict
        Every recalibrated parameter (new and existing) in model units.
    step_chi2 : ndarray, shape (n_steps,)
        ``2 sum |r|^2`` of each step over channels and orders (NaN where the model did not
        converge); ``values_per_step`` real residuals each.
    values_per_step : int
    model_toml : str
        The recalibrated model with the candidate.
    history : list of dict
        LM iterations (``iteration``, ``chi2_per_dof``, ``parameters``).
    linear : dict or None
        The linear recalibration (parameters, metric) of a linear candidate.
    seconds : float
        Wall time.
    message : str
    cpu_seconds : float
        Processor time of the verification (its process's).
    evaluations : int
        Evaluations of the objective by its recalibration
        (:attr:`~analysis.diagnosis.refit.Refit.evaluations`): the work it did.
    """

    candidate: Candidate | None
    parameters: dict[str, float]
    step_chi2: np.ndarray
    values_per_step: int
    model_toml: str
    history: list[dict] = field(default_factory=list)
    linear: dict | None = None
    seconds: float = 0.0
    message: str = ""
    cpu_seconds: float = 0.0
    evaluations: int = 0

    @property
    def failed(self) -> bool:
        return not np.isfinite(self.step_chi2).any()

    def last_decrease(self) -> float:
        """Share by which the last iteration lowered the metric (0 without two)."""
        h = [x["chi2_per_dof"] for x in self.history if np.isfinite(x.get("chi2_per_dof", 0))]
        return 1.0 - h[-1] / h[-2] if len(h) >= 2 and h[-2] > 0 else 0.0

    @property
    def stopped(self) -> bool:
        """The recalibration was stopped (its allowance used, or no better than the bar) before
        it converged."""
        return self.message.startswith("stopped")

    def chi2_per_dof(self, rows: np.ndarray | None = None) -> float:
        z = self.step_chi2 if rows is None else self.step_chi2[rows]
        z = z[np.isfinite(z)]
        if not z.size:
            return np.inf
        return float(z.sum() / (z.size * self.values_per_step))

    def rms_over_noise(self, rows: np.ndarray | None = None) -> float:
        return float(np.sqrt(self.chi2_per_dof(rows)))


def start_distributions(
    model: Model, names: list[str], values: Mapping[str, float]
) -> dict[str, Distribution]:
    """Start distributions: the paper's for the contact, a decade either side of the screen's
    estimate for a new positive parameter, a factor 2 for others (within the bounds)."""
    out: dict[str, Distribution] = {}
    paper = paper_distributions(
        model.parameters["gap"].nominal if "gap" in model.parameters else 1e-3
    )
    for n in names:
        p = model.parameters[n]
        v = float(values.get(n, p.value))
        if n in paper:
            out[n] = paper[n]
        elif v > 0 and p.lower >= 0:
            lo, hi = max(v / 10, p.lower if p.lower > 0 else v / 10), min(10 * v, p.upper)
            out[n] = Distribution("loguniform", lo, max(hi, lo * 1.001))
        else:
            s = abs(v) if v else 1.0
            out[n] = Distribution("uniform", max(v - 2 * s, p.lower), min(v + 2 * s, p.upper))
    return out


def calibration_rows(data) -> np.ndarray:
    """Steps a verification fits: those the rig converged at, on every level but the highest
    where three or more remain, which validates (the paper's 2, 4 and 6 N of four levels, as
    its calibration and :func:`~analysis.diagnosis.augment.augment` do); with fewer levels
    every one (docs/diagnosis.md, the rules table)."""
    levels = sorted(float(x) for x in data.levels_n)
    return fitted_rows(data, levels[:-1] if len(levels) >= 4 else levels)


def band_modes(model: Model, data) -> list[int]:
    """Modes (1-based) whose natural frequency lies in the file's fundamental band."""
    pred = BranchMatchedPredictor(model, data)
    f, _ = pred.model.assemble().normal_modes(20)
    lo, hi = 0.9 * data.frequency_hz.min(), 1.1 * data.frequency_hz.max()
    return [i + 1 for i, x in enumerate(f) if lo <= x <= hi]


def damping_parameters(candidate: Candidate, model: Model, data) -> list[str]:
    """``zeta_<mode>`` names a candidate recalibrates (laws acting at rest, joints)."""
    if candidate.law.kind in ACT_AT_REST or candidate.location.joint is not None:
        return [f"zeta_{m}" for m in band_modes(model, data)]
    return []


def _linear_recalibration(model: Model, run: str, names: list[str]):
    from analysis.calibration.linear import calibrate_linear

    linear = [n for n in model.parameter_names(group="linear", calibrate=True)]
    # the costs of candidates compare only when each fits the same parameters
    res = calibrate_linear(
        model, run, parameters=tuple(linear), min_modes=min(4, len(linear)), weak_parameters="fit"
    )
    info = {"parameters": res.parameters, "cost": res.cost, "n_residuals": int(res.jac.shape[0])}
    del names
    return res.model, info


#: Factors applied to the screen's coefficients of a candidate at unmeasured DOFs for further
#: starts: a screen reads the states there coarsely (docs/diagnosis.md, the rules table).
UNMEASURED_START_FACTORS = (0.5, 2.0)


def _scaled_starts(job: VerifyJob, model: Model) -> list[dict[str, float]]:
    """Further starts of a screened candidate at unmeasured DOFs: its linear coefficients (a
    stiffness, a damping, a slip force; not a clearance) scaled by
    :data:`UNMEASURED_START_FACTORS`."""
    cand = job.candidate
    if cand is None or job.start_toml is not None or cand.is_linear or not job.values:
        return []
    if not cand.location.unmeasured:
        return []
    names = cand.parameter_names()
    coeffs = {
        names[p]: job.values[p]
        for p in cand.law.linear
        if p in job.values and names[p] in model.parameters
    }
    if not coeffs or not any(coeffs.values()):
        return []
    return [{n: v * f for n, v in coeffs.items()} for f in UNMEASURED_START_FACTORS]


def run_verify(job: VerifyJob) -> Verified:
    """Add the candidate, recalibrate, and score the result on the whole file (top level,
    so executors can run it)."""
    t0 = time.perf_counter()
    c0 = time.process_time()
    try:
        v = _verify(job, t0)
    except Exception as exc:  # a worker must return, whatever the candidate does
        label = "the model" if job.candidate is None else job.candidate.label
        log.warning("verification of %s failed: %s", label, exc)
        v = Verified(
            job.candidate,
            {},
            np.full(0, np.nan),
            1,
            "",
            message=str(exc),
            seconds=time.perf_counter() - t0,
        )
    v.cpu_seconds = time.process_time() - c0
    return v


def _verify(job: VerifyJob, t0: float) -> Verified:
    model = Model.from_toml_text(job.model_toml, job.source)
    data = read_measurement(job.data_path)
    cand = job.candidate
    known_names = list(model.parameter_names(group="nonlinear", calibrate=True))
    linear_info = None
    if cand is None:
        m2, new = model, []
    elif job.start_toml is not None:
        m2 = Model.from_toml_text(job.start_toml, job.source)
        new = [n for n in cand.parameter_names().values() if n in m2.parameters]
        linear_info = {"parameters": {n: m2.parameters[n].value for n in new}}
    else:
        m2, new = cand.apply(model, dict(job.values))
        if cand.law.kind == "parameter":
            m2 = m2.with_values({cand.parameter: job.values[cand.parameter]})
        if cand.is_linear and job.linear_run is not None:
            m2, linear_info = _linear_recalibration(m2, job.linear_run, new)
    start = {}
    for n, v in job.known.items():
        if n in m2.parameters:
            p = m2.parameters[n]
            start[n] = float(np.clip(v, p.lower, p.upper))
    m2 = m2.with_values(start)
    damping = [] if cand is None else damping_parameters(cand, m2, data)
    names = list(dict.fromkeys([*new, *known_names, *damping]))
    dists = None
    if job.n_starts:
        plain = [n for n in names if not n.startswith("zeta_")]
        dists = start_distributions(m2, plain, {}) | {
            n: Distribution("loguniform", 0.002, 0.05) for n in names if n.startswith("zeta_")
        }
    rows = calibration_rows(data) if job.rows is None else np.asarray(job.rows, int)
    message, evaluations = "", 0
    try:
        r = refit(
            m2,
            data,
            names,
            rows=rows if rows.size else None,
            starts=Starts(_scaled_starts(job, m2), dists, job.n_starts, seed=job.seed),
            limits=FitLimits(
                max_iterations=job.max_iterations,
                ftol=1e-4,
                max_evaluations=job.max_evaluations,
                give_up_chi2=job.give_up_chi2,
                reweight_passes=job.reweight_passes,
                reweight_drop=job.reweight_drop,
            ),
            n_harmonics=job.n_harmonics,
            n_time=job.n_time,
        )
        fitted, history, params = r.model, r.history, r.parameters
        message = r.lm.message if r.lm is not None else ""
        evaluations = r.evaluations
    except (RuntimeError, ValueError) as exc:
        label = "the model" if cand is None else cand.label
        log.warning("verification of %s failed: %s", label, exc)
        fitted, history, params, message = m2, [], {}, str(exc)
    pred = BranchMatchedPredictor(fitted, data, n_harmonics=job.n_harmonics, n_time=job.n_time)
    cmp = compare(fitted, data, predictor=pred)
    z = np.abs(cmp.residual) ** 2
    step = 2 * z.sum(axis=(1, 2))
    step[~np.all(np.isfinite(z), axis=(1, 2))] = np.nan
    if linear_info is not None:
        params = {**linear_info["parameters"], **params}
    return Verified(
        candidate=cand,
        parameters=params,
        step_chi2=step,
        values_per_step=2 * z.shape[1] * z.shape[2],
        model_toml=fitted.to_toml(),
        history=history,
        linear=linear_info,
        seconds=time.perf_counter() - t0,
        message=message,
        evaluations=evaluations,
    )
