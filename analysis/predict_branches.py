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

A rig under force control is driven by a voltage, not by a force: the shaker's impedance can
hold the structure on the part of a force-driven branch that lies past its fold (the branch
that turns back), where a model driven by the recorded force is unstable. A step that misfits
just before a measured jump, where the model's forward solution jumps too, is therefore also
solved there: the branch at that step's force is continued from the step's forward solution
through the fold and back to the step's frequency
(:func:`~analysis.mhb.continuation.continue_branch`), and the fold partner is taken if it
fits better.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Iterator, Mapping, Sequence

import numpy as np

from analysis.mhb import sweep as _sweep
from analysis.mhb.continuation import ContinuationSettings, continue_branch
from analysis.mhb.sensitivity import point_sensitivities
from analysis.mhb.solver import solve_point
from analysis.mhb.sweep import solve_steps
from analysis.predict import (
    BOUNDED_MESSAGE,
    STOPPED_MESSAGE,
    CostBound,
    Prediction,
    SteppedSinePredictor,
    needed_rows,
    sweeps_of,
)
from analysis.system import build_problem_dofs

__all__ = ["BranchMatchedPredictor"]

#: A step whose RMS misfit exceeds this many standard errors, and whose fundamental misses by
#: more than this share (the other branch of a jump misses by far more than a model error),
#: is solved from the other side too.
SUSPECT_SIGMA = 5.0
SUSPECT_RELATIVE = 0.1
#: Sub-step halvings tried on a step that fails from its neighbour (the other branch is tried
#: anyway, from the far side).
MAX_SUBSTEP_DEPTH = 2
#: A measured jump: the fundamental of some channel changes by this share from one step to the
#: next. The last steps before one (:data:`FOLD_STEPS`) that misfit are solved past the fold too.
JUMP_RELATIVE = 0.3
FOLD_STEPS = 2
#: The local continuation around a fold (it ends once back at the step's frequency), over at
#: most this share of the frequency past the step.
FOLD_WINDOW = 0.01
FOLD_SEARCH = ContinuationSettings(ds=0.005, ds_max=0.02, max_points=80, stability=False)


def _iter_steps(pb, omega, force, *, X0=None, max_substep_depth: int = 4) -> Iterator:
    """The solutions of :func:`~analysis.mhb.sweep.solve_steps`, one step at a time.

    The same steps, starts and fallbacks in the same order (so the same solutions, bit for bit,
    and the same warning per failed step on the same logger), but yielded as they are solved:
    a caller that needs no more of them (a prediction whose metric is already ``inf``) stops
    there. ``omega`` (n,) and ``force`` (n, n_orders, n_f) as :func:`solve_steps` takes them.
    ``tests/analysis/test_predict_early_exit.py`` checks the equality against it.
    """
    last = prev = last_force = None
    X = X0
    for i in range(len(omega)):
        X_start = X
        if prev is not None and last is not None and prev.omega != last.omega:
            r = (omega[i] - last.omega) / (last.omega - prev.omega)
            if 0 < r <= 2:
                X_start = last.X + r * (last.X - prev.X)
        p = _sweep.solve_point(pb, omega[i], force[i], X_start, None)
        if not p.converged and X_start is not X:
            p = _sweep.solve_point(pb, omega[i], force[i], X, None)
        if not p.converged:
            q = _sweep.solve_point(pb, omega[i], force[i], None, None)
            if q.converged:
                p = q
        if not p.converged and last is not None:
            for depth in range(1, max_substep_depth + 1):
                p = _sweep._substep(
                    pb, last.omega, last_force, last.X, omega[i], force[i], None, depth
                )
                if p.converged:
                    break
        if not p.converged:
            q = _sweep._force_homotopy(pb, omega[i], force[i], None, 2**max_substep_depth)
            if q.converged:
                p = q
        if not p.converged:
            _sweep.log.warning(
                "MHB step %d (%.4g Hz) did not converge: %s", i, omega[i] / (2 * np.pi), p.message
            )
        else:
            prev, last, last_force, X = last, p, force[i], p.X
        yield p


