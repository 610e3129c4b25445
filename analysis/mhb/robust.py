"""A single-point solve that does not give up where a continuation would pass.

Damped Newton from the linear response can stall at the kinks of a piecewise-linear law (a
stop, a gap) where the residual is not differentiable: the line search then finds no descent.
Continuation passes there because each of its Newton solves starts close to the solution.
:func:`solve_point_robust` does the same at one frequency: if the direct solve fails, it
continues the solution in the force amplitude, by pseudo-arclength from a small fraction of
the force (where the response is close to linear) to the full force. The balance is linear in
the force scale ``lam``, ``R(X, lam) = X - G F_nl(X) - lam X_lin``, so ``dR/dlam = -X_lin``
exactly; the continuation goes through folds in the amplitude as well.
"""

from __future__ import annotations

import numpy as np

from analysis.mhb.aft import nonlinear_forces
from analysis.mhb.problem import HarmonicProblem
from analysis.mhb.solver import MHBPoint, NewtonSettings, _prepare, solve_point

__all__ = ["solve_point_robust"]

_START_FRACTION = 1 / 64
_MAX_STEPS = 2000
_MAX_STEP = 0.1
_MAX_ANGLE = 0.2  # rad between successive tangents
_MIN_TURN_STEP = 1e-3


class _AmplitudePath:
    """The balance at one frequency as a function of the scaled ``y = [X / xs, lam]``."""

    def __init__(self, problem: HarmonicProblem, omega: float, force, newton: NewtonSettings):
        self.pb, self.nt = problem, newton
        prep = _prepare(problem, omega, force)
        self.G, self.X_lin, self.wb = prep["G"], prep["X_lin"], prep["omega_b"]
        self.shape = self.X_lin.shape
        self.n = self.X_lin.size
        self.xs = max(np.abs(self.X_lin).max(), 1e-300)

    def residual(self, y: np.ndarray):
        X = y[:-1].reshape(self.shape) * self.xs
        F, dF = nonlinear_forces(self.pb, X, self.wb, True)
        R = X - (self.G @ F.ravel()).reshape(self.shape) - y[-1] * self.X_lin
        A = np.zeros((self.n + 1, self.n + 1))
        A[: self.n, : self.n] = (np.eye(self.n) - self.G @ dF) * self.xs
        A[: self.n, -1] = -self.X_lin.ravel()
        return R.ravel(), A, X

    def converged(self, R: np.ndarray, X: np.ndarray) -> bool:
        scale = max(np.abs(X).max(), self.xs)
        return np.abs(R).max() <= self.nt.rtol * scale + self.nt.atol

    def tangent(self, y: np.ndarray, prev: np.ndarray) -> np.ndarray:
        _, A, _ = self.residual(y)
        A[-1] = prev
        t = np.linalg.solve(A, np.append(np.zeros(self.n), 1.0))
        return t / np.linalg.norm(t)

    def correct(self, yp: np.ndarray, normal: np.ndarray, iterations: int = 12):
        """Newton on the balance and ``normal . (y - yp) = 0``; the solution or None."""
        y = yp.copy()
        for _ in range(iterations):
            R, A, X = self.residual(y)
            g = normal @ (y - yp)
            if self.converged(R, X) and abs(g) < 1e-10:
                return y
            A[-1] = normal
            try:
                y = y + np.linalg.solve(A, -np.append(R, g))
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(y)):
                return None
        return None

    def run(self, X_start: np.ndarray, lam_start: float) -> np.ndarray | None:
        """From a solution at ``lam_start`` to the one at ``lam = 1``: X there, or None."""
        y = np.append(X_start.ravel() / self.xs, lam_start)
        t = self.tangent(y, np.append(np.zeros(self.n), 1.0))
        ds = 0.02
        for _ in range(_MAX_STEPS):
            y_new = self.correct(y + ds * t, t)
            t_new = None if y_new is None else self.tangent(y_new, t)
            # a step that turns far may have jumped to another path: shorter, unless it is
            # already short (at a kink of a piecewise-linear law the tangent itself jumps)
            if t_new is None or (t @ t_new < np.cos(_MAX_ANGLE) and ds > _MIN_TURN_STEP):
                ds *= 0.5
                if ds < 1e-9:
                    return None
                continue
            if y_new[-1] >= 1.0:
                # the full force lies between y and y_new: fix lam = 1 from the interpolation
                s = (1.0 - y[-1]) / (y_new[-1] - y[-1])
                end = self.correct(y + s * (y_new - y), np.append(np.zeros(self.n), 1.0))
                if end is not None:
                    return end[:-1].reshape(self.shape) * self.xs
                ds *= 0.5  # land closer to the full force
                continue
            if y_new[-1] < 0:
                return None  # the path turned back past no force: not to the full force
            y, t, ds = y_new, t_new, min(1.5 * ds, _MAX_STEP)
        return None


def solve_point_robust(
    problem: HarmonicProblem,
    omega: float,
    force: np.ndarray,
    X0: np.ndarray | None = None,
    settings: NewtonSettings | None = None,
) -> MHBPoint:
    """Solve the balance at one frequency; where damped Newton fails, by continuation in the
    force amplitude.

    Parameters are those of :func:`~analysis.mhb.solver.solve_point`. ``X0`` (a neighbouring
    solution, the best predictor) is tried first, then the linear response, then the
    amplitude continuation from ``1/64`` of the force.

    Returns
    -------
    MHBPoint
        As from ``solve_point``; ``message`` says ``"converged (amplitude continuation)"``
        where the continuation was needed, or why everything failed.
    """
    st = settings or NewtonSettings()
    point = solve_point(problem, omega, force, X0, st)
    if point.converged or problem.n_nl == 0:
        return point
    if X0 is not None:
        q = solve_point(problem, omega, force, None, st)
        if q.converged:
            return q
    force = np.asarray(force, dtype=complex)
    start = solve_point(problem, omega, force * _START_FRACTION, None, st)
    if not start.converged:
        return point
    X = _AmplitudePath(problem, omega, force, st).run(start.X, _START_FRACTION)
    if X is None:
        point.message += "; the amplitude continuation did not reach the full force either"
        return point
    final = solve_point(problem, omega, force, X, st)
    if final.converged:
        final.message = "converged (amplitude continuation)"
        return final
    return point
