"""Pseudo-arclength continuation of periodic solutions in the excitation frequency.

Follows a branch through turning points (folds) at fixed force phasors, in the scaled
unknowns ``y = [X / x_scale, omega / omega_scale]``. The corrector solves the balance together
with the arclength condition ``t . (y - y_pred) = 0``; ``dR/domega`` is a central difference of
the residual (cheap: one AFT each side). Step length adapts to the corrector's effort and,
with ``ContinuationSettings.max_angle``, to the curvature: a step whose tangent turns by more
than that angle is retried shorter, so that the chord between two points stays close to the
curve (its sagitta is about ``ds * angle / 8`` in the scaled unknowns).

Turning points (folds) and amplitude peaks are located after the run, on request
(:meth:`Branch.turning_points`, :meth:`Branch.peaks`): between the two points that bracket one,
the curve is parametrised by the position ``s`` along their chord, each ``s`` solved to the
Newton tolerance, and the root of the tangent's frequency component (a fold) or of the
amplitude's derivative along the curve (a peak) is found by Brent's method.

References
----------
E. L. Allgower, K. Georg, *Introduction to Numerical Continuation Methods*, SIAM 2003, ch. 2.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from analysis.mhb.aft import nonlinear_forces
from analysis.mhb.problem import HarmonicProblem
from analysis.mhb.solver import MHBPoint, NewtonSettings, _prepare, _recover, solve_point
from analysis.mhb.stability import floquet_exponents

__all__ = ["Branch", "ContinuationSettings", "Located", "continue_branch"]

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
    max_angle : float, optional
        Largest angle [rad] between the unit tangents of successive points (scaled unknowns):
        curvature control. A step that turns more is retried shorter (down to ``ds_min``) and
        the next step is shortened in proportion. None (the default) adapts the step to the
        corrector's effort only.
    """

    ds: float = 0.02
    ds_min: float = 1e-6
    ds_max: float = 0.2
    max_points: int = 2000
    corrector_iterations: int = 12
    stability: bool = True
    max_angle: float | None = None

    def __post_init__(self) -> None:
        if not (0 < self.ds_min <= self.ds <= self.ds_max):
            raise ValueError("ContinuationSettings: need 0 < ds_min <= ds <= ds_max")
        if self.max_angle is not None and not (0 < self.max_angle < np.pi / 2):
            raise ValueError(
                f"ContinuationSettings.max_angle: need 0 < max_angle < pi/2 rad, "
                f"got {self.max_angle!r}"
            )


@dataclass(frozen=True)
class Located:
    """A fold or an amplitude peak located on a branch.

    Attributes
    ----------
    kind : str
        ``"fold"`` or ``"peak"``.
    omega : float
        Angular frequency [rad/s] to the Newton tolerance of the balance.
    point : MHBPoint
        The periodic solution there.
    after : int
        Index of the branch point before it (it lies between points ``after`` and
        ``after + 1``).
    amplitude : float
        For a peak, the amplitude located [m]; for a fold, that of output 0 at order 0.
    """

    kind: str
    omega: float
    point: MHBPoint
    after: int
    amplitude: float


