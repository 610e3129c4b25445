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
from analysis.mhb.problem import HarmonicProblem
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
    # every parameter at once: the linear ones' block derivatives stacked (L, H+1, r, c)
    il = [i for i, p in enumerate(names) if p in lin_names]
    lp = [names[i] for i in il]

    def stacked(block: str) -> np.ndarray:
        return np.stack([rec["d", block, p] for p in lp])

    dq = np.zeros((len(names), *point.q_out.shape), complex)
    dX_all = np.zeros((len(names), b.size, n))
    if n and names:
        G, dFdX, F = prep["G"], point.lin["dF"], point.lin["F"]
        Fc = b.to_complex(F)
        dF_el = parameter_forces(problem, point.X, prep["omega_b"])
        dF_p = np.zeros((len(names), b.size, n))
        for i, p in enumerate(names):
            if p in dF_el:
                dF_p[i] = dF_el[p]
        # dX = J^-1 (G dF_p + dG F + dX_lin): one factorisation of J for every parameter
        rhs = (G @ dF_p.reshape(len(names), -1).T).T.reshape(dF_p.shape)
        if lp:
            dnn = stacked("nn")  # a new array: its harmonic 0 made real in place
            dnn[:, 0] = dnn[:, 0].real
            lin = np.einsum("lkij,kj->kli", dnn, Fc) + np.einsum("lkij,kj->kli", stacked("nf"), Fk)
            rhs[il] += b.from_complex(lin).transpose(1, 0, 2)  # as real_operator(dnn) @ F
        J = np.eye(b.size * n) - G @ dFdX
        dX_all = np.linalg.solve(J, rhs.reshape(len(names), -1).T).T.reshape(dF_p.shape)
        dF_tot = (dFdX @ dX_all.reshape(len(names), -1).T).T.reshape(dF_p.shape) + dF_p
        dq += np.einsum("kij,kpj->pki", rec["on"], b.to_complex(dF_tot.transpose(1, 0, 2)))
        if lp:
            dq[il] += np.einsum("lkij,kj->lki", stacked("on"), Fc)
    if lp:
        dq[il] += np.einsum("lkij,kj->lki", stacked("of"), Fk)
    return {
        p: PointSensitivity(dX=np.ascontiguousarray(dX_all[i]), dq_out=dq[i])
        for i, p in enumerate(names)
    }
