"""Newton solution of the multi-harmonic balance at one frequency.

Unknowns are the real Fourier coefficients of the nonlinear DOFs (mean included); nonlinear
forces come from the alternating frequency-time (AFT) scheme with the analytic Jacobian
``dF/dX = P diag(df/du) E + omega_b P diag(df/dv) dE`` of each element.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from analysis.mhb import kernels
from analysis.mhb.aft import nonlinear_forces
from analysis.mhb.problem import HarmonicProblem

__all__ = ["MHBPoint", "NewtonSettings", "solve_point"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class NewtonSettings:
    """Newton iteration settings.

    Parameters
    ----------
    rtol : float
        Convergence when ``max|R| <= rtol * max|X| + atol`` (R: balance residual [m]).
    atol : float
        Absolute residual floor [m].
    max_iterations : int
    max_halvings : int
        Backtracking steps of the line search on ``|R|``.
    stall_window : int
        Give up when the residual has not halved over this many iterations.
    """

    rtol: float = 1e-10
    atol: float = 1e-15
    max_iterations: int = 40
    max_halvings: int = 10
    stall_window: int = 8

    def __post_init__(self) -> None:
        if not (self.rtol > 0 and self.atol >= 0):
            raise ValueError("NewtonSettings.rtol must be > 0 and atol >= 0")
        if self.max_iterations < 1:
            raise ValueError("NewtonSettings.max_iterations must be >= 1")


@dataclass
class MHBPoint:
    """Periodic solution at one excitation frequency.

    Attributes
    ----------
    omega : float
        Fundamental angular frequency [rad/s].
    X : ndarray, shape (2H+1, n_nl)
        Real Fourier coefficients of the nonlinear DOFs [m].
    q_nl : ndarray, shape (H+1, n_nl), complex
        Phasors of the nonlinear DOFs per harmonic of the base (index 0: mean) [m].
    f_nl : ndarray, shape (H+1, n_nl), complex
        Nonlinear force phasors on those DOFs [N].
    q_out : ndarray, shape (H+1, n_out), complex
        Output DOF phasors [m].
    force : ndarray, shape (H+1, n_f), complex
        External force phasors per harmonic [N].
    converged : bool
    iterations : int
    residual : float
        Final ``max|R|`` [m].
    message : str
        Why the iteration stopped.
    """

    omega: float
    X: np.ndarray
    q_nl: np.ndarray
    f_nl: np.ndarray
    q_out: np.ndarray
    force: np.ndarray
    converged: bool
    iterations: int
    residual: float
    message: str
    order_k: np.ndarray = field(repr=False)
    lin: dict = field(default_factory=dict, repr=False)

    def outputs(self) -> np.ndarray:
        """Output phasors at the excitation orders, shape (n_orders, n_out) [m]."""
        return self.q_out[self.order_k]

    def time_history(
        self, problem: HarmonicProblem, dofs, n: int = 256, quantity: str = "displacement"
    ) -> tuple[np.ndarray, np.ndarray]:
        """Time history of any structural DOFs over one base period: ``(t [s], q)``,
        ``q`` of shape (n, n_dofs) (see :func:`analysis.mhb.histories.time_history`)."""
        from analysis.mhb.histories import time_history

        return time_history(problem, self, dofs, n, quantity)

    def frf(self, force_column: int = 0) -> np.ndarray:
        """Multi-harmonic FRFs ``H^nu = Q_nu / F_nu``, shape (n_orders, n_out) [m/N]."""
        F = self.force[self.order_k, force_column]
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.q_out[self.order_k] / F[:, None]


def _prepare(problem: HarmonicProblem, omega: float, force: np.ndarray) -> dict:
    rec = problem.receptances(omega)
    Fk = problem.force_harmonics(force)
    prep = {"w": rec["w"], "Fk": Fk, "omega_b": omega / problem.denominator, "rec": rec}
    if problem.n_nl:
        prep["G"] = rec["G"]
        prep["X_lin"] = problem.basis.from_complex(np.matmul(rec["nf"], Fk[:, :, None])[:, :, 0])
    return prep


def _recover(problem: HarmonicProblem, prep: dict, F: np.ndarray | None) -> np.ndarray:
    rec, Fk = prep["rec"], prep["Fk"]
    q = np.matmul(rec["of"], Fk[:, :, None])[:, :, 0]
    if problem.n_nl and F is not None:
        Fc = problem.basis.to_complex(F)
        q += np.matmul(rec["on"], Fc[:, :, None])[:, :, 0]
    return q


def _linear_point(problem: HarmonicProblem, omega: float, prep: dict) -> MHBPoint:
    """The solution of a problem without nonlinear DOFs (the linear response)."""
    b = problem.basis
    return MHBPoint(
        omega,
        np.zeros((b.size, 0)),
        np.zeros((b.n_harmonics + 1, 0), complex),
        np.zeros((b.n_harmonics + 1, 0), complex),
        _recover(problem, prep, None),
        prep["Fk"],
        True,
        0,
        0.0,
        "linear",
        problem.order_k,
    )


def _line_search(residual, X: np.ndarray, dX: np.ndarray, R: np.ndarray, max_halvings: int):
    """Backtracking on ``|R|`` along the Newton step: ``(X, R, F, dF)`` of the step taken,
    or None when no trial decreases the residual."""
    alpha, r2 = 1.0, np.linalg.norm(R)
    for _ in range(max_halvings + 1):
        # every trial with its Jacobian: it costs a fraction of the forces (the law acts on
        # part of the period only), less than evaluating the trial taken a second time
        Xt = X + alpha * dX
        Rt, Ft, dFt = residual(Xt, True)
        rt2 = np.linalg.norm(Rt)
        if np.isfinite(rt2) and rt2 < (1 - 1e-4 * alpha) * r2:
            break
        alpha *= 0.5
    else:
        if not (np.isfinite(rt2) and rt2 < r2):
            return None
    return Xt, Rt, Ft, dFt


def solve_point(
    problem: HarmonicProblem,
    omega: float,
    force: np.ndarray,
    X0: np.ndarray | None = None,
    settings: NewtonSettings | None = None,
) -> MHBPoint:
    """Solve the balance at one frequency by damped Newton.

    Parameters
    ----------
    problem : HarmonicProblem
    omega : float
        Fundamental angular frequency [rad/s].
    force : ndarray, shape (n_orders, n_f) or (n_orders,), complex
        External force phasors at the excitation orders [N].
    X0 : ndarray, shape (2H+1, n_nl), optional
        Start (warm start from the previous step); default the linear response.
    settings : NewtonSettings, optional

    Returns
    -------
    MHBPoint
        ``converged`` is False with ``message`` saying why if Newton did not converge.
    """
    st = settings or NewtonSettings()
    prep = _prepare(problem, omega, force)
    b = problem.basis
    n = problem.n_nl
    if n == 0:
        return _linear_point(problem, omega, prep)
    G, X_lin, wb = prep["G"], prep["X_lin"], prep["omega_b"]
    X = X_lin.copy() if X0 is None else np.array(X0, dtype=float).reshape(b.size, n)
    arrays = problem.element_arrays()
    if arrays is not None:
        X, R, F, dF, outcome, it, rn = kernels.newton(
            X,
            G,
            X_lin,
            float(wb),
            arrays.codes,
            arrays.params,
            arrays.n_params,
            arrays.thresholds,
            arrays.L,
            problem.kernel_basis,
            np.array(
                [st.rtol, st.atol, st.max_iterations, st.stall_window, st.max_halvings], float
            ),
        )
        message = kernels.MESSAGES[outcome].format(window=st.stall_window)
        return _point(problem, omega, prep, X, F, dF, outcome == 0, it, rn, message)
    scale = max(np.abs(X_lin).max(), 1e-300)

    def residual(Xc: np.ndarray, jac: bool):
        F, dF = nonlinear_forces(problem, Xc, wb, jac)
        R = Xc - (G @ F.ravel()).reshape(b.size, n) - X_lin
        return R, F, dF

    R, F, dF = residual(X, True)
    rn = np.abs(R).max()
    message, converged, it = "maximum iterations reached", False, 0
    eye = np.eye(b.size * n)
    history = []
    for it in range(1, st.max_iterations + 1):
        if not np.isfinite(rn):
            message = "non-finite residual"
            break
        history.append(rn)
        if it > st.stall_window and rn > 0.5 * history[-1 - st.stall_window]:
            message = f"stalled (residual not halved in {st.stall_window} iterations)"
            break
        if rn <= st.rtol * max(np.abs(X).max(), scale) + st.atol:
            converged, message, it = True, "converged", it - 1
            break
        J = eye - G @ dF
        try:
            dX = np.linalg.solve(J, -R.ravel()).reshape(b.size, n)
        except np.linalg.LinAlgError:
            message = "singular Jacobian"
            break
        step = _line_search(residual, X, dX, R, st.max_halvings)
        if step is None:
            message = "line search failed (no descent)"
            break
        X, R, F, dF = step
        rn = np.abs(R).max()
    else:
        if rn <= st.rtol * max(np.abs(X).max(), scale) + st.atol:
            converged, message = True, "converged"
    return _point(problem, omega, prep, X, F, dF, converged, it, rn, message)


def _point(problem, omega, prep, X, F, dF, converged, it, rn, message) -> MHBPoint:
    """The solution found at ``omega``, with what its linearisation needs."""
    b = problem.basis
    point = MHBPoint(
        omega=omega,
        X=X,
        q_nl=b.to_complex(X),
        f_nl=b.to_complex(F),
        q_out=_recover(problem, prep, F),
        force=prep["Fk"],
        converged=bool(converged),
        iterations=int(it),
        residual=float(rn),
        message=message,
        order_k=problem.order_k,
    )
    point.lin = {"prep": prep, "dF": dF, "F": F}
    return point