@dataclass
class Branch:
    """A continued branch of periodic solutions.

    Attributes
    ----------
    points : list of MHBPoint
    stable : ndarray of bool or None
        Stability per point (None if not computed).
    folds : list of int
        Index of the first point past each turning point in frequency, as seen while stepping
        (one sign change of the tangent's frequency component that reverts within two points
        is not counted; the caller's ``until`` sees this list). The folds themselves, every one
        and located to the solver's tolerance, are :meth:`turning_points`.
    message : str
        Why the continuation stopped.
    tangents : ndarray, shape (n_points, n_unknowns + 1) or None
        Unit tangent at each point in the scaled unknowns.
    """

    points: list[MHBPoint]
    stable: np.ndarray | None
    folds: list[int] = field(default_factory=list)
    message: str = ""
    tangents: np.ndarray | None = None
    _curve: _Curve | None = field(default=None, repr=False)
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def omega(self) -> np.ndarray:
        return np.array([p.omega for p in self.points])

    def outputs(self) -> np.ndarray:
        """Output phasors at the orders, shape (n_points, n_orders, n_out)."""
        return np.stack([p.outputs() for p in self.points])

    def turning_points(self) -> list[Located]:
        """Every turning point in frequency (fold), located to the Newton tolerance.

        Each sign change of the tangent's frequency component between two points is one fold
        (two in one interval are found if the interval's chord shows them). Computed on the
        first call (a few Newton solves per fold) and kept.
        """
        if "folds" not in self._cache:
            self._cache["folds"] = [] if self._curve is None else self._curve.folds(self)
        return list(self._cache["folds"])

    def peaks(self, output: int = 0, order: int = 0) -> list[Located]:
        """Every local maximum of the amplitude of an output at an excitation order along
        the branch, located to the Newton tolerance.

        Parameters
        ----------
        output : int
            Column of the problem's output DOFs.
        order : int
            Index into the problem's excitation orders.
        """
        key = ("peaks", output, order)
        if key not in self._cache:
            self._cache[key] = [] if self._curve is None else self._curve.peaks(self, output, order)
        return list(self._cache[key])


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
        """``dR/domega`` at fixed ``X``: ``-dG/dw F - G dF/dw - dX_lin/dw``, the receptances'
        derivatives exact (:meth:`HarmonicProblem.receptance_rates`), the forces' (through
        the velocities) by central differences. Differencing the whole residual instead
        evaluated the receptances at two new frequencies each time, most of a step's work."""
        pb = self.pb
        prep = _prepare(pb, omega, self.force)
        rates = pb.receptance_rates(omega)
        wb = prep["omega_b"]
        h = 1e-7 * wb
        F, _ = nonlinear_forces(pb, X, wb, False)
        Fp, _ = nonlinear_forces(pb, X, wb + h, False)
        Fm, _ = nonlinear_forces(pb, X, wb - h, False)
        dF = (Fp - Fm) / (2 * h * pb.denominator)
        Fk = prep["Fk"]
        dX_lin = pb.basis.from_complex(np.matmul(rates["nf"], Fk[:, :, None])[:, :, 0])
        return -(rates["G"] @ F.ravel()) - prep["G"] @ dF.ravel() - dX_lin.ravel()


@dataclass
class _Corrected:
    y: np.ndarray
    ok: bool
    iterations: int
    R: np.ndarray
    prep: dict
    F: np.ndarray
    dF: np.ndarray


