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
from analysis.mhb.solver import solve_point
from analysis.model import Model
from analysis.predict_branches import BranchMatchedPredictor

__all__ = ["ZETA", "DampedPredictor", "damped_space", "with_values", "zeta_name"]


def zeta_name(mode: int) -> str:
    """The parameter name of mode ``mode``'s damping ratio (1-based, as ``[damping.per_mode]``)."""
    return f"{ZETA}{int(mode)}"


def with_values(model: Model, values: dict[str, float]) -> Model:
    """``model`` with parameter values and modal damping ratios (``zeta_<mode>``) replaced."""
    zetas = {int(n[len(ZETA) :]): float(v) for n, v in values.items() if n.startswith(ZETA)}
    plain = {n: v for n, v in values.items() if not n.startswith(ZETA)}
    out = model.with_values(plain) if plain else model
    if zetas:
        per_mode = {**out.damping.per_mode, **zetas}
        out = out.with_damping(dataclasses.replace(out.damping, per_mode=per_mode))
    return out


#: Prefix of a modal damping ratio calibrated with the parameters: ``"zeta_4"`` is mode 4's.
ZETA = "zeta_"


class DampedPredictor(BranchMatchedPredictor):
    """A predictor whose parameters may include modal damping ratios (``zeta_<mode>``),
    differentiated by finite differences: each step solved again with the ratio shifted,
    started from its solution (Newton stays on the chosen branch and needs a few iterations;
    solving the sweeps again would cost a whole prediction and could take another branch)."""

    def predict(self, values=None, params=(), rows=None):
        values = dict(values or {})
        zetas = {n: values.pop(n) for n in list(values) if n.startswith(ZETA)}
        base_model = self.model
        if zetas:
            per_mode = dict(base_model.damping.per_mode)
            per_mode.update({int(n[len(ZETA) :]): float(v) for n, v in zetas.items()})
            self.model = base_model.with_damping(
                dataclasses.replace(base_model.damping, per_mode=per_mode)
            )
        try:
            plain = [p for p in params if not p.startswith(ZETA)]
            pred = super().predict(values, plain, rows)
            for n in params:
                if n.startswith(ZETA):
                    pred.d_frf[n] = self._zeta_derivative(values, rows, pred, n, zetas[n])
            return pred
        finally:
            self.model = base_model

    def _zeta_derivative(self, values, rows, pred, name: str, zeta: float) -> np.ndarray:
        """``d frf / d zeta`` by a forward difference of ``1e-3 zeta``, each step solved from
        its solution (steps where that fails: the sweeps solved again at the shifted ratio)."""
        model = self.model.with_values(values) if values else self.model
        _, points = self.solve(model, rows=rows)  # the solutions just made (kept)
        h = 1e-3 * zeta
        per_mode = {**model.damping.per_mode, int(name[len(ZETA) :]): zeta + h}
        shifted = model.with_damping(dataclasses.replace(model.damping, per_mode=per_mode))
        pb = self.problem(shifted)
        out = np.full_like(pred.frf, np.nan)
        lost = []
        for row, p in points.items():
            if not p.converged:
                continue
            force = self._force_sign * self.drive_force[row][:, None]
            q = solve_point(pb, p.omega, force, X0=p.X)
            if q.converged:
                out[row] = (self.frf_of(row, q)[0] - pred.frf[row]) / h
            else:
                lost.append(row)
        if lost:
            keep = self.model
            self.model = keep.with_damping(shifted.damping)
            try:
                again = BranchMatchedPredictor.predict(self, values, (), rows)
            finally:
                self.model = keep
            out[lost] = (again.frf[lost] - pred.frf[lost]) / h
        return out

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
