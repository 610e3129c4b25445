"""Model predictions on the branch the test was on.

Where a nonlinear response is multi-valued (the jump of a hardening or contact resonance), the
test and a model can sit on different branches at the same frequency: the rig may leave the
resonant branch a few steps before its fold (a transient, a force-control correction), and a
model stepped by continuation leaves it only at the fold. Such a step misfits by hundreds of
standard errors although the model is right, and it dominates any comparison or calibration.

:class:`BranchMatchedPredictor` solves each sweep as the test did (forward continuation) and,
over the steps that misfit, once more in the reverse order (continuation from the far side,
which follows the other branch back to its fold); each step then takes the solution closer to
the measurement. Derivatives are those of the chosen solution, so calibrations stay exact.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from analysis.mhb.sensitivity import point_sensitivities
from analysis.mhb.sweep import solve_steps
from analysis.predict import Prediction, SteppedSinePredictor, sweeps_of
from analysis.system import build_problem_dofs

__all__ = ["BranchMatchedPredictor"]

#: A step whose RMS misfit exceeds this many standard errors is solved from the other side too.
SUSPECT_SIGMA = 5.0
#: Sub-step halvings tried on a step that fails from its neighbour (the other branch is tried
#: anyway, from the far side).
MAX_SUBSTEP_DEPTH = 2


class BranchMatchedPredictor(SteppedSinePredictor):
    """:class:`~analysis.predict.SteppedSinePredictor` that follows the test's branch.

    Parameters are those of :class:`~analysis.predict.SteppedSinePredictor`, plus

    match_branches : bool
        False gives the plain forward continuation (the test's sweep order only).
    """

    def __init__(self, model, data, *, match_branches: bool = True, **kwargs) -> None:
        super().__init__(model, data, **kwargs)
        self.match_branches = match_branches
        H, s = self.measured()
        positive = s[np.isfinite(s) & (s > 0)]
        floor = positive.min() if positive.size else 1.0
        self._H = H
        self._sigma = np.maximum(np.nan_to_num(s, nan=floor), floor)

    def _step_misfit(self, frf: np.ndarray, row: int) -> float:
        z = np.abs((frf - self._H[row]) / self._sigma[row]) ** 2
        return float(np.sqrt(np.mean(z))) if np.all(np.isfinite(z)) else np.inf

    def problem(self, model, extra_dofs: Sequence[int] = ()):
        """Balance problem of ``model`` (with the file's sensor masses) for the file's drive.

        Outputs are the compared channels' DOFs followed by ``extra_dofs``.
        """
        return build_problem_dofs(
            model,
            [self._force_dof],
            [*self._out_dofs, *extra_dofs],
            orders=self.orders,
            n_harmonics=self.settings["n_harmonics"],
            n_time=self.settings["n_time"],
            linear=self._linear_model(model),
        )

    def frf_of(self, row: int, point) -> tuple[np.ndarray, np.ndarray]:
        """Channel FRFs (C, n_orders) of a solution at step ``row`` and the factor from
        displacement phasors to them."""
        d = self.data
        orders = np.array([float(o) for o in self.orders])
        wk = 2 * np.pi * d.frequency_hz[row] * orders
        F = self._force_sign * d.force[row]
        sign = np.array(self._out_sign)[:, None]
        power = np.array(self._power)[:, None]
        factor = sign * (1j * wk[None, :]) ** power / F[None, :] * self._force_sign
        C = len(self._out_dofs)
        return point.outputs()[:, :C].T * factor, factor

    def solve(self, model=None, extra_dofs: Sequence[int] = (), rows: np.ndarray | None = None):
        """Solutions of every needed step on the measured branch.

        Parameters
        ----------
        model : Model, optional
            Default: the predictor's model (with the file's sensor masses).
        extra_dofs : sequence of int
            Further output DOFs (after the channels').
        rows : ndarray of int, optional
            Steps needed (their sweeps are solved).

        Returns
        -------
        problem : HarmonicProblem
        points : dict row -> MHBPoint
        """
        model = self.model if model is None else model
        pb = self.problem(model, extra_dofs)
        d = self.data
        need = np.ones(d.n_steps, bool) if rows is None else np.isin(np.arange(d.n_steps), rows)
        out = {}
        for sweep in sweeps_of(d):
            if not need[sweep].any():
                continue
            F = self._force_sign * d.force[sweep][:, :, None]
            w = 2 * np.pi * d.frequency_hz[sweep]
            points = solve_steps(pb, w, F, max_substep_depth=MAX_SUBSTEP_DEPTH).points
            chosen = list(points)
            fits = np.array(
                [
                    self._step_misfit(self.frf_of(r, p)[0], r) if p.converged else np.inf
                    for r, p in zip(sweep, points, strict=True)
                ]
            )
            bad = np.flatnonzero(fits > SUSPECT_SIGMA)
            if self.match_branches and bad.size:
                lo, hi = bad.min(), min(bad.max() + 1, sweep.size - 1)
                seg = np.arange(hi, lo - 1, -1)
                X0 = points[hi].X if points[hi].converged and hi > bad.max() else None
                back = solve_steps(
                    pb, w[seg], F[seg], X0=X0, max_substep_depth=MAX_SUBSTEP_DEPTH
                ).points
                for j, p in zip(seg, back, strict=True):
                    if p.converged:
                        fit = self._step_misfit(self.frf_of(sweep[j], p)[0], sweep[j])
                        if fit < fits[j]:
                            chosen[j], fits[j] = p, fit
            out.update(zip(sweep.tolist(), chosen, strict=True))
        return pb, out

    def predict(
        self,
        values: Mapping[str, float] | None = None,
        params: Sequence[str] = (),
        rows: np.ndarray | None = None,
    ) -> Prediction:
        """Model FRFs (and derivatives) on the measured branch; see the base class."""
        model = self.model.with_values(values) if values else self.model
        pb, points = self.solve(model, rows=rows)
        d = self.data
        n, C, H = d.n_steps, len(self.channel_indices), len(self.orders)
        frf = np.full((n, C, H), np.nan + 0j)
        dfrf = {p: np.full((n, C, H), np.nan + 0j) for p in params}
        conv = np.zeros(n, dtype=bool)
        msgs: list[str] = []
        need = np.ones(n, bool) if rows is None else np.isin(np.arange(n), rows)
        for row, p in points.items():
            conv[row] = p.converged
            if not p.converged:
                msgs.append(f"step {row} ({d.frequency_hz[row]:.3f} Hz): {p.message}")
                continue
            frf[row], factor = self.frf_of(row, p)
            if params and need[row]:
                sens = point_sensitivities(pb, p, list(params))
                for name in params:
                    dfrf[name][row] = sens[name].d_outputs(pb.order_k)[:, :C].T * factor
        return Prediction(frf, dfrf, conv, msgs)