class _Curve:
    """The balance in the scaled unknowns ``y = [X / xs, omega / ws]`` of one branch."""

    def __init__(self, problem: HarmonicProblem, force, newton: NewtonSettings, first: MHBPoint):
        self.pb, self.force, self.nt = problem, force, newton
        self.sysm = _System(problem, force)
        self.shape = first.X.shape
        self.xs = max(np.abs(first.X).max(), 1e-12)
        self.ws = abs(first.omega)

    def scaled(self, p: MHBPoint) -> np.ndarray:
        return np.append(p.X.ravel() / self.xs, p.omega / self.ws)

    def unscaled(self, y: np.ndarray) -> tuple[np.ndarray, float]:
        return y[:-1].reshape(self.shape) * self.xs, y[-1] * self.ws

    def bordered(self, J: np.ndarray, X: np.ndarray, w: float, row: np.ndarray) -> np.ndarray:
        n = self.sysm.s
        A = np.zeros((n + 1, n + 1))
        A[:n, :n] = J * self.xs
        A[:n, -1] = self.sysm.d_omega(X, w) * self.ws
        A[-1] = row
        return A

    def tangent(self, X, omega, prev_t=None, direction: float = 1.0) -> np.ndarray:
        """Unit tangent; oriented along ``prev_t`` (or in ``direction`` of frequency)."""
        sysm = self.sysm
        _, J, *_ = sysm.residual(X, omega)
        Rw = sysm.d_omega(X, omega)
        if prev_t is None:
            tX = np.linalg.solve(J * self.xs, -Rw * self.ws)
            t = np.append(tX, 1.0) * direction
        else:
            A = np.zeros((sysm.s + 1, sysm.s + 1))
            A[: sysm.s, : sysm.s] = J * self.xs
            A[: sysm.s, -1] = Rw * self.ws
            A[-1] = prev_t
            t = np.linalg.solve(A, np.append(np.zeros(sysm.s), 1.0))
        return t / np.linalg.norm(t)

    def correct(self, yp: np.ndarray, normal: np.ndarray, iterations: int) -> _Corrected:
        """Newton on the balance and ``normal . (y - yp) = 0`` from ``yp``."""
        yc, ok, its = yp.copy(), False, 0
        for _ in range(iterations):
            its += 1
            X, w = self.unscaled(yc)
            R, J, prep, F, dF = self.sysm.residual(X, w)
            g = normal @ (yc - yp)
            if np.abs(R).max() <= self.nt.rtol * max(np.abs(X).max(), self.xs) and abs(g) < 1e-10:
                ok = True
                break
            A = self.bordered(J, X, w, normal)
            try:
                dy = np.linalg.solve(A, -np.append(R / 1.0, g))
            except np.linalg.LinAlgError:
                break
            yc = yc + dy
            if not np.all(np.isfinite(yc)):
                break
        return _Corrected(yc, ok, its, R, prep, F, dF)

    def point(self, c: _Corrected) -> MHBPoint:
        pb = self.pb
        X, w = self.unscaled(c.y)
        p = MHBPoint(
            w,
            X,
            pb.basis.to_complex(X),
            pb.basis.to_complex(c.F),
            _recover(pb, c.prep, c.F),
            c.prep["Fk"],
            True,
            c.iterations,
            float(np.abs(c.R).max()),
            "converged",
            pb.order_k,
        )
        p.lin = {"prep": c.prep, "dF": c.dF, "F": c.F}
        return p

    # -- location of folds and peaks on the chord between two points ---------------------
    def on_chord(self, y0: np.ndarray, y1: np.ndarray, s: float):
        """The solution at position ``s`` (0..1) along the chord from y0 to y1, and its unit
        tangent oriented along the chord; None where the corrector fails."""
        d = y1 - y0
        e = d / np.linalg.norm(d)
        c = self.correct(y0 + s * d, e, max(self.nt.max_iterations, 20))
        if not c.ok:
            return None
        X, w = self.unscaled(c.y)
        _, J, *_ = self.sysm.residual(X, w)
        t = np.linalg.solve(self.bordered(J, X, w, e), np.append(np.zeros(self.sysm.s), 1.0))
        return c, t / np.linalg.norm(t)

    def amplitude(self, y: np.ndarray, output: int, order: int) -> float:
        X, w = self.unscaled(y)
        prep = _prepare(self.pb, w, self.force)
        F, _ = nonlinear_forces(self.pb, X, prep["omega_b"], False)
        return float(abs(_recover(self.pb, prep, F)[self.pb.order_k[order], output]))

    def slope(self, y: np.ndarray, t: np.ndarray, output: int, order: int) -> float:
        """Derivative of the amplitude along the unit tangent (central difference of an
        explicit smooth function of y, not of Newton solutions)."""
        h = 1e-6
        a1, a0 = self.amplitude(y + h * t, output, order), self.amplitude(y - h * t, output, order)
        return (a1 - a0) / (2 * h)

    def _root(self, y0, y1, fun, after: int, kind: str) -> list[tuple]:
        """Roots of ``fun(c, t)`` along the chord y0 -> y1: sign changes between the ends, or
        between 8 samples when the ends agree (two roots in one interval)."""
        cache: dict[float, float] = {}

        def g(s: float) -> float:
            if s not in cache:
                res = self.on_chord(y0, y1, s)
                cache[s] = np.nan if res is None else fun(*res)
            return cache[s]

        grid = [0.0, 1.0] if g(0.0) * g(1.0) < 0 else list(np.linspace(0.0, 1.0, 9))
        found = []
        for a, b in zip(grid[:-1], grid[1:], strict=True):
            ga, gb = g(a), g(b)
            if not (np.isfinite(ga) and np.isfinite(gb)) or ga * gb >= 0:
                continue
            try:
                s = brentq(g, a, b, xtol=1e-13, rtol=4 * np.finfo(float).eps)
            except (ValueError, RuntimeError):
                continue
            res = self.on_chord(y0, y1, s)
            if res is not None:
                found.append((self.point(res[0]), after, kind))
        return found

    def _located(self, found: list[tuple], output: int, order: int) -> list[Located]:
        return [
            Located(kind, p.omega, p, after, float(abs(p.q_out[self.pb.order_k[order], output])))
            for p, after, kind in found
        ]

    def folds(self, branch: Branch) -> list[Located]:
        T = branch.tangents
        ys = [self.scaled(p) for p in branch.points]
        found = []
        for i in range(len(ys) - 1):
            if np.sign(T[i][-1]) != np.sign(T[i + 1][-1]):
                found += self._root(ys[i], ys[i + 1], lambda c, t: t[-1], i, "fold")
        return self._located(found, 0, 0)

    def peaks(self, branch: Branch, output: int, order: int) -> list[Located]:
        amp = np.abs(branch.outputs()[:, order, output])
        ys = [self.scaled(p) for p in branch.points]
        found = []
        for i in range(1, len(ys) - 1):
            if not (amp[i] > amp[i - 1] and amp[i] >= amp[i + 1]):
                continue
            # the peak lies after point i if the amplitude still rises there
            res = self.on_chord(ys[i - 1], ys[i], 1.0)
            rising = res is not None and self.slope(res[0].y, res[1], output, order) > 0
            j = i if rising else i - 1
            found += self._root(
                ys[j], ys[j + 1], lambda c, t: self.slope(c.y, t, output, order), j, "peak"
            )
        return self._located(found, output, order)


