"""K-fold cross-validation of a nonlinear calibration (paper sec. 2.4).

The calibration data are split into K subsamples, by default one sensor at one level each
(3 levels x 3 sensors = 9 in the paper). Each fold recalibrates on the other K-1 subsamples with
undamped Gauss-Newton started from the optimum; the K estimates give the parameter mean and a
jackknife-scaled covariance ``(K-1)/K sum (p_k - p_mean)(p_k - p_mean)^T``, compared with the
inverse Fisher information of the full calibration.

When the two disagree, the result says why it can: each fold's misfit at the calibrated optimum
(chi-square per value with its p-value: a fold the model cannot fit is a systematic model
error, which FIM^-1 does not know about) and each fold's share of every parameter's
information (deleting a fold that carries most of it moves the estimate by more than its noise:
the jackknife over unequal folds overstates the scatter, Efron and Stein).

References
----------
B. Efron, C. Stein, "The jackknife estimate of variance", Ann. Statist. 9 (1981) 586-596.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import functools
import logging
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from analysis.calibration.lm import least_squares_lm
from analysis.calibration.nonlinear import (
    NonlinearCalibration,
    ObjectiveSpec,
    fitted_rows,
    make_predictor,
)
from analysis.calibration.objective import FRFObjective
from analysis.calibration.uncertainty import adequate
from analysis.events import Listener, UnitDone
from analysis.executors import run_jobs
from analysis.measurement_file import SteppedSineData
from analysis.model import Model

__all__ = ["FOLDS_STAGE", "CrossValidation", "cross_validate"]

log = logging.getLogger(__name__)

#: The stage name of the folds in the cross-validation's events.
FOLDS_STAGE = "cross-validation folds"


@dataclass
class CrossValidation:
    """Result of :func:`cross_validate`.

    Attributes
    ----------
    folds : list of str
        What each fold leaves out (``"acc7 @ 4 N"``).
    estimates : ndarray, shape (K, n)
        Parameters of each fold (physical units).
    mean : ndarray, shape (n,)
    cov : ndarray, shape (n, n)
        Jackknife-scaled covariance.
    fim_std : ndarray, shape (n,)
        Standard deviations from the inverse Fisher information of the full calibration (the
        noise-only ones, ``cov_noise``).
    iterations : list of int
        Accepted Gauss-Newton steps of each fold.
    stuck : list of str
        Folds whose Gauss-Newton iteration could not leave the calibrated optimum (no step
        reduced their cost): their estimates carry no scatter, and the standard deviations
        understate the uncertainty.
    fold_chi2 : ndarray, shape (K,)
        Chi-square per value of each fold's FRFs at the calibrated optimum (with the
        calibration's weights; about 1 where the model fits within the file's uncertainties).
    fold_p : ndarray, shape (K,)
        Probability of a chi-square at least that large from noise alone (NaN under identity
        weighting, which has no noise scale).
    information_share : ndarray, shape (K, n)
        Each fold's share of each parameter's Fisher information (diagonal; columns sum to 1).
    """

    names: tuple[str, ...]
    folds: list[str]
    estimates: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    fim_std: np.ndarray
    iterations: list[int]
    seconds: float
    stuck: list[str] = field(default_factory=list)
    fold_chi2: np.ndarray | None = None
    fold_p: np.ndarray | None = None
    information_share: np.ndarray | None = None

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    @property
    def std_ratio(self) -> np.ndarray:
        """Cross-validation std / FIM^-1 std per parameter."""
        return self.std / self.fim_std

    def misfit_folds(self, alpha: float = 1e-3) -> list[int]:
        """Folds the calibrated model does not fit, worst first: beyond
        :data:`~analysis.calibration.uncertainty.ADEQUATE_RMS` of the noise (the threshold
        every analysis uses) and improbable from the noise alone (probability below
        ``alpha``)."""
        if self.fold_p is None:
            return []
        bad = [
            j
            for j, p in enumerate(self.fold_p)
            if np.isfinite(p) and p < alpha and not adequate(np.sqrt(self.fold_chi2[j]))
        ]
        return sorted(bad, key=lambda j: -self.fold_chi2[j])

    def notes(self, low: float = 0.5, high: float = 2.0, alpha: float = 1e-3) -> list[str]:
        """Why a parameter's cross-validation scatter departs from FIM^-1 (outside
        ``[low, high]`` times), from the fold diagnostics; empty when all agree."""
        out: list[str] = []
        bad = self.misfit_folds(alpha)
        for i, (name, ratio) in enumerate(zip(self.names, self.std_ratio, strict=True)):
            if not np.isfinite(ratio) or low <= ratio <= high:
                continue
            if ratio < low:
                why = (
                    f"{len(self.stuck)} fold(s) did not move"
                    if self.stuck
                    else "the file's uncertainties may overstate the noise"
                )
                out.append(f"{name}: the folds scatter {ratio:.2f} x FIM^-1 (below {low:g}): {why}")
                continue
            text = f"{name}: the folds scatter {ratio:.2f} x more than FIM^-1 predicts"
            if bad:
                worst = ", ".join(
                    f"{self.folds[j]} (chi2/value {self.fold_chi2[j]:.2f}, p {self.fold_p[j]:.1g})"
                    for j in bad[:3]
                )
                text += (
                    f". The calibrated model misfits {worst}: a systematic model error there"
                    " (e.g. in the fixed linear part), which FIM^-1, computed for an exact"
                    " model, leaves out; `compare` and `diagnose` show where"
                )
            if self.information_share is not None:
                j = int(np.argmax(self.information_share[:, i]))
                share = self.information_share[j, i]
                if share > 0.5:  # deleting it at least doubles the move (1 / (1 - share))
                    text += (
                        f". {self.folds[j]} carries {100 * share:.0f} % of its information:"
                        " deleting a fold that large moves the estimate by more than its noise"
                        " (the jackknife over unequal folds overstates the scatter)"
                    )
            out.append(text)
        return out

    def to_json(self) -> dict:
        def listed(a):  # NaN (no value) as null
            if a is None:
                return None
            return np.where(np.isfinite(a), a, None).tolist()

        return {
            "names": list(self.names),
            "folds": self.folds,
            "estimates": self.estimates.tolist(),
            "mean": self.mean.tolist(),
            "cov": self.cov.tolist(),
            "std": self.std.tolist(),
            "fim_std": self.fim_std.tolist(),
            "std_ratio": self.std_ratio.tolist(),
            "iterations": self.iterations,
            "seconds": self.seconds,
            "stuck": self.stuck,
            "fold_chi2": listed(self.fold_chi2),
            "fold_p": listed(self.fold_p),
            "information_share": listed(self.information_share),
            "notes": self.notes(),
        }


class _Started:
    """A fold's objective whose residuals and Jacobian at the start are given: every fold starts
    at the calibrated optimum, where the predictions of all folds are those of the full
    calibration (a fold leaves out FRFs, not steps' solutions), so they are made once."""

    def __init__(self, objective: FRFObjective, theta0: np.ndarray, r0, J0) -> None:
        self.objective, self.theta0, self.r0, self.J0 = objective, theta0, r0, J0

    def __call__(self, theta, want_jac: bool = True):
        if self.r0 is not None and np.array_equal(theta, self.theta0):
            return self.r0, (self.J0 if want_jac else None)
        return self.objective(theta, want_jac)


def _fold(spec: ObjectiveSpec, theta0: np.ndarray, bounds, max_iterations: int, start=None):
    """One fold's Gauss-Newton from ``theta0``; ``start`` the full objective's ``(r, J, index)``
    there (``index`` picks the fold's residuals from them), or None."""
    obj = spec.build()
    r0 = J0 = None
    if start is not None:
        r, J, index = start
        r0, J0 = r[index], J[index]
    fun = _Started(obj, theta0, r0, J0)
    res = least_squares_lm(
        fun,
        theta0,
        bounds=bounds,
        damped=False,
        max_iterations=max_iterations,
        trial_cost=obj.bounded_cost,
    )
    return res.x, len(res.history) - 1


def residual_index(full_mask: np.ndarray, fold_mask: np.ndarray, n_orders: int) -> np.ndarray:
    """Positions in :class:`FRFObjective` residuals over ``full_mask`` of those over
    ``fold_mask`` (a subset): real parts of the selected FRFs' orders, then imaginary parts."""
    keep = np.repeat(fold_mask[full_mask], n_orders)
    idx = np.flatnonzero(keep)
    return np.concatenate([idx, keep.size + idx])


def cross_validate(
    model: Model,
    data: SteppedSineData,
    calibration: NonlinearCalibration,
    *,
    executor: cf.Executor | None = None,
    max_iterations: int = 20,
    progress: Listener | None = None,
) -> CrossValidation:
    """K-fold cross-validation started from the calibrated optimum.

    Parameters
    ----------
    model : Model
        The model that was calibrated (before the calibrated values).
    data : SteppedSineData
    calibration : NonlinearCalibration
    executor : concurrent.futures.Executor, optional
        Runs the folds in parallel.
    progress : callable, optional
        Receives a :class:`analysis.events.UnitDone` (stage :data:`FOLDS_STAGE`) as folds
        finish, and one with ``done`` 0 when they start.
    """
    t0 = time.perf_counter()
    model = calibration.conditioned(model)
    st = calibration.settings
    space = calibration.space
    pred = make_predictor(model, data, st)
    folds, masks = [], []
    for lv in calibration.calibration_levels_n:
        rows = fitted_rows(data, [lv], st.include_unconverged)
        for c, name in enumerate(pred.channel_names):
            folds.append(f"{name} @ {lv:g} N")
            masks.append((rows, c))
    base = np.zeros((data.n_steps, len(pred.channel_names)), bool)
    base[fitted_rows(data, calibration.calibration_levels_n, st.include_unconverged)] = True
    specs = []
    for rows, c in masks:
        m = base.copy()
        m[rows, c] = False
        specs.append(
            ObjectiveSpec(
                model.to_toml(),
                str(data.path),
                space.names,
                m,
                st.weighting,
                st.channels,
                st.n_harmonics,
                st.n_time,
                st.match_branches,
            )
        )
    bounds = space.theta_bounds()
    x0 = calibration.lm.x
    tick = (lambda k: progress(UnitDone(FOLDS_STAGE, k, len(specs)))) if progress else None
    if tick:
        tick(0)  # the clock starts here: folds run side by side
    full = dataclasses.replace(specs[0], mask=base).build()
    r0, J0 = full(x0)
    jobs = [
        (
            spec,
            None
            if J0 is None
            else (r0, J0, residual_index(full.mask, spec.mask & full.mask, full.H.shape[2])),
        )
        for spec in specs
    ]
    job = functools.partial(_fold_job, theta0=x0, bounds=bounds, max_iterations=max_iterations)
    out = run_jobs(job, jobs, executor, tick)
    stuck = [name for name, (_, accepted) in zip(folds, out, strict=True) if accepted == 0]
    if stuck:
        log.warning(
            "cross-validation: %d of %d folds could not leave the calibrated optimum (%s): "
            "the standard deviations understate the uncertainty",
            len(stuck),
            len(out),
            ", ".join(stuck[:4]) + (" ..." if len(stuck) > 4 else ""),
        )
    fold_chi2, fold_p, share = _fold_diagnostics(full, r0, J0, masks)
    est = np.array([space.to_physical(x) for x, _ in out])
    K = len(est)
    mean = est.mean(axis=0)
    dev = est - mean
    cov = (K - 1) / K * dev.T @ dev
    return CrossValidation(
        names=space.names,
        folds=folds,
        estimates=est,
        mean=mean,
        cov=cov,
        fim_std=np.sqrt(np.diag(calibration.cov_noise)),
        iterations=[it for _, it in out],
        seconds=time.perf_counter() - t0,
        stuck=stuck,
        fold_chi2=fold_chi2,
        fold_p=fold_p,
        information_share=share,
    )


def _fold_job(job, theta0, bounds, max_iterations: int):
    spec, start = job
    return _fold(spec, theta0, bounds, max_iterations, start)


def _fold_diagnostics(obj: FRFObjective, r, J, masks):
    """Per fold: chi-square per value of the residuals ``r`` (Jacobian ``J``) of ``obj`` at the
    calibrated optimum, its noise-only p-value and the fold's share of each parameter's
    (diagonal) Fisher information. ``masks`` are ``(rows, channel)``."""
    K = len(masks)
    if J is None or not np.all(np.isfinite(r)):
        log.warning(
            "cross-validation: the calibrated model did not converge on every step; "
            "no fold diagnostics"
        )
        return None, None, None
    label = np.full(obj.mask.shape, -1)
    for j, (rows, c) in enumerate(masks):
        label[rows, c] = j
    per_value = np.repeat(label[obj.mask], obj.H.shape[2])
    per_value = np.concatenate([per_value, per_value])  # real parts, then imaginary parts
    chi2 = np.full(K, np.nan)
    p = np.full(K, np.nan)
    info = np.zeros((K, J.shape[1]))
    for j in range(K):
        sel = per_value == j
        if not sel.any():
            continue
        ss = float(r[sel] @ r[sel])
        chi2[j] = ss / sel.sum()
        if obj.weighting == "uncertainty":
            p[j] = stats.chi2.sf(ss, sel.sum())
        info[j] = np.sum(J[sel] ** 2, axis=0)
    total = info.sum(axis=0)
    share = info / np.where(total > 0, total, 1.0)
    return chi2, p, share
