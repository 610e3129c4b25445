"""Time histories of any structural DOF from a periodic solution of the balance.

The balance solves for the nonlinear DOFs only; any other DOF ``d`` follows from the converged
nonlinear and external forces through the receptances,
``Q_d,k = H_dn(k w) F_nl,k + H_df(k w) F_ext,k``, and its time history is
``q_d(t) = Re{ sum_k Q_d,k exp(i k w_b t) }`` (``w_b`` the base frequency; velocity and
acceleration multiply each harmonic by ``i k w_b`` once or twice).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from analysis.mhb.problem import HarmonicProblem

__all__ = ["dof_phasors", "time_history"]

_DERIVATIVES = {"displacement": 0, "velocity": 1, "acceleration": 2}


def _dofs(problem: HarmonicProblem, dofs: int | Sequence[int]) -> list[int]:
    items: list[object] = [dofs] if np.isscalar(dofs) else list(dofs)  # type: ignore[arg-type]
    n = problem.linear.n_dof
    bad = [d for d in items if not (isinstance(d, int | np.integer) and 0 <= d < n)]
    if bad or not items:
        raise ValueError(f"dofs: expected DOF indices in 0..{n - 1}, got {bad or items!r}")
    return [int(d) for d in items]  # type: ignore[call-overload]


def dof_phasors(problem: HarmonicProblem, point, dofs: int | Sequence[int]) -> np.ndarray:
    """Phasors of DOFs per harmonic of the base, shape (H+1, n_dofs), complex [m].

    Parameters
    ----------
    problem : HarmonicProblem
        The problem the point was solved on.
    point : MHBPoint
        A converged periodic solution.
    dofs : int or sequence of int
        Structural DOF indices of the problem's linear model.
    """
    dofs = _dofs(problem, dofs)
    w = problem.harmonic_omegas(point.omega)
    Q = np.einsum("kij,kj->ki", problem.linear.block(dofs, problem.force_dofs)(w), point.force)
    if problem.n_nl:
        Q += np.einsum("kij,kj->ki", problem.linear.block(dofs, problem.nl_dofs)(w), point.f_nl)
    Q[0] = Q[0].real
    return Q


def time_history(
    problem: HarmonicProblem,
    point,
    dofs: int | Sequence[int],
    n: int = 256,
    quantity: str = "displacement",
    periods: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """Time history of DOFs over whole base periods of a periodic solution.

    Parameters
    ----------
    problem, point : HarmonicProblem, MHBPoint
    dofs : int or sequence of int
        Structural DOF indices.
    n : int
        Samples per base period.
    quantity : {"displacement", "velocity", "acceleration"}
    periods : int
        Base periods to cover.

    Returns
    -------
    t : ndarray, shape (n * periods,)
        Time [s] from the phase origin of the force phasors (``t = 0``).
    q : ndarray, shape (n * periods, n_dofs)
        [m], [m/s] or [m/s^2] (rad for a rotation).
    """
    if quantity not in _DERIVATIVES:
        raise ValueError(f"quantity: expected one of {sorted(_DERIVATIVES)}, got {quantity!r}")
    if int(n) < 2 or int(periods) < 1:
        raise ValueError(f"n >= 2 and periods >= 1 expected, got n={n!r}, periods={periods!r}")
    Q = dof_phasors(problem, point, dofs)
    wb = point.omega / problem.denominator
    k = np.arange(Q.shape[0])
    Q = Q * ((1j * k * wb) ** _DERIVATIVES[quantity])[:, None]
    t = np.arange(int(n) * int(periods)) * (2 * np.pi / wb) / int(n)
    return t, (np.exp(1j * np.outer(t, k * wb)) @ Q).real
