"""Time integration to periodic steady state: the independent reference for the balance.

The same structure (a :class:`~analysis.linear.reduced.SecondOrderModel`) and the same element
laws are integrated with scipy's explicit Runge-Kutta (DOP853); the periodic steady state is
found by shooting (Newton on the period map, started from the previous step's end state) and
the final period, a plain integrated trajectory that repeats itself, is projected onto the
harmonics.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from analysis.linear.reduced import SecondOrderModel, reduced_model
from analysis.mhb.problem import HarmonicProblem

__all__ = ["SteadyState", "integrate_steady_state", "state_from_balance", "time_domain_model"]

log = logging.getLogger(__name__)


@dataclass
class SteadyState:
    """Result of integrating to periodic steady state.

    Attributes
    ----------
    q_out : ndarray, shape (H+1, n_out), complex
        Output phasors from the last period [m].
    q_nl : ndarray, shape (H+1, n_nl), complex
    state : ndarray, shape (2 m,)
        State at the end (to start the next step from).
    periods : int
        Base periods integrated.
    periodicity : float
        Final ``max|y(T) - y(0)| / max|y|`` over one period.
    converged : bool
    """

    q_out: np.ndarray
    q_nl: np.ndarray
    state: np.ndarray
    periods: int
    periodicity: float
    converged: bool
    order_k: np.ndarray

    def outputs(self) -> np.ndarray:
        """Output phasors at the excitation orders, shape (n_orders, n_out)."""
        return self.q_out[self.order_k]


def time_domain_model(problem: HarmonicProblem) -> SecondOrderModel:
    """The second-order model of a problem's linear part (augmented at loaded DOFs)."""
    return reduced_model(problem.linear, list(problem.nl_dofs) + list(problem.force_dofs))


def _ode(problem: HarmonicProblem, mdl: SecondOrderModel, omega: float, force: np.ndarray):
    """Right-hand sides of the state equation and of its variational equation."""
    T = mdl.T
    Tn, Tf = T[problem.nl_dofs], T[problem.force_dofs]
    L = problem.L
    Fk = problem.force_harmonics(force)
    kk = np.arange(Fk.shape[0])
    wb = omega / problem.denominator
    Minv = np.linalg.inv(mdl.M)
    A_K, A_C = Minv @ mdl.K, Minv @ mdl.C
    Bf, Bn = Minv @ Tf.T, Minv @ Tn.T
    G = L @ Tn  # element relative displacement from z, shape (n_e, m)
    BG = Bn @ L.T  # acceleration per element force, shape (m, n_e)
    els = [a.element for a in problem.attachments]
    m = mdl.size

    def forces(z, zd, jac):
        u, v = G @ z, G @ zd
        f = np.empty(len(els))
        kt = np.empty(len(els))
        ct = np.empty(len(els))
        for e, el in enumerate(els):
            ev = el.evaluate(u[e : e + 1], v[e : e + 1])
            f[e], kt[e], ct[e] = ev.f[0], ev.df_du[0], ev.df_dv[0]
        return f, kt, ct

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        z, zd = y[:m], y[m : 2 * m]
        f_ext = (Fk * np.exp(1j * kk * wb * t)[:, None]).sum(axis=0).real
        acc = Bf @ f_ext - A_K @ z - A_C @ zd
        if els:
            f, kt, ct = forces(z, zd, False)
            acc = acc + BG @ f
        return np.concatenate([zd, acc])

    def rhs_var(t: float, y: np.ndarray) -> np.ndarray:
        z, zd = y[:m], y[m : 2 * m]
        Y = y[2 * m :].reshape(2 * m, 2 * m)
        f_ext = (Fk * np.exp(1j * kk * wb * t)[:, None]).sum(axis=0).real
        acc = Bf @ f_ext - A_K @ z - A_C @ zd
        AK, AC = A_K, A_C
        if els:
            f, kt, ct = forces(z, zd, True)
            acc = acc + BG @ f
            AK = A_K - (BG * kt) @ G
            AC = A_C - (BG * ct) @ G
        dY = np.concatenate([Y[m:], -AK @ Y[:m] - AC @ Y[m:]])
        return np.concatenate([zd, acc, dY.ravel()])

    return rhs, rhs_var, wb, m


