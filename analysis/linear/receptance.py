"""Receptances of the underlying linear structure.

:class:`ModalLinearModel` builds receptance blocks ``H[rows, cols](omega)`` by modal
superposition of the retained modes plus a residual-flexibility correction for the truncated
ones (the static flexibility not carried by the retained modes), which makes the block exact at
``omega = 0``. :class:`DirectLinearModel` solves the dynamic stiffness directly: exact for any
damping matrix, meant for small systems. Both give exact derivatives with respect to parameters
that enter ``M``, ``K`` (and ``C``).

References
----------
R. R. Craig, A. J. Kurdila, *Fundamentals of Structural Dynamics*, 2nd ed., Wiley 2006,
sec. 11.4 (mode acceleration / residual flexibility).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from analysis.linear.modal import Modes, modal_analysis, mode_sensitivities

__all__ = [
    "ZETA",
    "DirectLinearModel",
    "LinearModel",
    "ModalLinearModel",
    "ReceptanceBlock",
    "frequency_derivative",
    "zeta_name",
]

#: Prefix of a modal damping ratio as a parameter: ``"zeta_4"`` is mode 4's.
ZETA = "zeta_"


def zeta_name(mode: int) -> str:
    """The parameter name of mode ``mode``'s damping ratio (1-based, as ``[damping.per_mode]``)."""
    return f"{ZETA}{int(mode)}"


class ReceptanceBlock(Protocol):
    """A receptance sub-matrix as a function of angular frequency."""

    @property
    def shape(self) -> tuple[int, int]:
        """``(n_rows, n_cols)``."""
        ...

    def __call__(self, omega: np.ndarray) -> np.ndarray:
        """``H(omega)``, shape (n_omega, n_rows, n_cols), m/N."""
        ...

    def derivative(self, omega: np.ndarray, param: str) -> np.ndarray:
        """``dH/dp`` at ``omega``, shape (n_omega, n_rows, n_cols)."""
        ...


def frequency_derivative(block: ReceptanceBlock, omega: np.ndarray) -> np.ndarray:
    """``dH/domega`` of a receptance block, shape (n_omega, n_rows, n_cols), m/N per rad/s:
    the block's own ``frequency_derivative`` where it has one (exact), else central
    differences of the block with steps of 1e-7 of the frequency (or of the largest one
    asked for, at 0)."""
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    exact = getattr(block, "frequency_derivative", None)
    if exact is not None:
        return exact(w)
    h = 1e-7 * np.maximum(np.abs(w), max(float(np.abs(w).max()), 1.0))
    return (np.asarray(block(w + h)) - np.asarray(block(w - h))) / (2 * h)[:, None, None]


class LinearModel(Protocol):
    """Anything that provides receptance blocks between DOF sets."""

    n_dof: int
    param_names: tuple[str, ...]

    def block(self, rows: list[int], cols: list[int]) -> ReceptanceBlock: ...


@dataclass
class _ModalBlock:
    phi_r: np.ndarray  # (nr, m)
    phi_c: np.ndarray  # (nc, m)
    omega_r: np.ndarray  # (m,)
    zeta_r: np.ndarray  # (m,)
    residual: np.ndarray  # (nr, nc)
    sens: dict = field(default_factory=dict)  # param -> (dphi_r, dphi_c, dlam, dres)
    zeta: dict = field(default_factory=dict)  # damping ratio name -> retained mode or None

    @property
    def shape(self) -> tuple[int, int]:
        return self.residual.shape

    def _g(self, omega: np.ndarray) -> np.ndarray:
        w = np.asarray(omega, dtype=float)[:, None]
        wr = self.omega_r[None, :]
        return 1.0 / (wr**2 - w**2 + 2j * self.zeta_r * wr * w)

    def __call__(self, omega: np.ndarray) -> np.ndarray:
        g = self._g(omega)
        return np.einsum("im,wm,jm->wij", self.phi_r, g, self.phi_c) + self.residual

    def frequency_derivative(self, omega: np.ndarray) -> np.ndarray:
        """``dH/domega``: ``dg/dw = g^2 (2 w - 2 i zeta w_r)``; the residual is static."""
        w = np.asarray(omega, dtype=float)[:, None]
        g = self._g(omega)
        dg = g**2 * (2 * w - 2j * self.zeta_r * self.omega_r)
        return np.einsum("im,wm,jm->wij", self.phi_r, dg, self.phi_c)

    def derivative(self, omega: np.ndarray, param: str) -> np.ndarray:
        if param in self.zeta:
            return self._zeta_derivative(omega, self.zeta[param])
        dphi_r, dphi_c, dlam, dres = self.sens[param]
        w = np.asarray(omega, dtype=float)[:, None]
        g = self._g(omega)
        dwr = dlam / (2 * self.omega_r)
        dg = -(g**2) * (dlam + 2j * self.zeta_r * dwr * w)
        out = np.einsum("im,wm,jm->wij", dphi_r, g, self.phi_c)
        out += np.einsum("im,wm,jm->wij", self.phi_r, g, dphi_c)
        out += np.einsum("im,wm,jm->wij", self.phi_r, dg, self.phi_c)
        return out + dres

    def _zeta_derivative(self, omega: np.ndarray, mode: int | None) -> np.ndarray:
        """``dH/dzeta_r = -phi_r phi_r^T 2 i w w_r g_r^2`` of retained mode ``mode``; a mode
        in the residual flexibility is static, its damping enters nowhere."""
        w = np.asarray(omega, dtype=float)
        out = np.zeros((w.size, *self.shape), complex)
        if mode is not None:
            wr = self.omega_r[mode]
            g = 1.0 / (wr**2 - w**2 + 2j * self.zeta_r[mode] * wr * w)
            dg = -(g**2) * 2j * wr * w
            out += dg[:, None, None] * np.outer(self.phi_r[:, mode], self.phi_c[:, mode])
        return out


