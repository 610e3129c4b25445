"""The result of a linear calibration and its JSON form."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from analysis.calibration.linear.modal_id import ModalFit
from analysis.calibration.linear.mode_matching import ModePair
from analysis.model import Model

__all__ = ["LinearCalibration"]


@dataclass
class LinearCalibration:
    """Result of :func:`~analysis.calibration.linear.calibrate.calibrate_linear`.

    The first fields are those of a scipy optimisation result (in the scaled coordinates of
    :class:`analysis.calibration.parameters.ParameterSpace`).

    Attributes
    ----------
    x : ndarray, shape (n,)
        Scaled solution.
    cost : float
        ``1/2 sum r^2`` of the calibration residuals (log10 units).
    jac : ndarray, shape (m, n)
        Jacobian of the residuals at ``x``.
    cov : ndarray, shape (n, n)
        Covariance of the physical parameters, every parameter's, held ones included: the
        fitted ones' from the data (``covariance_estimator`` says which estimator:
        :func:`~analysis.calibration.linear.calibrate.data_covariance`) plus what the held
        ones' prior uncertainty does to them; a held one's own variance is its prior's.
    nfev, njev, nit : int
        Totals over the damping-continuation stages.
    success : bool
    message : str
        Of the last stage.
    names : tuple of str
    stages : list of dict
        Per continuation stage: ``zeta0, cost, nit, nfev, njev, success, message``.
    parameters, start : dict name -> float
        Calibrated and starting values.
    zeta0 : float
        Equalized damping.
    metric_frequency_hz : ndarray, shape (nk,), Hz
    calibration_channels, validation_channels : tuple of str
    calibration_points, validation_points : tuple of int
    fit : ModalFit
        The identified test modes (receptance, model axes, all motion channels).
    modes : list of ModePair
        Identified modes with damping and their calibrated-model partner.
    validation : dict
        ``{"before": {...}, "after": {...}}`` (see :func:`calibrate_linear`).
    model : Model
        The calibrated model (values replaced, ``DampingSpec.per_mode`` from the identified
        damping).
    settings : dict
    timings : dict of str to float, s
    status : dict name -> str
        ``"fitted"``; ``"held"`` (at its nominal value with its prior uncertainty: the test
        does not determine it better than the prior, or it ran to a bound); ``"at_bound"``
        (ran to a bound and no prior is known: held at nominal, uncertainty unknown).
    status_reason : dict name -> str
        Why each parameter that is not fitted is held.
    prior_rel_std : dict name -> float or None
        The model file's priors.
    covariance_estimator : str
    damping_rel_std : dict int -> float
        Relative standard deviation of each mode's identified damping ratio (the pole fit's),
        by the calibrated model's mode number as in ``damping``.
    unidentified_modes : list of dict
        Modes of the calibrated model (with the sensors) inside the band that no test mode was
        paired with: ``model_mode``, ``frequency_hz`` and ``sensitivity`` (name ->
        ``d ln f / d ln p`` of each calibrated parameter; ``model_mode`` 1-based as in
        :class:`~analysis.calibration.linear.mode_matching.ModePair`). The parameters that act
        mainly on them are what the test leaves undetermined (:meth:`undetermined`).
    """

    x: np.ndarray
    cost: float
    jac: np.ndarray
    cov: np.ndarray
    nfev: int
    njev: int
    nit: int
    success: bool
    message: str
    names: tuple[str, ...]
    stages: list[dict[str, Any]]
    parameters: dict[str, float]
    start: dict[str, float]
    zeta0: float
    metric_frequency_hz: np.ndarray
    calibration_channels: tuple[str, ...]
    validation_channels: tuple[str, ...]
    calibration_points: tuple[int, ...]
    validation_points: tuple[int, ...]
    fit: ModalFit
    modes: list[ModePair]
    validation: dict[str, dict[str, Any]]
    model: Model
    settings: dict[str, Any]
    source: str = ""
    timings: dict[str, float] = field(default_factory=dict)
    unidentified_modes: list[dict[str, Any]] = field(default_factory=list)
    status: dict[str, str] = field(default_factory=dict)
    status_reason: dict[str, str] = field(default_factory=dict)
    prior_rel_std: dict[str, float | None] = field(default_factory=dict)
    covariance_estimator: str = ""
    damping_rel_std: dict[int, float] = field(default_factory=dict)

    @property
    def std(self) -> dict[str, float]:
        """Standard deviations of the parameters (physical units)."""
        return dict(zip(self.names, np.sqrt(np.diag(self.cov)).tolist(), strict=True))

    @property
    def correlation(self) -> np.ndarray:
        """Correlation matrix of the parameters, shape (n, n)."""
        s = np.sqrt(np.diag(self.cov))
        return self.cov / np.maximum(np.outer(s, s), 1e-300)

    def held(self) -> dict[str, str]:
        """Parameters not fitted (held at their nominal value): name -> why."""
        return {
            n: self.status_reason.get(n, "")
            for n in self.names
            if self.status.get(n, "fitted") != "fitted"
        }

    def undetermined(self, max_relative_std: float = 0.05) -> dict[str, float]:
        """Parameters the test leaves uncertain: name -> relative standard deviation, for the
        held ones and the fitted ones above ``max_relative_std`` (default 5 %), largest
        first (NaN: a held parameter with no known prior)."""
        rel = {n: self.std[n] / abs(self.parameters[n]) for n in self.names if self.parameters[n]}
        bad = {n: r for n, r in rel.items() if n in self.held() or not r <= max_relative_std}
        return dict(sorted(bad.items(), key=lambda kv: -kv[1] if np.isfinite(kv[1]) else -np.inf))

    def identifiability_notes(self, max_relative_std: float = 0.05) -> list[str]:
        """Plain-language lines on the parameters the test does not determine: which are
        held at their prior and why, which are fitted but uncertain, the model modes in the
        band without a test mode that they act on (the measurement that would determine
        them); empty when all are determined."""
        bad = self.undetermined(max_relative_std)
        if not bad:
            return []
        held = self.held()
        lines = [f"  held at its nominal value: {n}: {why}" for n, why in held.items()]
        loose = {n: r for n, r in bad.items() if n not in held}
        if loose:
            lines.append(
                f"  fitted, but uncertain (relative std above {100 * max_relative_std:g} %, held "
                "parameters' priors included): "
                + ", ".join(f"{n} ({100 * r:.3g} %)" for n, r in loose.items())
            )
        for n in bad:
            acts = sorted(
                (m for m in self.unidentified_modes if abs(m["sensitivity"].get(n, 0.0)) > 1e-3),
                key=lambda m: -abs(m["sensitivity"][n]),
            )
            if acts:
                lines.append(
                    f"    {n} acts on model modes the test did not identify (d ln f / d ln {n}): "
                    + ", ".join(
                        f"{m['frequency_hz']:.2f} Hz ({m['sensitivity'][n]:+.3f})" for m in acts[:3]
                    )
                )
        lines.append(
            "    to determine them: measure the modes they act on (more response there: "
            "level, averages, points); their uncertainty is carried into every later result"
        )
        return lines

    @property
    def damping(self) -> dict[int, float]:
        """Identified damping ratio by model mode number (the calibrated model's ``per_mode``)."""
        return dict(self.model.damping.per_mode)

    def save_model(self, path: str | Path) -> Path:
        """Write the calibrated model file (a new file; the input model file is untouched)."""
        return self.model.save(path)

    def to_json(self) -> dict[str, Any]:
        """Everything as JSON-ready types."""
        return {
            "source": self.source,
            "success": self.success,
            "message": self.message,
            "cost": self.cost,
            "nfev": self.nfev,
            "njev": self.njev,
            "nit": self.nit,
            "names": list(self.names),
            "stages": self.stages,
            "parameters": self.parameters,
            "start": self.start,
            "std": self.std,
            "cov": self.cov.tolist(),
            "correlation": self.correlation.tolist(),
            "zeta0": self.zeta0,
            "n_residuals": int(self.jac.shape[0]),
            "metric_frequency_hz": self.metric_frequency_hz.tolist(),
            "calibration_channels": list(self.calibration_channels),
            "validation_channels": list(self.validation_channels),
            "calibration_points": list(self.calibration_points),
            "validation_points": list(self.validation_points),
            "identified_modes": {
                "band_hz": list(self.fit.band_hz),
                "rms_relative_error": self.fit.rms_relative_error,
                "modes": [m.to_json() for m in self.modes],
            },
            "damping_per_mode": {str(k): v for k, v in self.damping.items()},
            "damping_rel_std": {str(k): v for k, v in self.damping_rel_std.items()},
            "validation": self.validation,
            "settings": self.settings,
            "timings": self.timings,
            "undetermined": self.undetermined(),
            "status": {n: self.status.get(n, "fitted") for n in self.names},
            "status_reason": self.status_reason,
            "held": self.held(),
            "prior_rel_std": self.prior_rel_std,
            "covariance_estimator": self.covariance_estimator,
            "units": {n: self.model.parameters[n].unit for n in self.names},
            "interval_95": {
                n: [self.parameters[n] - 1.96 * sd, self.parameters[n] + 1.96 * sd]
                for n, sd in self.std.items()
            },
            "unidentified_modes": self.unidentified_modes,
        }