def integrate_steady_state(
    problem: HarmonicProblem,
    omega: float,
    force: np.ndarray,
    state0: np.ndarray | None = None,
    *,
    model: SecondOrderModel | None = None,
    rtol: float = 1e-9,
    periodic_tol: float = 1e-7,
    max_periods: int = 1500,
    transient_block: int = 25,
) -> SteadyState:
    """Integrate ``M z'' + C z' + K z = B_f^T f(t) + B_n^T f_nl`` to periodic steady state.

    Starting from ``state0`` (as a stepped test starts each step from the previous one's end),
    the period map ``y0 -> y(T)`` is iterated with Newton's method on ``y(T) - y0 = 0``
    (shooting), its Jacobian the monodromy matrix from the variational equations; a step that
    does not reduce the mismatch falls back to plain periods (the physical transient). The
    result is a trajectory of scipy's DOP853 that repeats itself to ``periodic_tol``.

    Parameters
    ----------
    problem : HarmonicProblem
        Elements, DOFs, orders and harmonic basis (used only to project the result).
    omega : float
        Fundamental angular frequency [rad/s].
    force : ndarray, shape (n_orders, n_f), complex
        Force phasors [N]; the drive starts at phase zero at ``t = 0``.
    state0 : ndarray, shape (2 m,), optional
        Start state (the previous step's end state); default at rest.
    model : SecondOrderModel, optional
        Default :func:`time_domain_model` of the problem.
    rtol : float
        Relative tolerance of the integrator.
    periodic_tol : float
        Accept when ``max|y(T) - y(0)|`` is below this fraction of ``max|y|``.
    max_periods : int
        Bound on the periods integrated.
    transient_block : int
        Plain periods integrated when a Newton step does not contract.

    Returns
    -------
    SteadyState
    """
    mdl = model or time_domain_model(problem)
    rhs, rhs_var, wb, m = _ode(problem, mdl, omega, force)
    period = 2 * np.pi / wb
    b = problem.basis
    t_eval = np.append(np.arange(b.n_time) * period / b.n_time, period)
    y = np.zeros(2 * m) if state0 is None else np.asarray(state0, dtype=float).copy()
    I = np.eye(2 * m)

    def one_period(y0, variational):
        scale = max(np.abs(y0).max(), 1e-12)
        if variational:
            sol = solve_ivp(
                rhs_var,
                (0.0, period),
                np.concatenate([y0, I.ravel()]),
                method="DOP853",
                rtol=rtol,
                atol=rtol * 1e-3 * scale,
            )
            return sol.y[: 2 * m, -1], sol.y[2 * m :, -1].reshape(2 * m, 2 * m)
        sol = solve_ivp(
            rhs,
            (0.0, period),
            y0,
            method="DOP853",
            rtol=rtol,
            atol=rtol * 1e-3 * scale,
            t_eval=t_eval,
        )
        return sol, None

    err, periods = np.inf, 0
    while periods < max_periods:
        yT, Phi = one_period(y, True)
        periods += 1
        r = yT - y
        err = np.abs(r).max() / max(np.abs(yT).max(), 1e-300)
        if err < periodic_tol:
            break
        try:
            y_new = y + np.linalg.solve(Phi - I, -r)
        except np.linalg.LinAlgError:
            y_new = yT
        yT2, _ = one_period(y_new, True)
        periods += 1
        if np.abs(yT2 - y_new).max() < 0.5 * np.abs(r).max():
            y = y_new
            continue
        # Newton did not contract (far from the orbit, e.g. after a jump between branches):
        # let the physical transient act for a block of periods, then try again.
        y = yT
        for _ in range(transient_block):
            sol, _ = one_period(y, False)
            y = sol.y[:, -1]
            periods += 1
    sol, _ = one_period(y, False)
    periods += 1
    z_t = sol.y[:m, :-1].T  # (N, m) over the final period, t from 0
    To, Tn = mdl.T[problem.output_dofs], mdl.T[problem.nl_dofs]
    q_out = b.to_complex(b.from_time(z_t @ To.T))
    q_nl = b.to_complex(b.from_time(z_t @ Tn.T))
    end = sol.y[:, -1]
    err = np.abs(end - y).max() / max(np.abs(end).max(), 1e-300)
    return SteadyState(
        q_out, q_nl, end, periods, float(err), bool(err < 10 * periodic_tol), problem.order_k
    )


def state_from_balance(
    problem: HarmonicProblem, point, model: SecondOrderModel | None = None
) -> np.ndarray:
    """State ``[z, z']`` at ``t = 0`` of a balanced periodic solution, shape (2 m,).

    The generalised coordinates follow from the converged nonlinear and external forces of the
    point, ``Z_k = (K - (k w)^2 M + i k w C)^-1 T^T F_k``. Used to start a time integration where
    a stepped test would be: at the previous step's steady state.
    """
    mdl = model or time_domain_model(problem)
    w = problem.harmonic_omegas(point.omega)
    T = mdl.T
    Fz = point.force @ T[problem.force_dofs] + point.f_nl @ T[problem.nl_dofs]  # (H+1, m)
    Z = np.empty_like(Fz)
    for k, wk in enumerate(w):
        Z[k] = np.linalg.solve(mdl.K - wk**2 * mdl.M + 1j * wk * mdl.C, Fz[k])
    Z[0] = Z[0].real
    z0 = Z.real.sum(axis=0)
    zd0 = (1j * w[:, None] * Z).real.sum(axis=0)
    return np.concatenate([z0, zd0])
