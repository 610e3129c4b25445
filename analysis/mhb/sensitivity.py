"""Parameter sensitivities of a converged balance by implicit differentiation.

At a solution ``R(X, p) = X - G(p) F(X, p) - X_lin(p) = 0``::

    dX/dp = J^-1 (G dF/dp + dG/dp F + dX_lin/dp),   J = I - G dF/dX,

and the outputs ``q_o = H_on F(X) + H_of F_ext`` follow by the chain rule. Element parameters
enter through ``dF/dp`` (AFT of the element's exact ``df/dp``); structural parameters through
the receptance derivatives. The derivative is exact wherever the element laws are
differentiable along the periodic orbit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.mhb.aft import parameter_forces
from analysis.mhb.problem import HarmonicProblem, real_operator
from analysis.mhb.solver import MHBPoint

__all__ = ["PointSensitivity", "parameter_names", "point_sensitivities"]


@dataclass(frozen=True)
class PointSensitivity:
    """Derivatives of one solution with respect to one parameter.

    Attributes
    ----------
    dX : ndarray, shape (2H+1, n_nl)
        Derivative of the nonlinear-DOF coefficients [m per parameter unit].
    dq_out : ndarray, shape (H+1, n_out), complex
        Derivative of the output phasors.
    """

    dX: np.ndarray
    dq_out: np.ndarray

    def d_outputs(self, order_k: np.ndarray) -> np.ndarray:
        """Derivative of the output phasors at the excitation orders, (n_orders, n_out)."""
        return self.dq_out[order_k]


def parameter_names(problem: HarmonicProblem) -> list[str]:
    """Every parameter a sensitivity can be taken for: element-mapped ones, then structural."""
    names: list[str] = []
    for att in problem.attachments:
        for p in att.param_map:
            if p not in names:
                names.append(p)
    for p in getattr(problem.linear, "param_names", ()):
        if p not in names:
            names.append(p)
    return names


def point_sensitivities(
    problem: HarmonicProblem, point: MHBPoint, params: list[str] | None = None
) -> dict[str, PointSensitivity]:
    """Sensitivities of a converged :class:`MHBPoint` to model parameters.

    Parameters
    ----------
    problem : HarmonicProblem
        The problem the point was solved with.
    point : MHBPoint
        A converged solution (``point.converged`` must be True).
    params : list of str, optional
        Parameter names (default: :func:`parameter_names`).

    Returns
    -------
    dict name -> PointSensitivity
    """
    if not point.converged:
        raise ValueError(f"sensitivities need a converged point (this one: {point.message})")
    names = parameter_names(problem) if params is None else list(params)
    known = set(parameter_names(problem))
    unknown = [p for p in names if p not in known]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; known: {sorted(known)}")
    b = problem.basis
    n = problem.n_nl
    prep = point.lin["prep"]
    rec, Fk = prep["rec"], prep["Fk"]  # the blocks' derivatives too: see HarmonicProblem.prefetch
    lin_names = set(getattr(problem.linear, "param_names", ()))
    out: dict[str, PointSensitivity] = {}
    if n:
        G, dFdX, F = prep["G"], point.lin["dF"], point.lin["F"]
        J = np.eye(b.size * n) - G @ dFdX
        dF_el = parameter_forces(problem, point.X, prep["omega_b"])
        Hon = prep["rec"]["on"]
        # every parameter's right-hand side first: one factorisation of J for all of them
        rhs = np.zeros((b.size * n, len(names)))
        for i, p in enumerate(names):
            dFp = dF_el.get(p)
            if dFp is not None:
                rhs[:, i] += G @ dFp.ravel()
            if p in lin_names:
                dHnn = np.array(rec["d", "nn", p])
                dHnn[0] = dHnn[0].real
                rhs[:, i] += real_operator(dHnn) @ F.ravel()
                dHnf = rec["d", "nf", p]
                rhs[:, i] += b.from_complex(np.einsum("kij,kj->ki", dHnf, Fk)).ravel()
        dX_all = np.linalg.solve(J, rhs).T.copy() if names else rhs.T
    for i, p in enumerate(names):
        dq = np.zeros_like(point.q_out)
        if n:
            dX = dX_all[i].reshape(b.size, n)
            dFp = dF_el.get(p)
            dFtot = (dFdX @ dX.ravel()).reshape(b.size, n)
            if dFp is not None:
                dFtot = dFtot + dFp
            dq += np.einsum("kij,kj->ki", Hon, b.to_complex(dFtot))
            if p in lin_names:
                dq += np.einsum("kij,kj->ki", rec["d", "on", p], b.to_complex(F))
        else:
            dX = np.zeros((b.size, 0))
        if p in lin_names:
            dq += np.einsum("kij,kj->ki", rec["d", "of", p], Fk)
        out[p] = PointSensitivity(dX=dX, dq_out=dq)
    return out
