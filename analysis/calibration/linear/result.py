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
        Covariance of the physical parameters, ``D (J^T J)^-1 D s^2`` with ``D = dp/dtheta``
        and the residual variance ``s^2 = 2 cost / (m - n)``. The residuals at neighbouring
        metric frequencies are correlated, so this is a formal (optimistic) figure.
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

    @property
    def std(self) -> dict[str, float]:
        """Standard deviations of the parameters (physical units)."""
        return dict(zip(self.names, np.sqrt(np.diag(self.cov)).tolist(), strict=True))

    @property
    def correlation(self) -> np.ndarray:
        """Correlation matrix of the parameters, shape (n, n)."""
        s = np.sqrt(np.diag(self.cov))
        return self.cov / np.maximum(np.outer(s, s), 1e-300)

    def undetermined(self, max_relative_std: float = 0.05) -> dict[str, float]:
        """Parameters the test does not determine: name -> relative standard deviation, for
        those above ``max_relative_std`` (default 5 %), largest first."""
        rel = {n: self.std[n] / abs(self.parameters[n]) for n in self.names if self.parameters[n]}
        bad = {n: r for n, r in rel.items() if r > max_relative_std}
        return dict(sorted(bad.items(), key=lambda kv: -kv[1]))

    def identifiability_notes(self, max_relative_std: float = 0.05) -> list[str]:
        """Plain-language lines on the parameters the test leaves undetermined: their
        uncertainty, the model modes in the band without a test mode that they act on (the
        measurement that would determine them) and what to do; empty when all are determined."""
        bad = self.undetermined(max_relative_std)
        if not bad:
            return []
        lines = [
            f"  not determined by this test (relative std above {100 * max_relative_std:g} %): "
            + ", ".join(f"{n} ({100 * r:.3g} %)" for n, r in bad.items())
        ]
        for n in bad:
            acts = sorted(
                (m for m in self.unidentified_modes if abs(m["sensitivity"].get(n, 0.0)) > 1e-3),
                key=lambda m: -abs(m["sensitivity"][n]),
            )
            if acts:
                lines.append(
                    f"    {n} acts on model modes the test did not identify (d ln f / d ln {n}): "
                    + ", ".join(f"{m['frequency_hz']:.2f} Hz ({m['sensitivity'][n]:+.3f})"
                                for m in acts[:3])
                )  # fmt: skip
        lines.append(
            "    keep them at their nominal values (calibrate the others with --parameters), "
            "or measure the modes they act on (more response there: level, averages, points)"
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
            "validation": self.validation,
            "settings": self.settings,
            "timings": self.timings,
            "undetermined": self.undetermined(),
            "unidentified_modes": self.unidentified_modes,
        }