class ModalLinearModel:
    """Modal receptances with residual flexibility.

    Parameters
    ----------
    M, K : ndarray, shape (n, n)
        Mass [kg] and stiffness [N/m]; ``K`` must be non-singular (a supported structure).
    zeta : float, ndarray or dict
        Modal damping (see :func:`analysis.linear.modal.modal_analysis`).
    f_max_hz : float
        Modes up to this frequency are retained; the rest enter as residual flexibility.
    dM, dK : dict name -> ndarray, optional
        Parameter derivatives for sensitivities (modal damping ratios held fixed).
    damping_modes : sequence of int, optional
        Modes (1-based) whose damping ratios are parameters too, named :func:`zeta_name`
        (``zeta_4``), with exact derivatives.
    modes : Modes, optional
        Every mode of ``(K, M)`` with its damping ratio, when the caller has them already
        (``zeta`` and ``default_zeta`` are then not used): a fit evaluates its accepted
        iterate once more for the Jacobian.
    """

    def __init__(
        self,
        M: np.ndarray,
        K: np.ndarray,
        zeta: float | np.ndarray | dict[int, float] = 0.01,
        *,
        default_zeta: float = 0.01,
        f_max_hz: float = 2000.0,
        dM: dict[str, np.ndarray] | None = None,
        dK: dict[str, np.ndarray] | None = None,
        damping_modes: Sequence[int] = (),
        modes: Modes | None = None,
    ) -> None:
        self.M = np.asarray(M, dtype=float)
        self.K = np.asarray(K, dtype=float)
        self.n_dof = self.M.shape[0]
        self.all_modes = (
            modal_analysis(self.M, self.K, zeta, default_zeta=default_zeta)
            if modes is None
            else modes
        )
        if self.all_modes.omega[0] <= 0:
            raise ValueError(
                "the structure has a rigid-body mode: residual flexibility needs supports"
            )
        keep = np.flatnonzero(self.all_modes.frequency_hz <= f_max_hz)
        if keep.size == 0:
            keep = np.arange(1)
        self.keep = keep
        self.modes = Modes(
            self.all_modes.omega[keep], self.all_modes.phi[:, keep], self.all_modes.zeta[keep]
        )
        self.dM = dict(dM or {})
        self.dK = dict(dK or {})
        # a damping ratio's mode among the retained ones (None: in the residual flexibility)
        retained = {int(m) + 1: i for i, m in enumerate(keep)}
        self.zeta = {zeta_name(m): retained.get(int(m)) for m in damping_modes}
        self.param_names = tuple(self.dK) + tuple(self.zeta)
        self._sens: tuple[dict, dict] | None = None
        self._high: tuple[np.ndarray, np.ndarray] | None = None
        self._terms: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def _mode_sens(self) -> tuple[dict, dict]:
        if self._sens is None:
            self._sens = mode_sensitivities(
                self.M, self.K, self.all_modes, self.dM, self.dK, which=self.keep
            )
        return self._sens

    def high_flexibility(self, dofs: list[int]) -> np.ndarray:
        """Rows ``dofs`` of the static flexibility of the truncated modes, ``sum_h phi
        phi^T / omega^2``, shape (len(dofs), n) (symmetric: its columns are these rows
        transposed).

        Summed mode by mode: ``K^-1 - sum_retained phi phi^T / omega^2`` is the same in exact
        arithmetic, but on soft supports ``K^-1`` is dominated by the retained suspension modes
        and the difference keeps their round-off.
        """
        if self._high is None:
            high = np.setdiff1d(np.arange(len(self.all_modes)), self.keep)
            ph = self.all_modes.phi[:, high]
            self._high = (ph / self.all_modes.omega[high] ** 2, ph)
        scaled, ph = self._high
        return scaled[dofs] @ ph.T

    def _shape_terms(self, p: str) -> tuple[np.ndarray, np.ndarray]:
        """``(dX^T M + X^T dM, M dX + dM X)`` of parameter ``p`` (``X`` the retained shapes),
        shared by every block's residual derivative."""
        if p not in self._terms:
            dX = self._mode_sens()[1][p]
            phi, M, dM = self.modes.phi, self.M, self.dM.get(p)
            A = dX.T @ M + (phi.T @ dM if dM is not None else 0.0)
            B = M @ dX + (dM @ phi if dM is not None else 0.0)
            self._terms[p] = (A, B)
        return self._terms[p]

    def block(self, rows: list[int], cols: list[int]) -> _ModalBlock:
        """Receptance block between DOF index lists ``rows`` and ``cols``."""
        rows, cols = list(rows), list(cols)
        phi = self.modes.phi
        Rr = self.high_flexibility(rows)  # (rows, n)
        Rc = self.high_flexibility(cols).T  # (n, cols)
        blk = _ModalBlock(
            phi[rows],
            phi[cols],
            self.modes.omega,
            self.modes.zeta,
            Rr[:, cols].copy(),
            zeta=dict(self.zeta),
        )
        if self.dK:
            dlam, dphi = self._mode_sens()
            for p in self.dK:
                dX = dphi[p]
                A, B = self._shape_terms(p)
                # dR_h = -R dK R - X (dX^T M + X^T dM) R - R (M dX + dM X) X^T: no cancellation
                dres = -(Rr @ self.dK[p] @ Rc)
                dres -= phi[rows] @ (A @ Rc)
                dres -= (Rr @ B) @ phi[cols].T
                blk.sens[p] = (dX[rows], dX[cols], dlam[p], dres)
        return blk


