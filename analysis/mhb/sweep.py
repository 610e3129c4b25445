"""Stepped solution in the order of a stepped-sine test (warm start from the previous step)."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from analysis.mhb.problem import HarmonicProblem
from analysis.mhb.solver import MHBPoint, NewtonSettings, solve_point

__all__ = ["SweepResult", "solve_steps"]

log = logging.getLogger(__name__)


@dataclass
class SweepResult:
    """Solutions of consecutive steps.

    Attributes
    ----------
    points : list of MHBPoint
        One per step, in the order solved.
    """

    points: list[MHBPoint]

    @property
    def converged(self) -> np.ndarray:
        """Per-step convergence flags, shape (n_steps,)."""
        return np.array([p.converged for p in self.points])

    @property
    def omega(self) -> np.ndarray:
        """Fundamental angular frequency per step [rad/s], shape (n_steps,)."""
        return np.array([p.omega for p in self.points])

    def outputs(self) -> np.ndarray:
        """Output phasors at the excitation orders, shape (n_steps, n_orders, n_out) [m]."""
        return np.stack([p.outputs() for p in self.points])

    def frf(self) -> np.ndarray:
        """Multi-harmonic FRFs, shape (n_steps, n_orders, n_out) [m/N]."""
        return np.stack([p.frf() for p in self.points])

    def failures(self) -> list[tuple[int, str]]:
        """(step index, reason) of every step that did not converge."""
        return [(i, p.message) for i, p in enumerate(self.points) if not p.converged]


def _substep(problem, omega0, force0, X0, omega1, force1, settings, depth) -> MHBPoint:
    """Reach (omega1, force1) from a converged (omega0, force0, X0) in halving sub-steps."""
    n_sub = 2**depth
    X = X0
    point = None
    for s in range(1, n_sub + 1):
        t = s / n_sub
        w = (1 - t) * omega0 + t * omega1
        f = (1 - t) * force0 + t * force1
        point = solve_point(problem, w, f, X, settings)
        if not point.converged:
            return point
        X = point.X
    return point


def _force_homotopy(problem, omega, force, settings, n_sub) -> MHBPoint:
    """Reach a point by raising the force from 1/n_sub of its value (robust first start)."""
    X, point = None, None
    for s in range(1, n_sub + 1):
        point = solve_point(problem, omega, force * (s / n_sub), X, settings)
        if not point.converged:
            return point
        X = point.X
    return point


def _rescue(problem, omega, force, p, last, last_force, settings, max_depth) -> MHBPoint:
    """A step that failed from the previous solution: from its linear response, then in
    sub-steps from the last converged step, then by raising the force (``p`` if all fail)."""
    # the branch followed may have ended (a jump): try the linear response first
    q = solve_point(problem, omega, force, None, settings)
    if q.converged:
        return q
    if last is not None:
        for depth in range(1, max_depth + 1):
            p = _substep(problem, last.omega, last_force, last.X, omega, force, settings, depth)
            if p.converged:
                return p
    q = _force_homotopy(problem, omega, force, settings, 2**max_depth)
    return q if q.converged else p


def solve_steps(
    problem: HarmonicProblem,
    omega: np.ndarray,
    force: np.ndarray,
    *,
    X0: np.ndarray | None = None,
    settings: NewtonSettings | None = None,
    max_substep_depth: int = 4,
) -> SweepResult:
    """Solve consecutive steps, each warm-started from the previous converged one.

    Parameters
    ----------
    problem : HarmonicProblem
    omega : ndarray, shape (n_steps,)
        Fundamental angular frequencies [rad/s] in the order a test steps through them.
    force : ndarray, shape (n_steps, n_orders, n_f) or (n_orders, n_f) or (n_steps, n_orders)
        Force phasors per step (e.g. the measured ones) [N]; one set broadcasts to all steps.
    X0 : ndarray, optional
        Start for the first step (default: its linear response).
    max_substep_depth : int
        When a step fails from the previous solution (secant-predicted, then as it was) it is
        started from its linear response (the branch followed may have ended: a jump), then
        approached in up to ``2**max_substep_depth`` sub-steps of frequency and force, then by
        raising the force from a small fraction in as many sub-steps. A step that still fails
        is returned flagged (``converged=False``) with the reason, and the next step starts
        from the last converged one.

    Returns
    -------
    SweepResult
    """
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    force = np.asarray(force, dtype=complex)
    n_o, n_f = len(problem.orders), len(problem.force_dofs)
    if force.ndim == 1 or (force.ndim == 2 and force.shape == (n_o, n_f)):
        force = np.broadcast_to(force.reshape(n_o, n_f), (omega.size, n_o, n_f))
    elif force.ndim == 2:
        force = force.reshape(omega.size, n_o, n_f)
    if force.shape != (omega.size, n_o, n_f):
        raise ValueError(
            f"force: expected shape (n_steps={omega.size}, n_orders={n_o}, n_f={n_f}), "
            f"got {force.shape}"
        )
    problem.prefetch(omega)
    points: list[MHBPoint] = []
    last: MHBPoint | None = None
    last_force = None
    X, prev = X0, None
    for i in range(omega.size):
        X_start = X
        if prev is not None and last is not None and prev.omega != last.omega:
            # secant predictor along the frequency steps
            r = (omega[i] - last.omega) / (last.omega - prev.omega)
            if 0 < r <= 2:
                X_start = last.X + r * (last.X - prev.X)
        p = solve_point(problem, omega[i], force[i], X_start, settings)
        if not p.converged and X_start is not X:
            p = solve_point(problem, omega[i], force[i], X, settings)
        if not p.converged:
            p = _rescue(
                problem, omega[i], force[i], p, last, last_force, settings, max_substep_depth
            )
        if not p.converged:
            log.warning(
                "MHB step %d (%.4g Hz) did not converge: %s", i, omega[i] / (2 * np.pi), p.message
            )
        else:
            prev, last, last_force, X = last, p, force[i], p.X
        points.append(p)
    return SweepResult(points)
