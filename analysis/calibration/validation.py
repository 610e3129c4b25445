"""Validation of a calibrated model at a level not used in the calibration.

The model predicts the held-out FRFs with an uncertainty band from the parameter covariance
(linearised: ``var = d^T C d`` for the real and imaginary parts), and each prediction is judged
against the measurement uncertainty: ``z = |H_model - H_meas| / sqrt(s_meas^2 + s_model^2)``.
The verdict passes when the mean of ``z^2`` (the chi-square per degree of freedom: two per
complex value, each real part with half the complex variance) is at most ``threshold``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from analysis.calibration.modal_damping import DampedPredictor
from analysis.calibration.nonlinear import NonlinearCalibration, fitted_rows, make_predictor
from analysis.calibration.uncertainty import ADEQUATE_RMS
from analysis.measurement_file import SteppedSineData
from analysis.model import Model

__all__ = ["Validation", "validate"]

log = logging.getLogger(__name__)


@dataclass
class Validation:
    """Prediction of held-out FRFs with bands and a verdict.

    Attributes
    ----------
    rows : ndarray of int
        Steps validated.
    frequency_hz : ndarray, shape (n,)
    measured, predicted : ndarray, shape (n, n_channels, n_orders), complex
    measured_std, predicted_std : ndarray, shape (n, n_channels, n_orders)
        Standard errors (complex magnitude) of measurement and prediction.
    chi2_per_dof : float
    passed : bool
    """

    level_n: float
    channels: list[str]
    rows: np.ndarray
    frequency_hz: np.ndarray
    measured: np.ndarray
    measured_std: np.ndarray
    predicted: np.ndarray
    predicted_std: np.ndarray
    chi2_per_dof: float
    within_2sigma: float
    threshold: float
    passed: bool

    def summary(self) -> str:
        verdict = "PASS" if self.passed else "FAIL"
        return (
            f"validation at {self.level_n:g} N: {verdict} - chi2/dof {self.chi2_per_dof:.2f} "
            f"(threshold {self.threshold:g}), {100 * self.within_2sigma:.0f} % of FRF values "
            f"within 2 sigma"
        )

    def to_json(self) -> dict:
        return {
            "level_n": self.level_n,
            "channels": self.channels,
            "chi2_per_dof": self.chi2_per_dof,
            "within_2sigma": self.within_2sigma,
            "threshold": self.threshold,
            "passed": self.passed,
            "n_steps": int(self.rows.size),
        }


def validate(
    model: Model,
    data: SteppedSineData,
    calibration: NonlinearCalibration,
    *,
    level_n: float | None = None,
    threshold: float = ADEQUATE_RMS**2,
) -> Validation:
    """Predict the held-out level with uncertainty bands and judge it.

    Parameters
    ----------
    model : Model
        The model before calibration (the calibrated values are applied here).
    level_n : float, optional
        Level to validate (default: the calibration's validation level).
    threshold : float
        Largest chi-square per degree of freedom that passes (default: the square of
        :data:`~analysis.calibration.uncertainty.ADEQUATE_RMS`, as every analysis judges).
    """
    lv = calibration.validation_level_n if level_n is None else level_n
    if lv is None:
        raise ValueError("no validation level: the file has a single level; name one")
    st = calibration.settings
    rows = fitted_rows(data, [lv], st.include_unconverged)
    names, C = calibration.joint_covariance()
    base = calibration.conditioned(model)
    if len(names) > calibration.space.size:  # the held values' uncertainty reaches the bands
        pred = DampedPredictor(
            base, data, channels=st.channels, n_harmonics=st.n_harmonics, n_time=st.n_time
        )
        if not st.match_branches:
            log.info("validation: the bands use the branch-matched prediction")
    else:
        pred = make_predictor(base, data, st)
    values = {**(calibration.held_posterior or {}), **calibration.parameters}
    p = pred.predict({n: values[n] for n in names}, list(names), rows=rows)
    H, sH = pred.measured()
    dre = np.stack([p.d_frf[n][rows].real for n in names], axis=-1)
    dim = np.stack([p.d_frf[n][rows].imag for n in names], axis=-1)
    var_model = np.einsum("...i,ij,...j->...", dre, C, dre) + np.einsum(
        "...i,ij,...j->...", dim, C, dim
    )
    s_model = np.sqrt(np.maximum(var_model, 0))
    diff = p.frf[rows] - H[rows]
    s_tot2 = sH[rows] ** 2 + var_model
    floor = np.nanmax(s_tot2) * 1e-12 + 1e-300
    z2 = np.abs(diff) ** 2 / np.maximum(s_tot2, floor)
    ok = np.isfinite(z2)
    chi2 = float(z2[ok].mean())  # two degrees of freedom per complex value, each E = 1/2
    within = float((z2[ok] <= 4.0).mean())
    return Validation(
        level_n=float(lv),
        channels=list(pred.channel_names),
        rows=rows,
        frequency_hz=data.frequency_hz[rows],
        measured=H[rows],
        measured_std=sH[rows],
        predicted=p.frf[rows],
        predicted_std=s_model,
        chi2_per_dof=chi2,
        within_2sigma=within,
        threshold=threshold,
        passed=bool(chi2 <= threshold),
    )
