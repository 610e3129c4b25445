"""Time integration to periodic steady state: the independent reference for the balance.

The same structure (a :class:`~analysis.linear.reduced.SecondOrderModel`) and the same element
laws are integrated with scipy's explicit Runge-Kutta (DOP853) one base period at a time until
the state repeats, as a stepped-sine test would settle; the last period is then projected onto
the harmonics.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from analysis.linear.reduced import SecondOrderModel, reduced_model
from analysis.mhb.problem import HarmonicProblem

__all__ = ["SteadyState", "integrate_steady_state", "time_domain_model"]

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


def integrate_steady_state(
    problem: HarmonicProblem,
    omega: float,
    force: np.ndarray,
    state0: np.ndarray | None = None,
    *,
    model: SecondOrderModel | None = None,
    rtol: float = 1e-9,
    periodic_tol: float = 1e-6,
    max_periods: int = 2000,
    min_periods: int = 3,
) -> SteadyState:
    """Integrate ``M z'' + C z' + K z = B_f^T f(t) + B_n^T f_nl`` to periodic steady state.

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
    periodic_tol : float
        Stop when the state repeats over a period to this fraction of its largest entry.

    Returns
    -------
    SteadyState
    """
    mdl = model or time_domain_model(problem)
    T = mdl.T
    Tn = T[problem.nl_dofs]
    Tf = T[problem.force_dofs]
    To = T[problem.output_dofs]
    L = problem.L
    Fk = problem.force_harmonics(force)
    kk = np.arange(Fk.shape[0])
    wb = omega / problem.denominator
    Minv = np.linalg.inv(mdl.M)
    A_K = Minv @ mdl.K
    A_C = Minv @ mdl.C
    Bf = Minv @ Tf.T
    Bn = Minv @ Tn.T
    els = [a.element for a in problem.attachments]
    m = mdl.size

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        z, zd = y[:m], y[m:]
        f_ext = (Fk * np.exp(1j * kk * wb * t)[:, None]).sum(axis=0).real
        acc = Bf @ f_ext - A_K @ z - A_C @ zd
        if els:
            u = L @ (Tn @ z)
            v = L @ (Tn @ zd)
            fe = np.array([el.force(u[e], v[e]) for e, el in enumerate(els)], dtype=float)
            acc = acc + Bn @ (L.T @ fe)
        return np.concatenate([zd, acc])

    period = 2 * np.pi / wb
    y = np.zeros(2 * m) if state0 is None else np.asarray(state0, dtype=float).copy()
    b = problem.basis
    t_eval = np.append(np.arange(b.n_time) * period / b.n_time, period)
    err, k, sol = np.inf, 0, None
    for k in range(1, max_periods + 1):
        sol = solve_ivp(
            rhs,
            (0.0, period),
            y,
            method="DOP853",
            rtol=rtol,
            atol=rtol * max(np.abs(y).max(), 1e-12) * 1e-3,
            t_eval=t_eval,
            dense_output=False,
        )
        if not sol.success:
            raise RuntimeError(f"time integration failed at period {k}: {sol.message}")
        y_new = sol.y[:, -1]
        scale = max(np.abs(y_new).max(), 1e-300)
        err = np.abs(y_new - y).max() / scale
        y = y_new
        if k >= min_periods and err < periodic_tol:
            break
    z_t = sol.y[:m, :-1].T  # (N, m) over the last period, t from 0
    q_out = b.to_complex(b.from_time(z_t @ To.T))
    q_nl = b.to_complex(b.from_time(z_t @ Tn.T))
    return SteadyState(q_out, q_nl, y, k, float(err), bool(err < periodic_tol), problem.order_k)