def _note_fold(folds: list[int], t_old: np.ndarray, t_new: np.ndarray, n_points: int) -> None:
    if np.sign(t_new[-1]) != np.sign(t_old[-1]):
        if folds and n_points - folds[-1] <= 2:
            folds.pop()  # the tangent wobbled across one fold: not a new fold
        else:
            folds.append(n_points)


def _angle(t_old: np.ndarray, t_new: np.ndarray) -> float:
    return float(np.arccos(np.clip(t_old @ t_new, -1.0, 1.0)))


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
    curve = _Curve(problem, force, nt, first)
    direction = np.sign(omega_end - omega_start) or 1.0
    pts = [first]
    y = curve.scaled(first)
    t = curve.tangent(first.X, omega_start, direction=direction)
    tangents = [t]
    ds = st.ds
    folds: list[int] = []
    message = "reached the end frequency"
    while len(pts) < st.max_points:
        c = curve.correct(y + ds * t, t, st.corrector_iterations)
        if not c.ok:
            ds *= 0.5
            if ds < st.ds_min:
                message = "step size fell below ds_min"
                break
            continue
        X, w = curve.unscaled(c.y)
        t_new = curve.tangent(X, w, t)
        ds_next = _next_step(st, ds, c.iterations, _angle(t, t_new))
        if ds_next is None:  # turned too far: the same step again, shorter
            ds = max(0.5 * ds, st.ds_min)
            continue
        _note_fold(folds, t, t_new, len(pts))
        pts.append(curve.point(c))
        tangents.append(t_new)
        y, t, ds = c.y, t_new, ds_next
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
    return Branch(pts, stable, folds, message, np.array(tangents), curve)


def _next_step(st: ContinuationSettings, ds: float, iterations: int, angle: float):
    """The next step length after an accepted one, or None to retry it shorter (the tangent
    turned by more than ``max_angle`` and the step can still shrink)."""
    ds_next = min(ds * (1.5 if iterations <= 4 else 1.0), st.ds_max)
    if st.max_angle is None:
        return ds_next
    if angle > st.max_angle and ds > st.ds_min:
        return None
    if angle > 0:
        # keep the next turn near 0.8 max_angle, assuming the curvature stays as it is
        ds_next = min(ds_next, max(ds * 0.8 * st.max_angle / angle, st.ds_min))
    return ds_next