def _jumps(fundamental: np.ndarray) -> np.ndarray:
    """Positions ``k`` where some channel's fundamental FRF (steps, channels) changes by more
    than :data:`JUMP_RELATIVE` from step ``k`` to ``k + 1``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        change = np.abs(np.diff(fundamental, axis=0)) / np.abs(fundamental[:-1])
    return np.flatnonzero(np.nan_to_num(change, nan=0.0).max(axis=1) > JUMP_RELATIVE)


class _Tally:
    """A sweep's final step terms added to a :class:`~analysis.predict.CostBound` (nothing
    without one): the steps of ``segment`` count once the backward pass has passed them, those
    in ``pending`` (that may still take a fold partner) at the end."""

    def __init__(self, predictor, bound, sweep, chosen, segment, pending) -> None:
        self.predictor, self.bound, self.sweep, self.chosen = predictor, bound, sweep, chosen
        self.pending = set(pending)

    def add(self, positions: Iterable[int]) -> bool:
        """Add the terms of the steps at ``positions`` (of the sweep) that are final: whether
        the bound is now exceeded."""
        if self.bound is None:
            return False
        for j in positions:
            j = int(j)
            if j in self.pending:
                continue
            p = self.chosen[j]
            if p.converged:
                row = int(self.sweep[j])
                self.bound.add(row, self.predictor.frf_of(row, p)[0])
        return self.bound.exceeded

    def close(self) -> None:
        """Add the pending steps' terms (after the fold partners)."""
        pending, self.pending = sorted(self.pending), set()
        self.add(pending)


