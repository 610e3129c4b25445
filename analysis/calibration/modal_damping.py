"""Modal damping ratios as calibration parameters: ``zeta_<mode>`` beside the model's own.

A model's modal damping is not a model-file parameter (it is the ``[damping]`` table, by mode
number), yet a calibration may fit it or carry its uncertainty. :class:`DampedPredictor`
predicts with ratios named ``zeta_4`` (mode 4's) among the values and differentiates with
respect to them; :func:`damped_space` scales them (log, bounds 1e-4 to 0.2).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from analysis.calibration.parameters import ParameterSpace
from analysis.linear.receptance import ZETA, zeta_name
from analysis.model import Model
from analysis.predict_branches import BranchMatchedPredictor

__all__ = ["ZETA", "DampedPredictor", "damped_space", "with_values", "zeta_name"]


def with_values(model: Model, values: dict[str, float]) -> Model:
    """``model`` with parameter values and modal damping ratios (``zeta_<mode>``) replaced."""
    zetas = {int(n[len(ZETA) :]): float(v) for n, v in values.items() if n.startswith(ZETA)}
    plain = {n: v for n, v in values.items() if not n.startswith(ZETA)}
    out = model.with_values(plain) if plain else model
    if zetas:
        per_mode = {**out.damping.per_mode, **zetas}
        out = out.with_damping(dataclasses.replace(out.damping, per_mode=per_mode))
    return out


class DampedPredictor(BranchMatchedPredictor):
    """A predictor whose parameters may include modal damping ratios (``zeta_<mode>``), with
    exact derivatives: the receptances' own (``-phi phi^T 2 i w w_r g^2``,
    :class:`~analysis.linear.receptance.ModalLinearModel`) through the balance's implicit
    differentiation, as every structural parameter's."""

    def predict(self, values=None, params=(), rows=None, *, stop_at_failure=False, bound=None):
        values = dict(values or {})
        zetas = {n: values.pop(n) for n in list(values) if n.startswith(ZETA)}
        asked = {int(n[len(ZETA) :]) for n in params if n.startswith(ZETA)}
        if not asked <= set(self.damping_modes):
            # a linear model (and solutions) with their derivatives; kept for the calls
            # without derivatives (a fit's trial steps), whose solutions a fit's next call
            # with them reuses
            self.damping_modes = tuple(sorted(asked | set(self.damping_modes)))
            self._linear_key, self._last = None, None
        base_model = self.model
        if zetas:
            per_mode = dict(base_model.damping.per_mode)
            per_mode.update({int(n[len(ZETA) :]): float(v) for n, v in zetas.items()})
            self.model = base_model.with_damping(
                dataclasses.replace(base_model.damping, per_mode=per_mode)
            )
        try:
            return super().predict(
                values, params, rows, stop_at_failure=stop_at_failure, bound=bound
            )
        finally:
            self.model = base_model

    def _linear_model(self, model):
        key = (tuple(sorted(model.damping.per_mode.items())), model.damping.default_zeta)
        if getattr(self, "_damping_key", None) != key:
            self._linear_key = None
            self._damping_key = key
        return super()._linear_model(model)


def damped_space(model: Model, names) -> ParameterSpace:
    plain = [n for n in names if not n.startswith(ZETA)]
    sp = ParameterSpace.from_model(model, plain)
    zetas = [n for n in names if n.startswith(ZETA)]
    if not zetas:
        return sp
    z = np.array(
        [model.damping.per_mode.get(int(n[len(ZETA) :]), model.damping.default_zeta) for n in zetas]
    )
    order = list(names)
    allv = {
        "log": dict(zip(plain, sp.log, strict=True)) | {n: True for n in zetas},
        "nominal": dict(zip(plain, sp.nominal, strict=True)) | dict(zip(zetas, z, strict=True)),
        "lower": dict(zip(plain, sp.lower, strict=True)) | {n: 1e-4 for n in zetas},
        "upper": dict(zip(plain, sp.upper, strict=True)) | {n: 0.2 for n in zetas},
    }
    return ParameterSpace(
        names=tuple(order),
        **{
            k: np.array([v[n] for n in order], dtype=bool if k == "log" else float)
            for k, v in allv.items()
        },
    )
