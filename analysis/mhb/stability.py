"""Stability of periodic solutions: Hill's method, with a monodromy-matrix cross-check.

Both linearise the element laws along the periodic orbit (``df/du``, ``df/dv`` sampled by the
AFT) on the problem's second-order model. Hill's method writes the perturbation as
``exp(lambda t) sum_k p_k exp(i k w t)``, truncated to ``|k| <= n_hill``; of its eigenvalues the
``2 m`` in the first band ``|Im lambda| <= w/2`` whose eigenvectors are most concentrated on
``k = 0`` are taken as Floquet exponents (Lazarus & Thomas). The monodromy method multiplies
the exact transition matrices of the piecewise-constant linearisation over the AFT samples.

References
----------
A. Lazarus, O. Thomas, "A harmonic-based method for computing the stability of periodic
solutions of dynamical systems", C. R. Mecanique 338 (2010) 510-517.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from analysis.linear.reduced import SecondOrderModel
from analysis.mhb.problem import HarmonicProblem
from analysis.mhb.solver import MHBPoint
from analysis.mhb.time_integration import time_domain_model

__all__ = ["Stability", "floquet_exponents"]


@dataclass(frozen=True)
class Stability:
    """Floquet exponents of a periodic solution.

    Attributes
    ----------
    exponents : ndarray, shape (2 m,), complex
        Floquet exponents [1/s].
    stable : bool
        All real parts below ``tol`` times the base angular frequency.
    max_real : float
        Largest real part [1/s].
    method : str
    """

    exponents: np.ndarray
    stable: bool
    max_real: float
    method: str


def _tangents(problem: HarmonicProblem, point: MHBPoint) -> tuple[np.ndarray, np.ndarray]:
    """Nodal tangent stiffness and damping along the orbit, shape (N, n_nl, n_nl) each."""
    b = problem.basis
    wb = point.omega / problem.denominator
    U = point.X @ problem.L.T
    u_t, v_t = b.E @ U, wb * (b.dE @ U)
    N, n = b.n_time, problem.n_nl
    Kt = np.zeros((N, n, n))
    Ct = np.zeros((N, n, n))
    for e, att in enumerate(problem.attachments):
        ev = att.element.evaluate(u_t[:, e], v_t[:, e])
        LL = np.outer(problem.L[e], problem.L[e])
        Kt += ev.df_du[:, None, None] * LL
        Ct += ev.df_dv[:, None, None] * LL
    return Kt, Ct


def floquet_exponents(
    problem: HarmonicProblem,
    point: MHBPoint,
    *,
    method: str = "hill",
    n_hill: int | None = None,
    model: SecondOrderModel | None = None,
    tol: float = 1e-6,
) -> Stability:
    """Floquet exponents and stability of a converged periodic solution.

    Parameters
    ----------
    problem, point : HarmonicProblem, MHBPoint
    method : {"hill", "monodromy"}
    n_hill : int, optional
        Harmonics in Hill's matrix (default: the problem's ``n_harmonics``).
    model : SecondOrderModel, optional
        Default: the problem's time-domain model.
    tol : float
        Stability threshold on ``max Re(lambda) / omega_base``.
    """
    kernels = {"hill": _hill, "monodromy": _monodromy}
    if method not in kernels:
        raise ValueError(f"method: expected one of {sorted(kernels)}, got {method!r}")
    mdl = model or time_domain_model(problem)
    Kt, Ct = _tangents(problem, point)
    B = mdl.T[problem.nl_dofs]  # (n_nl, m)
    Kz = np.einsum("ia,tij,jb->tab", B, Kt, B)
    Cz = np.einsum("ia,tij,jb->tab", B, Ct, B)
    wb = point.omega / problem.denominator
    lam = kernels[method](mdl, Kz, Cz, wb, n_hill or problem.n_harmonics)
    mr = float(lam.real.max())
    return Stability(lam, bool(mr < tol * wb), mr, method)


def _hill(mdl: SecondOrderModel, Kz: np.ndarray, Cz: np.ndarray, wb: float, nh: int) -> np.ndarray:
    N, m, _ = Kz.shape
    j = np.arange(-2 * nh, 2 * nh + 1)
    tau = 2 * np.pi * np.arange(N) / N
    ph = np.exp(-1j * np.outer(j, tau)) / N  # (4nh+1, N)
    Kc = np.einsum("jt,tab->jab", ph, Kz)  # complex Fourier coefficients
    Cc = np.einsum("jt,tab->jab", ph, Cz)
    ks = np.arange(-nh, nh + 1)
    nb = ks.size
    M1 = np.zeros((nb, m, nb, m), complex)
    M0 = np.zeros((nb, m, nb, m), complex)
    for a, k in enumerate(ks):
        for c, kj in enumerate(ks):
            d = k - kj + 2 * nh
            M1[a, :, c, :] = -Cc[d]
            M0[a, :, c, :] = -(Kc[d] + 1j * kj * wb * Cc[d])
        M1[a, :, a, :] += 2j * k * wb * mdl.M + mdl.C
        M0[a, :, a, :] += -((k * wb) ** 2) * mdl.M + 1j * k * wb * mdl.C + mdl.K
    size = nb * m
    M1 = M1.reshape(size, size)
    M0 = M0.reshape(size, size)
    M2inv = np.kron(np.eye(nb), np.linalg.inv(mdl.M))
    A = np.zeros((2 * size, 2 * size), complex)
    A[:size, size:] = np.eye(size)
    A[size:, :size] = -M2inv @ M0
    A[size:, size:] = -M2inv @ M1
    lam, V = np.linalg.eig(A)
    P = V[:size].reshape(nb, m, -1)
    w0 = (np.abs(P[nh]) ** 2).sum(axis=0) / np.maximum((np.abs(P) ** 2).sum(axis=(0, 1)), 1e-300)
    # Among the eigenvalues in the first band (|Im| <= w/2) take the 2m most concentrated on
    # the central harmonic; shifted copies (lambda + i k w) lie outside the band.
    band = np.abs(lam.imag) <= 0.5 * wb * (1 + 1e-9)
    score = w0 + 2.0 * band
    pick = np.argsort(-score)[: 2 * m]
    return lam[pick]


def _monodromy(mdl: SecondOrderModel, Kz, Cz, wb: float, nh: int) -> np.ndarray:
    N, m, _ = Kz.shape
    dt = 2 * np.pi / wb / N
    Minv = np.linalg.inv(mdl.M)
    Phi = np.eye(2 * m)
    A = np.zeros((2 * m, 2 * m))
    A[:m, m:] = np.eye(m)
    for t in range(N):
        A[m:, :m] = -Minv @ (mdl.K - Kz[t])
        A[m:, m:] = -Minv @ (mdl.C - Cz[t])
        Phi = sla.expm(A * dt) @ Phi
    mu = np.linalg.eigvals(Phi)
    return np.log(mu.astype(complex)) * wb / (2 * np.pi)