class BranchMatchedPredictor(SteppedSinePredictor):
    """:class:`~analysis.predict.SteppedSinePredictor` that follows the test's branch.

    Parameters are those of :class:`~analysis.predict.SteppedSinePredictor`, plus

    match_branches : bool
        False gives the plain forward continuation (the test's sweep order only).

    Orders the file records with a zero force target at every level (a test that holds the
    force's higher harmonics at zero) drive the model with their measured force but are not
    compared: their FRFs divide by a force at the noise. :attr:`compared` holds the indices of
    the compared orders; :meth:`measured` and :meth:`predict` return those orders only.
    """

    def __init__(self, model, data, *, match_branches: bool = True, **kwargs) -> None:
        super().__init__(model, data, **kwargs)
        self.match_branches = match_branches
        targets = np.abs(np.asarray(data.force_targets))
        excited = np.flatnonzero(targets.max(axis=0) > 0) if targets.size else np.array([], int)
        self.compared = excited if excited.size else np.arange(len(self.orders))
        self.compared_orders = [self.orders[k] for k in self.compared]
        H, s = self.measured()
        # a floor for choosing between branches at one step only (a relative comparison);
        # a comparison or a calibration weighted by these errors refuses zeros first
        # (analysis.predict.check_standard_errors)
        positive = s[np.isfinite(s) & (s > 0)]
        floor = positive.min() if positive.size else 1.0
        self._H = H
        self._sigma = np.maximum(np.nan_to_num(s, nan=floor), floor)
        self._last: tuple | None = None

    def measured(self, all_orders: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Measured FRFs and standard errors, shape (n_steps, n_channels, n_compared) (every
        recorded order with ``all_orders``)."""
        H, s = super().measured()
        if all_orders or not hasattr(self, "compared"):
            return H, s
        return H[:, :, self.compared], s[:, :, self.compared]

    def _step_relative(self, frf: np.ndarray, row: int) -> float:
        """Largest relative misfit of the fundamental over the channels."""
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.abs(frf[:, 0] - self._H[row, :, 0]) / np.abs(self._H[row, :, 0])
        return float(np.max(e)) if np.all(np.isfinite(e)) else np.inf

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
            orders=self.drive_orders,
            n_harmonics=self.settings["n_harmonics"],
            n_time=self.settings["n_time"],
            linear=self._linear_model(model),
        )

    def frf_of(self, row: int, point) -> tuple[np.ndarray, np.ndarray]:
        """Channel FRFs (C, n_compared) of a solution at step ``row`` and the factor from
        displacement phasors to them."""
        d = self.data
        k = self.compared
        orders = np.array([float(self.orders[i]) for i in k])
        wk = 2 * np.pi * d.frequency_hz[row] * orders
        F = self._force_sign * d.force[row, k]
        sign = np.array(self._out_sign)[:, None]
        power = np.array(self._power)[:, None]
        factor = sign * (1j * wk[None, :]) ** power / F[None, :] * self._force_sign
        C = len(self._out_dofs)
        return point.outputs()[k, :C].T * factor, factor

    def solve(
        self,
        model=None,
        extra_dofs: Sequence[int] = (),
        rows: np.ndarray | None = None,
        *,
        stop_at_failure: bool = False,
        bound: CostBound | None = None,
    ):
        """Solutions of every needed step on the measured branch.

        Parameters
        ----------
        model : Model, optional
            Default: the predictor's model (with the file's sensor masses).
        extra_dofs : sequence of int
            Further output DOFs (after the channels').
        rows : ndarray of int, optional
            Steps needed: each sweep is followed through those of its steps only (default:
            every step).
        stop_at_failure : bool
            Stop at the first needed step that ends without a solution on either branch (a
            metric over the needed steps is then ``inf`` whatever the others give): the
            sweeps not yet solved are left out of ``points``. A step is only given up once no
            later stage can still solve it (the forward pass, then the backward pass over the
            misfitting steps; the fold partners replace solved steps only), so the steps that
            are returned, and whether any needed step failed, are those of a full solve. The
            sweeps are independent (each starts from its first step's linear response), so
            they are solved here in the order likeliest to fail first
            (:meth:`~analysis.predict.SteppedSinePredictor._sweep_order`).
        bound : CostBound, optional
            Stop once the metric over the needed steps provably exceeds ``bound.limit``: each
            step's term is added to ``bound.floor`` once no later stage can change its
            solution (:meth:`_solve_sweep`), and the solve ends when the floor passes the
            limit (``bound.exceeded``), with the sweeps not yet solved left out (they are tried
            in the order of ``stop_at_failure``). Every step solved is the same as without it.

        Returns
        -------
        problem : HarmonicProblem
        points : dict row -> MHBPoint
            In the file's order of the steps.
        """
        model = self.model if model is None else model
        key = (tuple(extra_dofs), None if rows is None else np.asarray(rows).tobytes())
        if self._last is not None and self._last[1] == key and self._last[0] == model:
            # the same model (values, damping, elements) at the same steps: a fit evaluates
            # its accepted iterate once more for the derivatives
            return self._last[2]
        pb = self.problem(model, extra_dofs)
        d = self.data
        need = needed_rows(d.n_steps, rows)
        sweeps = [s[need[s]] for s in sweeps_of(d) if need[s].any()]  # needed steps, in order
        early = stop_at_failure or bound is not None
        order = self._sweep_order(sweeps) if early else range(len(sweeps))
        solved: dict[int, dict] = {}
        stopped = False
        for i in order:
            solved[i], failed = self._solve_sweep(pb, sweeps[i], stop_at_failure, bound)
            past = bound is not None and bound.exceeded
            if failed or past:  # the sweeps that end predictions early are tried first
                self._failed_sweeps[i] = self._failed_sweeps.get(i, 0) + 1
            if past or (failed and stop_at_failure):
                stopped = True
                break
        out = {}
        for i in sorted(solved):
            out.update(solved[i])
        if not stopped:  # complete: the same solutions as without stop_at_failure
            self._last = (model, key, (pb, out))
        return pb, out

    def _solve_sweep(
        self, pb, sweep: np.ndarray, stop_at_failure: bool, bound: CostBound | None = None
    ) -> tuple[dict, bool]:
        """Solutions (row -> MHBPoint) of the steps ``sweep`` (file rows, in the test's order)
        on the measured branch, and whether one of them has none. With ``stop_at_failure``,
        once a step is known to have none (no later stage can give it one), the others are
        left unfinished and only that step is returned.

        With ``bound``, a step's term is final once no later stage can replace its solution:
        the forward solution of a step outside the backward pass's segment, the chosen one of a
        step the backward pass has passed, and neither for the steps that may take a fold
        partner (those of :meth:`_before_jumps` with the forward misfits, a superset of the
        ones with the final misfits, which only decrease) until the end. Once ``bound`` is
        exceeded the sweep ends and nothing is returned."""
        self.steps_solved += sweep.size
        F = self._force_sign * self.drive_force[sweep][:, :, None]
        w = 2 * np.pi * self.data.frequency_hz[sweep]
        points = solve_steps(pb, w, F, max_substep_depth=MAX_SUBSTEP_DEPTH).points
        chosen = list(points)
        frfs = [
            self.frf_of(r, p)[0] if p.converged else None
            for r, p in zip(sweep, points, strict=True)
        ]
        fits = np.array(
            [
                np.inf if f is None else self._step_misfit(f, r)
                for r, f in zip(sweep, frfs, strict=True)
            ]
        )
        rel = np.array(
            [
                np.inf if f is None else self._step_relative(f, r)
                for r, f in zip(sweep, frfs, strict=True)
            ]
        )
        bad = np.flatnonzero((fits > SUSPECT_SIGMA) & (rel > SUSPECT_RELATIVE))
        seg = np.arange(0)
        if self.match_branches and bad.size:
            lo, hi = bad.min(), min(bad.max() + 1, sweep.size - 1)
            seg = np.arange(hi, lo - 1, -1)
        tally = _Tally(self, bound, sweep, chosen, seg, self._before_jumps(sweep, frfs, fits))
        if tally.add(np.setdiff1d(np.arange(sweep.size), seg)):
            return {}, False
        if seg.size:
            X0 = points[hi].X if points[hi].converged and hi > bad.max() else None
            if stop_at_failure or bound is not None:
                back = _iter_steps(pb, w[seg], F[seg], X0=X0, max_substep_depth=MAX_SUBSTEP_DEPTH)
            else:
                back = solve_steps(
                    pb, w[seg], F[seg], X0=X0, max_substep_depth=MAX_SUBSTEP_DEPTH
                ).points
            for j, p in zip(seg, back, strict=False):
                self.steps_solved += 1
                if p.converged:
                    self._keep_better(sweep[j], p, j, chosen, fits)
                elif stop_at_failure and not chosen[j].converged:
                    # unsolved both ways; the fold partners replace solved steps only
                    return {int(sweep[j]): chosen[j]}, True
                if tally.add([int(j)]):
                    return {}, False
        failed = not all(p.converged for p in chosen)
        if stop_at_failure and failed:
            k = next(k for k, p in enumerate(chosen) if not p.converged)
            return {int(sweep[k]): chosen[k]}, True
        if self.match_branches:
            for j in self._before_jumps(sweep, frfs, fits):
                for p in self._fold_partners(pb, points[j].X, w[j], w[j - 1], F[j]):
                    self._keep_better(sweep[j], p, j, chosen, fits)
        tally.close()
        return dict(zip(sweep.tolist(), chosen, strict=True)), failed

    def _keep_better(self, row: int, p, j: int, chosen: list, fits: np.ndarray) -> None:
        """Take solution ``p`` at position ``j`` (file step ``row``) if it fits better."""
        fit = self._step_misfit(self.frf_of(row, p)[0], row)
        if fit < fits[j]:
            chosen[j], fits[j] = p, fit

    def _before_jumps(self, sweep: np.ndarray, frfs: list, fits: np.ndarray) -> list[int]:
        """Positions in ``sweep`` (not the first) of misfitting steps at most
        :data:`FOLD_STEPS` before a measured jump after which the model's forward solution
        jumps too (its fold lies just past the step: the only place a fold partner is near).

        ``frfs`` are the forward solutions' FRFs (None where not converged)."""
        nan = np.full(self._H.shape[1], np.nan, complex)
        model = np.array([nan if f is None else f[:, 0] for f in frfs])
        measured = _jumps(self._H[sweep, :, 0])
        folds = set(_jumps(model).tolist())
        near = {j for k in measured for j in range(k - FOLD_STEPS + 1, k + 1) if j >= 1}
        return sorted(j for j in near & folds if fits[j] > SUSPECT_SIGMA)

    @staticmethod
    def _fold_partners(pb, X: np.ndarray, w: float, w_prev: float, F: np.ndarray) -> list:
        """Solutions at ``w`` on the far side of a fold just past the solution ``X`` there.

        The branch at force ``F`` is continued from ``X`` away from ``w_prev`` for at most the
        step from ``w_prev`` (and :data:`FOLD_WINDOW` of ``w``); if it folds back, it is
        followed until it is back at ``w``, and every later crossing of ``w`` is solved there.
        """
        ahead = np.sign(w - w_prev) or 1.0
        reach = min(abs(w - w_prev), FOLD_WINDOW * w)

        def back_at_w(points, folds) -> bool:
            return bool(folds) and (points[-1].omega - w) * ahead < 0

        branch = continue_branch(pb, w, w + ahead * reach, F, FOLD_SEARCH, X0=X, until=back_at_w)
        if not branch.folds:
            return []
        om = branch.omega
        crossings = np.flatnonzero(np.diff(np.sign(om - w)) != 0)
        out = []
        for i in crossings[crossings >= max(branch.folds[0] - 1, 1)]:
            p = solve_point(pb, w, F, X0=branch.points[i + 1].X)
            if p.converged:
                out.append(p)
        return out

    def response_sigma(self, pb, points: dict) -> np.ndarray:
        """Standard errors of the FRF residuals with the force's error through the model.

        The model is driven by the measured force, so a force error ``dF`` moves the model's
        response by ``(dq/dF) dF`` while the measured response does not move: the residual's
        variance is ``s_R^2 + sum_k |dq/dF_k|^2 s_F,k^2`` over every recorded order ``k``,
        divided by ``|F|^2`` for an FRF. For a linear structure ``dq/dF`` is the receptance
        and this is the file's first-order FRF error; near the fold of a resonance the
        tangent is far larger and the step weighs accordingly less.

        Parameters
        ----------
        pb : HarmonicProblem
        points : dict row -> MHBPoint
            Solutions (of :meth:`solve`).

        Returns
        -------
        ndarray, shape (n_steps, n_channels, n_compared)
            NaN-free; the file's first-order value where a step did not converge.
        """
        from analysis.mhb.solver import _prepare  # noqa: PLC0415

        d = self.data
        b = pb.basis
        C = len(self._out_dofs)
        k_all = pb.order_k
        idx = self.channel_indices
        out = self._sigma.copy()
        sR = d.response_std[:, idx][:, :, self.compared]
        sF = self.drive_force_std
        kc = self.compared
        for row, p in points.items():
            if not p.converged:
                continue
            prep = p.lin.get("prep") or _prepare(pb, p.omega, p.force[k_all])
            rec = prep["rec"]
            Hof = rec["of"][:, :C, 0]  # (H+1, C)
            n = pb.n_nl
            dirs = [(j, h, unit) for j, h in enumerate(k_all) for unit in (1.0, 1j)]
            dq_all = np.zeros((len(dirs), b.n_harmonics + 1, C), complex)
            if n:
                J = np.eye(b.size * n) - prep["G"] @ p.lin["dF"]
                Hnf = rec["nf"][:, :, 0]  # (H+1, n)
                Hon = rec["on"][:, :C, :]  # (H+1, C, n)
                rhs = []
                for _, h, unit in dirs:
                    e = np.zeros((b.n_harmonics + 1, n), complex)
                    e[h] = Hnf[h] * unit
                    rhs.append(b.from_complex(e).ravel())
                dX = np.linalg.solve(J, np.array(rhs).T)  # (size n, 2K)
                dFnl = (p.lin["dF"] @ dX).T.reshape(len(dirs), b.size, n)
                for i, df in enumerate(dFnl):
                    dq_all[i] = np.einsum("kij,kj->ki", Hon, b.to_complex(df))
            for i, (_, h, unit) in enumerate(dirs):
                dq_all[i, h] += Hof[h] * unit
            # each part of a complex force error has half its variance
            wgt = np.array([sF[row, j] ** 2 / 2 for j, _, _ in dirs])
            dq = dq_all[:, k_all[kc], :]  # (2K, n_compared, C)
            var = np.einsum("i,ikc->ck", wgt, np.abs(dq) ** 2)
            wk = 2 * np.pi * d.frequency_hz[row] * np.array([float(self.orders[i]) for i in kc])
            var *= np.abs(wk[None, :] ** np.array(self._power)[:, None]) ** 2
            F = np.abs(d.force[row, kc])[None, :]
            sig = np.sqrt(sR[row] ** 2 + var) / F
            ok = np.isfinite(sig) & (sig > 0)
            out[row][ok] = sig[ok]
        return out

    def predict(
        self,
        values: Mapping[str, float] | None = None,
        params: Sequence[str] = (),
        rows: np.ndarray | None = None,
        *,
        stop_at_failure: bool = False,
        bound: CostBound | None = None,
    ) -> Prediction:
        """Model FRFs (and derivatives) on the measured branch; see the base class (and
        :meth:`solve` for ``stop_at_failure`` and ``bound``)."""
        return self.predict_with_sigma(
            values, params, rows, sigma=False, stop_at_failure=stop_at_failure, bound=bound
        )[0]

    def predict_with_sigma(
        self,
        values: Mapping[str, float] | None = None,
        params: Sequence[str] = (),
        rows: np.ndarray | None = None,
        *,
        sigma: bool = True,
        stop_at_failure: bool = False,
        bound: CostBound | None = None,
    ) -> tuple[Prediction, np.ndarray | None]:
        """:meth:`predict` and, with ``sigma``, the residuals' standard errors of
        :meth:`response_sigma` at the same solutions."""
        model = self.model.with_values(values) if values else self.model
        pb, points = self.solve(model, rows=rows, stop_at_failure=stop_at_failure, bound=bound)
        d = self.data
        C = len(self.channel_indices)
        out = Prediction.empty((d.n_steps, C, len(self.compared)), params)
        need = needed_rows(d.n_steps, rows)
        if params:
            pb.prefetch([p.omega for r, p in points.items() if need[r] and p.converged], params)
        for row, p in points.items():
            if not out.mark(row, p, d.frequency_hz[row]):
                continue
            out.frf[row], factor = self.frf_of(row, p)
            if params and need[row]:
                sens = point_sensitivities(pb, p, list(params))
                for name in params:
                    out.d_frf[name][row] = (
                        sens[name].d_outputs(pb.order_k[self.compared])[:, :C].T * factor
                    )
        if bound is not None and bound.exceeded:
            out.messages.append(BOUNDED_MESSAGE.format(limit=bound.limit, floor=bound.floor))
            out = dataclasses.replace(out, floor=bound.floor)
        left = np.flatnonzero(need & ~np.isin(np.arange(d.n_steps), list(points)))
        if left.size and out.floor is None:  # stop_at_failure stopped at a step without one
            out.messages.append(STOPPED_MESSAGE.format(n=left.size))
        sig = self.response_sigma(pb, points) if sigma else None
        return out, sig
