"""What a calibrated value's stated uncertainty includes, and when a model is adequate.

The nonlinear calibration fits a few parameters (k_c, gap, v_c) of a model whose other values
were calibrated before, on another test (the linear parameters, the modal damping). Its
reported covariance is the sum of

* the noise's, ``(J^T W J)^-1`` of the uncertainty-weighted metric (``cov_noise``: the
  inverse Fisher information; what the cross-validation compares its folds' scatter with),
  scaled per parameter by the larger of the Birge ratio ``sqrt(chi2/dof)`` (a misfit the noise
  does not explain) and the folds' scatter over it (:func:`noise_scale`);
* what the held values' uncertainty does to the fitted ones (:func:`propagate_held`): a held
  value off by ``db`` moves the fit by ``G db``, ``G = -(J_a^T W J_a)^-1 J_a^T W J_b``, so
  ``G C_b G^T`` (``C_b``: the held values' covariance, from the linear calibration's result or
  the model file's priors, :class:`HeldParameters`).

A model is *adequate* where its residual is within :data:`ADEQUATE_RMS` of the noise: every
analysis (calibration, cross-validation, validation, comparison, diagnosis) uses that one
threshold, so none calls a model adequate that another finds misfitting.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from analysis.calibration.modal_damping import ZETA, DampedPredictor, damped_space, zeta_name
from analysis.calibration.objective import FRFObjective
from analysis.model import Model

__all__ = [
    "ADEQUATE_RMS",
    "HeldParameters",
    "adequate",
    "damping_modes_in_band",
    "held_for_run",
    "held_from_linear_result",
    "held_from_priors",
    "noise_scale",
    "propagate_held",
]

log = logging.getLogger(__name__)

ADEQUATE_RMS = 1.5
"""Largest root of chi-square per degree of freedom (RMS residual over the noise) at which a
model is adequate. At 1.5 the model error is about as large as the noise (``sqrt(1.5^2 - 1)
= 1.1`` times it): the file's standard errors are themselves estimates (48 periods: about 10 %
each) and a fit is never exact, so a model is not rejected for that; the stated intervals are
widened by the misfit (:func:`noise_scale`). Beyond it the model misses an effect whose error
has a structure no scale factor describes: intervals are then not to be trusted, and the
diagnosis looks for the missing effect."""


def adequate(rms_over_noise: float) -> bool:
    """Whether a residual of ``rms_over_noise`` (root of chi-square per degree of freedom) is
    within :data:`ADEQUATE_RMS`."""
    return bool(np.isfinite(rms_over_noise) and rms_over_noise <= ADEQUATE_RMS)


@dataclass(frozen=True)
class HeldParameters:
    """Parameters a calibration holds at their values, and how uncertain those values are.

    Attributes
    ----------
    names : tuple of str
        Model parameters and modal damping ratios (``zeta_<mode>``,
        :mod:`analysis.calibration.modal_damping`).
    values : dict name -> float
        The values held (the model's).
    cov : ndarray, shape (k, k)
        Their covariance, physical units.
    source : str
        Where the covariance comes from.
    notes : tuple of str
        What was left out, and why.
    """

    names: tuple[str, ...]
    values: dict[str, float]
    cov: np.ndarray
    source: str
    notes: tuple[str, ...] = ()

    @property
    def std(self) -> dict[str, float]:
        return dict(zip(self.names, np.sqrt(np.diag(self.cov)).tolist(), strict=True))

    def to_json(self) -> dict[str, Any]:
        return {
            "names": list(self.names),
            "values": self.values,
            "std": self.std,
            "cov": self.cov.tolist(),
            "source": self.source,
            "notes": list(self.notes),
        }

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> HeldParameters:
        return cls(
            names=tuple(doc["names"]),
            values={k: float(v) for k, v in doc["values"].items()},
            cov=np.array(doc["cov"], dtype=float),
            source=str(doc.get("source", "")),
            notes=tuple(doc.get("notes", ())),
        )


def _current(model: Model, name: str) -> float:
    if name.startswith(ZETA):
        mode = int(name[len(ZETA) :])
        return float(model.damping.per_mode.get(mode, model.damping.default_zeta))
    return float(model.parameters[name].value)


#: Smallest relative standard deviation stated for an identified modal damping ratio. The
#: pole fit's own standard error counts the noise only; the identified damping of a lightly
#: damped mode also moves with the modal model's order, band and residual terms by a few
#: percent (more than that standard error), so 2 % is the least uncertainty it is given.
IDENTIFIED_DAMPING_REL_FLOOR = 0.02

#: Standard deviation of ``ln zeta`` for a mode near the test's band whose damping the linear
#: test did not identify: it is the model's default (``[damping] default_zeta``), known only to
#: a factor of about e either way (structural damping of a bolted and welded steel frame on
#: rubber mounts lies between about 0.2 % and 5 %).
UNIDENTIFIED_DAMPING_LOG_STD = 1.0


def _with_damping(
    model: Model,
    names: list[str],
    cov: np.ndarray,
    modes: Iterable[int],
    rel_std: Mapping[int, float],
    notes: list[str],
):
    """``names``/``cov`` with the modal damping ratios of ``modes`` appended, independent of
    the rest: an identified one (in ``rel_std``) with its relative standard deviation, at
    least :data:`IDENTIFIED_DAMPING_REL_FLOOR`; one the linear test did not identify with
    :data:`UNIDENTIFIED_DAMPING_LOG_STD` about the model's default."""
    extra, var = [], []
    for mode in modes:
        zeta = _current(model, zeta_name(mode))
        r = rel_std.get(mode)
        if r is not None and np.isfinite(r):
            r = max(r, IDENTIFIED_DAMPING_REL_FLOOR)
        else:
            r = UNIDENTIFIED_DAMPING_LOG_STD
            notes.append(
                f"mode {mode}'s damping was not identified: {zeta:.3g} (the default) known to "
                f"a factor e^{UNIDENTIFIED_DAMPING_LOG_STD:g}"
            )
        extra.append(zeta_name(mode))
        var.append((r * zeta) ** 2)
    k = len(names)
    full = np.zeros((k + len(extra), k + len(extra)))
    full[:k, :k] = cov
    full[k:, k:] = np.diag(var)
    return names + extra, full


def held_from_linear_result(
    doc: Mapping[str, Any], model: Model, modes: Iterable[int] = (), source: str = ""
) -> HeldParameters:
    """The linear calibration's parameters and identified modal damping of ``modes`` with the
    uncertainty its result states (``linear_calibration.json`` as a dict): the full covariance
    of the linear parameters (held ones with their prior's) and each damping ratio's relative
    standard deviation.

    Raises
    ------
    ValueError
        When the model does not hold the result's calibrated values (another model).
    """
    names = [str(n) for n in doc["names"]]
    cov = np.array(doc["cov"], dtype=float)
    notes: list[str] = []
    for n in names:
        if n not in model.parameters:
            raise ValueError(f"{source}: parameter {n!r} of the linear result is not in the model")
        want, have = float(doc["parameters"][n]), model.parameters[n].value
        if not np.isclose(want, have, rtol=1e-9, atol=0.0):
            raise ValueError(
                f"{source}: the model's {n} = {have:.6g} is not the linear calibration's "
                f"{want:.6g}: give the model file that calibration wrote"
            )
    unknown = [i for i, n in enumerate(names) if not np.isfinite(cov[i, i])]
    for i in unknown:
        notes.append(f"{names[i]}: the linear calibration states no uncertainty, held as exact")
    keep = [i for i in range(len(names)) if i not in unknown]
    names = [names[i] for i in keep]
    cov = cov[np.ix_(keep, keep)]
    rel = {int(k): float(v) for k, v in doc.get("damping_rel_std", {}).items()}
    names, cov = _with_damping(model, names, cov, modes, rel, notes)
    return HeldParameters(
        names=tuple(names),
        values={n: _current(model, n) for n in names},
        cov=cov,
        source=f"the linear calibration {source}".strip(),
        notes=tuple(notes),
    )


def held_for_run(doc: Mapping[str, Any], model: Model, data, source: str = "") -> HeldParameters:
    """:func:`held_from_linear_result` with the modes whose damping a stepped-sine run ``data``
    feels (:func:`damping_modes_in_band` over its frequencies and orders)."""
    band = (float(data.frequency_hz.min()), float(data.frequency_hz.max()))
    modes = damping_modes_in_band(model, band, max(float(o) for o in data.orders))
    return held_from_linear_result(doc, model, modes, source=source)


def held_from_priors(model: Model) -> HeldParameters | None:
    """The linear parameters with a prior in the model file (``prior_rel_std``), independent,
    each with its prior standard deviation about its value; None when none has one."""
    names = [n for n in model.parameter_names("linear") if model.parameters[n].prior_rel_std]
    if not names:
        return None
    var = []
    for n in names:
        p = model.parameters[n]
        rel = p.prior_rel_std
        # under log scaling the prior is on ln p: its relative standard deviation to first order
        var.append((rel * abs(p.value)) ** 2)
    return HeldParameters(
        names=tuple(names),
        values={n: model.parameters[n].value for n in names},
        cov=np.diag(var),
        source="the model file's priors (prior_rel_std)",
        notes=(
            "no linear calibration result given: the linear parameters' priors stand in for "
            "their calibrated uncertainty; modal damping held as exact",
        ),
    )


def damping_modes_in_band(
    model: Model, band_hz: tuple[float, float], max_order: float
) -> list[int]:
    """The model's modes whose damping the test's response feels: natural frequency from half
    the band's lowest fundamental to 1.5 times its highest order's frequency
    (``band_hz[0] / 2 .. 1.5 max_order band_hz[1]``), identified by the linear test or not."""
    from analysis.linear.modal import modal_analysis

    asm = model.assemble()
    f = modal_analysis(asm.M, asm.K).frequency_hz
    lo, hi = band_hz[0] / 2, 1.5 * max_order * band_hz[1]
    return [i + 1 for i, fi in enumerate(f) if lo <= fi <= hi]


def load_linear_result(path: str | Path) -> dict[str, Any]:
    """A ``linear_calibration.json`` as a dict (NaN allowed)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: cannot read the linear calibration result ({exc})") from None
    if not {"names", "parameters", "cov"} <= set(doc):
        raise ValueError(f"{path}: not a linear calibration result (no names, parameters, cov)")
    return doc


@dataclass
class Propagation:
    """What the held values' uncertainty does to the fitted parameters.

    ``gain`` (n, k): ``d fitted / d held`` (physical units); ``cov`` (n, n): ``G C_b G^T``.
    """

    gain: np.ndarray
    cov: np.ndarray


def propagate_held(
    objective: FRFObjective,
    theta: np.ndarray,
    jac: np.ndarray,
    model: Model,
    held: HeldParameters,
) -> Propagation:
    """Carry the held values' covariance into the fitted parameters at the optimum.

    Parameters
    ----------
    objective : FRFObjective
        The calibration's metric (its predictor, selection and weights are used again).
    theta, jac : ndarray
        The optimum in scaled coordinates and the metric's Jacobian there.
    model : Model
        The model with the calibrated values.
    held : HeldParameters
    """
    pred0 = objective.predictor
    pred = DampedPredictor(
        model,
        pred0.data,
        channels=pred0.channel_names,
        n_harmonics=pred0.settings["n_harmonics"],
        n_time=pred0.settings["n_time"],
    )
    space_b = damped_space(model, held.names)
    obj_b = FRFObjective(pred, space_b, objective.mask, objective.weighting)
    obj_b.sigma, obj_b._weight = objective.sigma, objective._weight
    theta_b = space_b.to_theta([held.values[n] for n in held.names])
    r, Jb = obj_b(theta_b, True)
    if Jb is None or not np.all(np.isfinite(Jb)):
        raise RuntimeError(
            "the calibrated model did not converge at every step: the held "
            "values' uncertainty cannot be carried"
        )
    sa = objective.space
    Ja = jac / sa.dp_dtheta(theta)[None, :]  # per unit of each physical value
    Jb = Jb / space_b.dp_dtheta(theta_b)[None, :]
    gain = -np.linalg.lstsq(Ja, Jb, rcond=None)[0]
    cov = gain @ held.cov @ gain.T
    return Propagation(gain=gain, cov=cov)


def noise_scale(
    chi2_per_dof: float, fold_ratio: Sequence[float] | np.ndarray | None = None
) -> np.ndarray:
    """Per parameter, the factor on the noise-only standard deviation: the Birge ratio
    ``sqrt(chi2/dof)`` where the misfit exceeds the noise, or the folds' scatter over the
    noise-only prediction (cross-validation's ``std_ratio``) where that is larger: the
    folds measure how much the estimate moves when part of the data goes, which a model
    error inflates and the noise-only figure does not know; never below 1."""
    birge = float(np.sqrt(max(chi2_per_dof, 1.0))) if np.isfinite(chi2_per_dof) else 1.0
    if fold_ratio is None:
        return np.array([birge])
    r = np.asarray(fold_ratio, dtype=float)
    return np.maximum(birge, np.where(np.isfinite(r), r, 1.0))
