"""Levenberg-Marquardt and undamped Gauss-Newton on bounded, scaled least squares.

Minimises ``cost = 1/2 |r(theta)|^2`` with the analytic Jacobian. The damping follows Marquardt
(``(J^T J + lam diag(J^T J)) step = -J^T r``), raised on a rejected step and lowered on an
accepted one; ``lam = 0`` throughout gives the undamped Gauss-Newton of the paper's
cross-validation. Steps are projected onto the bounds.

References
----------
D. W. Marquardt, "An algorithm for least-squares estimation of nonlinear parameters",
J. SIAM 11 (1963) 431-441.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["OUT_OF_EVALUATIONS", "LeastSquaresResult", "least_squares_lm"]

#: The message of a fit stopped at its ``max_evaluations``.
OUT_OF_EVALUATIONS = "stopped: the evaluations allowed are used"


@dataclass
class LeastSquaresResult:
    """Result of :func:`least_squares_lm` (fields as scipy.optimize results).

    Attributes
    ----------
    x : ndarray, shape (n,)
        Solution in scaled coordinates.
    cost : float
        ``1/2 |r|^2`` at ``x``.
    fun : ndarray, shape (m,)
        Residuals at ``x``.
    jac : ndarray, shape (m, n)
    cov : ndarray, shape (n, n)
        ``(J^T J)^-1`` (the covariance for a unit-variance weighted residual).
    nfev, njev, nit : int
    success : bool
    message : str
    history : list of dict
        Per iteration: ``iteration, cost, lam, x, step_norm``.
    """

    x: np.ndarray
    cost: float
    fun: np.ndarray
    jac: np.ndarray
    cov: np.ndarray
    nfev: int
    njev: int
    nit: int
    success: bool
    message: str
    history: list[dict] = field(default_factory=list)


def least_squares_lm(
    fun: Callable[[np.ndarray, bool], tuple[np.ndarray, np.ndarray | None]],
    x0: np.ndarray,
    *,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    damped: bool = True,
    lam0: float = 1e-3,
    max_iterations: int = 50,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    callback: Callable[[dict], None] | None = None,
    max_evaluations: int | None = None,
    stop: Callable[[Sequence[dict], np.ndarray], str | None] | None = None,
    trial_cost: Callable[[np.ndarray, float], tuple[float, bool]] | None = None,
) -> LeastSquaresResult:
    """Bounded Levenberg-Marquardt (or undamped Gauss-Newton with ``damped=False``).

    Parameters
    ----------
    fun : callable
        ``fun(x, want_jac) -> (r, J)``: residuals shape (m,), Jacobian shape (m, n) or None.
        Non-finite residuals mark an infeasible point (the step is rejected).
    x0 : ndarray, shape (n,)
    bounds : (lower, upper), optional
    damped : bool
        False: plain Gauss-Newton steps (still projected onto the bounds, halved if they
        increase the cost).
    ftol, xtol : float
        Stop when the relative cost decrease and the step (relative to ``|x| + xtol``) are small.
    callback : callable, optional
        Called with each history entry.
    max_evaluations : int, optional
        Evaluations of ``fun`` allowed (with or without the Jacobian, the start's included):
        the fit stops before the first one past them, at the last accepted iterate, with
        :data:`OUT_OF_EVALUATIONS` as its message.
    stop : callable, optional
        ``stop(history, r)`` after each accepted iteration (``r`` the residuals there): a
        message to stop the fit there (not a success), or None to go on.
    trial_cost : callable, optional
        ``trial_cost(x, limit) -> (cost, exact)``: the cost of a trial step, which a trial
        needs only to compare with the current cost ``limit``: it may stop once the cost
        provably exceeds ``limit`` (``exact`` False: the trial fails, as it would with the
        whole cost). Must equal ``fun``'s cost where exact (e.g.
        :meth:`analysis.calibration.objective.FRFObjective.bounded_cost`); counted as one
        evaluation. Default: ``fun`` without the Jacobian.

    A stopped fit's covariance is that of its last iterate, not of an optimum.
    """
    x = np.asarray(x0, dtype=float).copy()
    lo, hi = bounds if bounds is not None else (np.full_like(x, -np.inf), np.full_like(x, np.inf))
    r, J = fun(x, True)
    nfev, njev = 1, 1
    if not np.all(np.isfinite(r)):
        raise ValueError("the start point gives non-finite residuals")
    cost = 0.5 * float(r @ r)
    lam = lam0 if damped else 0.0
    history = [{"iteration": 0, "cost": cost, "lam": lam, "x": x.tolist(), "step_norm": 0.0}]
    if callback:
        callback(history[-1])
    message, success, it = "maximum iterations reached", False, 0
    for it in range(1, max_iterations + 1):
        # every trial and the Jacobian at the accepted one within the allowance
        left = _TRIALS if max_evaluations is None else min(_TRIALS, max_evaluations - nfev - 1)
        if left < 1:
            message, it = OUT_OF_EVALUATIONS, it - 1
            break
        x_new, cost_new, lam, tries = _trial_step(
            fun, x, r, J, cost, lam, damped, lo, hi, left, trial_cost
        )
        nfev += tries
        if x_new is None:
            if tries < _TRIALS:
                message, it = OUT_OF_EVALUATIONS, it - 1
                break
            message, success = "no step reduces the cost (at a minimum within tolerance)", True
            break
        step_norm = float(np.linalg.norm(x_new - x))
        rel_dec = (cost - cost_new) / max(cost, 1e-300)
        x = x_new
        r, J = fun(x, True)
        nfev += 1
        njev += 1
        cost = 0.5 * float(r @ r)
        if damped:
            lam = max(lam / 3.0, 1e-12)
        history.append(
            {"iteration": it, "cost": cost, "lam": lam, "x": x.tolist(), "step_norm": step_norm}
        )
        if callback:
            callback(history[-1])
        reason = stop(history, r) if stop else None
        if reason is not None:
            message = reason
            break
        if rel_dec < ftol and step_norm < xtol * (np.linalg.norm(x) + xtol):
            message, success = "converged (cost and step below tolerance)", True
            break
        if rel_dec < ftol:
            message, success = "converged (relative cost decrease below ftol)", True
            break
    cov = _covariance(J)
    return LeastSquaresResult(x, cost, r, J, cov, nfev, njev, it, success, message, history)


def _covariance(J: np.ndarray) -> np.ndarray:
    """``(J^T J)^-1``, the pseudo-inverse where it is singular."""
    JTJ = J.T @ J
    try:
        return np.linalg.inv(JTJ)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(JTJ)


#: Trials of a step before the fit gives up (it is at a minimum within tolerance).
_TRIALS = 12


def _residual_cost(fun) -> Callable[[np.ndarray, float], tuple[float, bool]]:
    """A trial's cost from ``fun``'s residuals: ``(cost, True)``, ``inf`` where infeasible."""

    def cost_of(x: np.ndarray, limit: float) -> tuple[float, bool]:
        r, _ = fun(x, False)
        return (0.5 * float(r @ r) if np.all(np.isfinite(r)) else np.inf), True

    return cost_of


def _trial_step(fun, x, r, J, cost, lam, damped, lo, hi, trials: int = _TRIALS, trial_cost=None):
    """Up to ``trials`` trials of a step from ``x`` until one lowers the cost: the damping
    raised 5-fold after each failure (LM), or the Gauss-Newton step halved (undamped).
    ``trial_cost(x, limit) -> (cost, exact)`` prices a trial (default: from ``fun``'s
    residuals); it may stop once the cost is known to exceed ``limit`` (``exact`` False).

    Returns ``(x_new, cost_new, lam, evaluations)``; ``x_new`` None when no trial lowered it.
    """
    trial_cost = trial_cost or _residual_cost(fun)
    A = J.T @ J
    g = J.T @ r
    d = np.diag(A).copy()
    d[d <= 0] = 1.0
    factor, step = 1.0, None
    for tries in range(1, trials + 1):
        if damped or step is None:
            M = A + lam * np.diag(d)
            try:
                step = np.linalg.solve(M, -g)
            except np.linalg.LinAlgError:
                step = -np.linalg.lstsq(M, g, rcond=None)[0]
        x_new = np.clip(x + factor * step, lo, hi)
        cost_new, exact = trial_cost(x_new, cost)
        if exact and cost_new < cost:
            return x_new, cost_new, lam, tries
        if damped:
            lam = max(lam * 5.0, 1e-6)
        else:
            factor *= 0.5  # undamped: the Gauss-Newton direction, shortened
    return None, np.inf, lam, trials
