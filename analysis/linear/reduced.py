"""Second-order reduced models for time integration and Floquet/Hill stability.

A :class:`SecondOrderModel` is ``M z'' + C z' + K z = B_f^T f_ext + B_n^T f_nl`` with physical
DOFs ``q = B z``. From a modal model it is built on the retained modes augmented by the
residual static shapes of the loaded DOFs (modal truncation augmentation), so its static
flexibility at those DOFs is exact, like the residual-flexibility receptance; it also provides
receptance blocks of its own, so a balance solved on it and a time integration of it describe
exactly one model.

References
----------
J. M. Dickens, J. M. Nakagawa, M. J. Wittbrodt, "A critique of mode acceleration and modal
truncation augmentation methods for modal response analysis", Computers & Structures 62 (1997).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from analysis.linear.receptance import DirectLinearModel, ModalLinearModel, _ModalBlock

__all__ = ["SecondOrderModel", "reduced_model"]


@dataclass
class SecondOrderModel:
    """Linear second-order system in generalised coordinates ``z``.

    Attributes
    ----------
    M, C, K : ndarray, shape (m, m)
    T : ndarray, shape (n_dof, m)
        Physical DOFs ``q = T z`` (rows for every DOF of the parent model).
    modal : bool
        True if ``M = I`` and ``C``, ``K`` are diagonal (modal coordinates).
    """

    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    T: np.ndarray
    modal: bool = False

    @property
    def n_dof(self) -> int:
        return self.T.shape[0]

    @property
    def size(self) -> int:
        return self.M.shape[0]

    param_names: tuple[str, ...] = ()

    def block(self, rows: list[int], cols: list[int]):
        """Receptance block of this model (no residual term: it is complete by itself)."""
        if self.modal:
            w = np.sqrt(np.diag(self.K))
            z = np.diag(self.C) / (2 * w)
            return _ModalBlock(self.T[rows], self.T[cols], w, z, np.zeros((len(rows), len(cols))))
        lin = DirectLinearModel(self.M, self.C, self.K)
        Tr, Tc = self.T[list(rows)], self.T[list(cols)]

        class _Block:
            shape = (len(rows), len(cols))

            def __call__(self, omega):
                return Tr @ lin.full(omega) @ Tc.T

            def derivative(self, omega, param):
                raise ValueError(f"no parameter {param!r} in this reduced model")

        return _Block()


def reduced_model(
    linear, load_dofs: list[int], default_zeta: float | None = None
) -> SecondOrderModel:
    """Second-order model of a linear model for time-domain use.

    Parameters
    ----------
    linear : ModalLinearModel or DirectLinearModel or SecondOrderModel
        A modal model is reduced to its retained modes plus residual static shapes of
        ``load_dofs``; a direct model is used as it is.
    load_dofs : list of int
        DOFs where forces act (nonlinear and excitation DOFs).
    default_zeta : float, optional
        Damping ratio of the augmentation modes (default: the lowest retained-mode ratio... the
        model's default when known).
    """
    if isinstance(linear, SecondOrderModel):
        return linear
    if isinstance(linear, DirectLinearModel):
        n = linear.n_dof
        return SecondOrderModel(linear.M, linear.C, linear.K, np.eye(n), modal=False)
    if not isinstance(linear, ModalLinearModel):
        raise TypeError(f"cannot reduce a {type(linear).__name__}")
    modes = linear.modes
    phi = modes.phi
    M, K = linear.M, linear.K
    E = np.zeros((linear.n_dof, len(load_dofs)))
    E[list(load_dofs), range(len(load_dofs))] = 1.0
    S = np.linalg.solve(K, E)
    psi = S - phi @ (phi.T @ (M @ S))
    # orthonormalise the residual shapes (drop numerically dependent ones)
    Mr = psi.T @ M @ psi
    Kr = psi.T @ K @ psi
    keep = np.diag(Mr) > 1e-14 * max(np.diag(Mr).max(), 1e-300)
    psi, Mr, Kr = psi[:, keep], Mr[np.ix_(keep, keep)], Kr[np.ix_(keep, keep)]
    lam, V = sla.eigh(Kr, Mr)
    phi_a = psi @ V
    zeta_a = np.full(lam.size, modes.zeta[-1] if default_zeta is None else default_zeta)
    omega = np.concatenate([modes.omega, np.sqrt(lam)])
    zeta = np.concatenate([modes.zeta, zeta_a])
    T = np.concatenate([phi, phi_a], axis=1)
    m = omega.size
    return SecondOrderModel(
        M=np.eye(m), C=np.diag(2 * zeta * omega), K=np.diag(omega**2), T=T, modal=True
    )
