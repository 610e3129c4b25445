"""Pseudo-arclength continuation of periodic solutions in the excitation frequency.

Follows a branch through turning points (folds) at fixed force phasors, in the scaled
unknowns ``y = [X / x_scale, omega / omega_scale]``. The corrector solves the balance together
with the arclength condition ``t . (y - y_pred) = 0``; ``dR/domega`` is a central difference of
the residual (cheap: one AFT each side). Step length adapts to the corrector's effort.

References
----------
E. L. Allgower, K. Georg, *Introduction to Numerical Continuation Methods*, SIAM 2003, ch. 2.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from analysis.mhb.aft import nonlinear_forces
from analysis.mhb.problem import HarmonicProblem
from analysis.mhb.solver import MHBPoint, NewtonSettings, _prepare, _recover, solve_point
from analysis.mhb.stability import floquet_exponents

__all__ = ["Branch", "ContinuationSettings", "continue_branch"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ContinuationSettings:
    """Step control of the continuation.

    Parameters
    ----------
    ds : float
        Initial arclength step (scaled units).
    ds_min, ds_max : float
    max_points : int
    corrector_iterations : int
    stability : bool
        Compute Floquet exponents (Hill's method) at every point.
    """

    ds: float = 0.02
    ds_min: float = 1e-6
    ds_max: float = 0.2
    max_points: int = 2000
    corrector_iterations: int = 12
    stability: bool = True

    def __post_init__(self) -> None:
        if not (0 < self.ds_min <= self.ds <= self.ds_max):
            raise ValueError("ContinuationSettings: need 0 < ds_min <= ds <= ds_max")


@dataclass
class Branch:
    """A continued branch of periodic solutions.

    Attributes
    ----------
    points : list of MHBPoint
    stable : ndarray of bool or None
        Stability per point (None if not computed).
    folds : list of int
        Indices of points next to a turning point in frequency.
    message : str
        Why the continuation stopped.
    """

    points: list[MHBPoint]
    stable: np.ndarray | None
    folds: list[int] = field(default_factory=list)
    message: str = ""

    @property
    def omega(self) -> np.ndarray:
        return np.array([p.omega for p in self.points])

    def outputs(self) -> np.ndarray:
        """Output phasors at the orders, shape (n_points, n_orders, n_out)."""
        return np.stack([p.outputs() for p in self.points])


class _System:
    """Residual and Jacobians of the balance as functions of (X, omega)."""

    def __init__(self, problem: HarmonicProblem, force: np.ndarray):
        self.pb, self.force = problem, force
        self.s = problem.basis.size * problem.n_nl

    def residual(self, X: np.ndarray, omega: float, jac: bool = True):
        prep = _prepare(self.pb, omega, self.force)
        F, dF = nonlinear_forces(self.pb, X, prep["omega_b"], jac)
        R = X - (prep["G"] @ F.ravel()).reshape(X.shape) - prep["X_lin"]
        J = np.eye(self.s) - prep["G"] @ dF if jac else None
        return R.ravel(), J, prep, F, dF

    def d_omega(self, X: np.ndarray, omega: float) -> np.ndarray:
        h = 1e-7 * omega
        rp = self.residual(X, omega + h, False)[0]
        rm = self.residual(X, omega - h, False)[0]
        return (rp - rm) / (2 * h)


def continue_branch(
    problem: HarmonicProblem,
    omega_start: float,
    omega_end: float,
    force: np.ndarray,
    settings: ContinuationSettings | None = None,
    newton: NewtonSettings | None = None,
    *,
    X0: np.ndarray | None = None,
    until: Callable[[list[MHBPoint], list[int]], bool] | None = None,
) -> Branch:
    """Continue the periodic solution from ``omega_start`` until ``omega_end``.

    Parameters
    ----------
    problem : HarmonicProblem
    omega_start, omega_end : float
        Angular frequencies [rad/s]; either direction.
    force : ndarray, shape (n_orders, n_f), complex
        Fixed force phasors [N].
    settings, newton : optional
    X0 : ndarray, shape (2H+1, n_nl), optional
        Start of the first point's Newton solve (default the linear response): a solution
        already known nearby puts the branch on that solution's branch.
    until : callable, optional
        ``until(points, folds)`` is asked after each accepted point; True ends the branch
        there (message "stopped by the caller").

    Returns
    -------
    Branch
    """
    st = settings or ContinuationSettings()
    nt = newton or NewtonSettings()
    first = solve_point(problem, omega_start, force, X0=X0, settings=nt)
    if not first.converged:
        return Branch([first], None, [], f"no solution at the start: {first.message}")
    sysm = _System(problem, force)
    shape = first.X.shape
    xs = max(np.abs(first.X).max(), 1e-12)
    ws = abs(omega_start)
    direction = np.sign(omega_end - omega_start) or 1.0

    def tangent(X, omega, prev_t=None):
        _, J, *_ = sysm.residual(X, omega)
        Rw = sysm.d_omega(X, omega)
        A = np.zeros((sysm.s + 1, sysm.s + 1))
        A[: sysm.s, : sysm.s] = J * xs
        A[: sysm.s, -1] = Rw * ws
        if prev_t is None:
            tX = np.linalg.solve(J * xs, -Rw * ws)
            t = np.append(tX, 1.0) * direction
        else:
            A[-1] = prev_t
            t = np.linalg.solve(A, np.append(np.zeros(sysm.s), 1.0))
        return t / np.linalg.norm(t)

    pts = [first]
    y = np.append(first.X.ravel() / xs, omega_start / ws)
    t = tangent(first.X, omega_start)
    ds = st.ds
    folds: list[int] = []
    message = "reached the end frequency"
    while len(pts) < st.max_points:
        yp = y + ds * t
        yc, ok, its = yp.copy(), False, 0
        for _ in range(st.corrector_iterations):
            its += 1
            X = yc[:-1].reshape(shape) * xs
            w = yc[-1] * ws
            R, J, prep, F, dF = sysm.residual(X, w)
            g = t @ (yc - yp)
            if np.abs(R).max() <= nt.rtol * max(np.abs(X).max(), xs) and abs(g) < 1e-10:
                ok = True
                break
            A = np.zeros((sysm.s + 1, sysm.s + 1))
            A[: sysm.s, : sysm.s] = J * xs
            A[: sysm.s, -1] = sysm.d_omega(X, w) * ws
            A[-1] = t
            try:
                dy = np.linalg.solve(A, -np.append(R / 1.0, g))
            except np.linalg.LinAlgError:
                break
            yc = yc + dy
            if not np.all(np.isfinite(yc)):
                break
        if not ok:
            ds *= 0.5
            if ds < st.ds_min:
                message = "step size fell below ds_min"
                break
            continue
        X = yc[:-1].reshape(shape) * xs
        w = yc[-1] * ws
        p = MHBPoint(
            w,
            X,
            problem.basis.to_complex(X),
            problem.basis.to_complex(F),
            _recover(problem, prep, F),
            prep["Fk"],
            True,
            its,
            float(np.abs(R).max()),
            "converged",
            problem.order_k,
        )
        p.lin = {"prep": prep, "dF": dF, "F": F}
        t_new = tangent(X, w, t)
        if np.sign(t_new[-1]) != np.sign(t[-1]):
            if folds and len(pts) - folds[-1] <= 2:
                folds.pop()  # the tangent wobbled across one fold: not a new fold
            else:
                folds.append(len(pts))
        pts.append(p)
        y, t = yc, t_new
        ds = min(ds * (1.5 if its <= 4 else 1.0), st.ds_max)
        if (w - omega_end) * direction >= 0:
            break
        if until is not None and until(pts, folds):
            message = "stopped by the caller"
            break
    else:
        message = "maximum number of points"
    stable = None
    if st.stability:
        stable = np.array([floquet_exponents(problem, p).stable for p in pts])
    return Branch(pts, stable, folds, message)