@dataclass
class _DirectBlock:
    model: DirectLinearModel
    rows: list[int]
    cols: list[int]

    @property
    def shape(self) -> tuple[int, int]:
        return (len(self.rows), len(self.cols))

    def __call__(self, omega: np.ndarray) -> np.ndarray:
        H = self.model.full(omega)
        return H[:, self.rows][:, :, self.cols]

    def frequency_derivative(self, omega: np.ndarray) -> np.ndarray:
        """``dH/domega = -H (dZ/domega) H`` with ``dZ/domega = -2 omega M + i C``."""
        m = self.model
        H = m.full(omega)
        w = np.asarray(omega, dtype=float)[:, None, None]
        return -H[:, self.rows] @ (-2 * w * m.M + 1j * m.C) @ H[:, :, self.cols]

    def derivative(self, omega: np.ndarray, param: str) -> np.ndarray:
        m = self.model
        H = m.full(omega)
        w = np.asarray(omega, dtype=float)[:, None, None]
        dZ = m.dK.get(param, 0.0) - w**2 * m.dM.get(param, 0.0) + 1j * w * m.dC.get(param, 0.0)
        dH = -H[:, self.rows] @ dZ @ H[:, :, self.cols]
        return dH


class DirectLinearModel:
    """Receptances from the dynamic stiffness ``K - omega^2 M + i omega C`` (small systems).

    Parameters
    ----------
    M, C, K : ndarray, shape (n, n)
        Mass, viscous damping and stiffness matrices (any damping, also non-proportional).
    dM, dC, dK : dict name -> ndarray, optional
        Parameter derivatives.
    """

    def __init__(self, M, C, K, *, dM=None, dC=None, dK=None) -> None:
        self.M = np.atleast_2d(np.asarray(M, dtype=float))
        self.C = np.atleast_2d(np.asarray(C, dtype=float))
        self.K = np.atleast_2d(np.asarray(K, dtype=float))
        self.n_dof = self.M.shape[0]
        self.dM, self.dC, self.dK = dict(dM or {}), dict(dC or {}), dict(dK or {})
        self.param_names = tuple(sorted(set(self.dM) | set(self.dC) | set(self.dK)))

    def full(self, omega: np.ndarray) -> np.ndarray:
        """Full receptance matrix, shape (n_omega, n, n)."""
        w = np.asarray(omega, dtype=float)[:, None, None]
        Z = self.K - w**2 * self.M + 1j * w * self.C
        return np.linalg.inv(Z)

    def block(self, rows: list[int], cols: list[int]) -> _DirectBlock:
        """Receptance block between DOF index lists ``rows`` and ``cols``."""
        return _DirectBlock(self, list(rows), list(cols))
