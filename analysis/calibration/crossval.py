"""K-fold cross-validation of a nonlinear calibration (paper sec. 2.4).

The calibration data are split into K subsamples, by default one sensor at one level each
(3 levels x 3 sensors = 9 in the paper). Each fold recalibrates on the other K-1 subsamples with
undamped Gauss-Newton started from the optimum; the K estimates give the parameter mean and a
jackknife-scaled covariance ``(K-1)/K sum (p_k - p_mean)(p_k - p_mean)^T``, compared with the
inverse Fisher information of the full calibration.

References
----------
B. Efron, C. Stein, "The jackknife estimate of variance", Ann. Statist. 9 (1981) 586-596.
"""

from __future__ import annotations

import concurrent.futures as cf
import logging
import time
from dataclasses import dataclass, field

import numpy as np

from analysis.calibration.lm import least_squares_lm
from analysis.calibration.nonlinear import (
    NonlinearCalibration,
    ObjectiveSpec,
    fitted_rows,
    make_predictor,
)
from analysis.measurement_file import SteppedSineData
from analysis.model import Model

__all__ = ["CrossValidation", "cross_validate"]

log = logging.getLogger(__name__)


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
        Standard deviations from the inverse Fisher information of the full calibration.
    iterations : list of int
        Accepted Gauss-Newton steps of each fold.
    stuck : list of str
        Folds whose Gauss-Newton iteration could not leave the calibrated optimum (no step
        reduced their cost): their estimates carry no scatter, and the standard deviations
        understate the uncertainty.
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

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    @property
    def std_ratio(self) -> np.ndarray:
        """Cross-validation std / FIM^-1 std per parameter."""
        return self.std / self.fim_std

    def to_json(self) -> dict:
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
        }


def _fold(spec: ObjectiveSpec, theta0: np.ndarray, bounds, max_iterations: int):
    obj = spec.build()
    res = least_squares_lm(obj, theta0, bounds=bounds, damped=False, max_iterations=max_iterations)
    return res.x, len(res.history) - 1


def cross_validate(
    model: Model,
    data: SteppedSineData,
    calibration: NonlinearCalibration,
    *,
    executor: cf.Executor | None = None,
    max_iterations: int = 20,
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
    """
    t0 = time.perf_counter()
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
    if executor is None:
        out = [_fold(s, x0, bounds, max_iterations) for s in specs]
    else:
        futures = [executor.submit(_fold, s, x0, bounds, max_iterations) for s in specs]
        out = [f.result() for f in futures]
    stuck = [name for name, (_, accepted) in zip(folds, out, strict=True) if accepted == 0]
    if stuck:
        log.warning(
            "cross-validation: %d of %d folds could not leave the calibrated optimum (%s): "
            "the standard deviations understate the uncertainty",
            len(stuck), len(out), ", ".join(stuck[:4]) + (" ..." if len(stuck) > 4 else ""),
        )  # fmt: skip
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
        fim_std=np.sqrt(np.diag(calibration.cov)),
        iterations=[it for _, it in out],
        seconds=time.perf_counter() - t0,
        stuck=stuck,
    )
