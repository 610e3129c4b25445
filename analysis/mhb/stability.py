"""Stability of periodic solutions: Hill's method on the modes that matter, with a
monodromy-matrix cross-check.

All methods linearise the element laws along the periodic orbit (``df/du``, ``df/dv`` sampled
by the AFT) and perturb the problem's second-order model ``M z'' + C z' + K z = B^T f``.

``method="hill"`` (the default) writes Hill's eigenvalue problem on a modal reduction of that
model. Only modes with natural frequency up to ``mode_cutoff`` times the top harmonic
frequency ``n_hill * omega_b`` keep their dynamics: a mode above it cannot be represented by
the truncated Fourier series of the perturbation anyway (its copies in the central band need
harmonics beyond ``n_hill``), and the coefficients of the linearisation reach only to
``2 n_hill``, so it cannot be excited parametrically through them. The modes above answer
quasi-statically: their static flexibility ``R`` at the nonlinear DOFs turns the nodal tangent
stiffness ``k_t(t)`` into ``(I - k_t R)^-1 k_t`` (and the tangent damping likewise), sample by
sample. Hill's matrix is then ``2 (2 n_hill + 1) m_kept`` square and real (cosine/sine basis),
a few modes instead of every DOF of the model (2 of the 24 of the examples' cantilever). This
form was chosen over the receptance form on the nonlinear DOFs (small, but nonlinear in the
exponent: a Newton search per exponent loses exponents where they collide, at folds and period
doubling) and over shift-invert Arnoldi on the full matrix (no single shift reaches every
exponent in the band before the copies of others); see ``docs/mhb.md``.

Hill's truncation is the perturbation's, not the solution's: by default ``n_hill`` is
:data:`HILL_HARMONICS` whatever the problem's ``n_harmonics`` (within what the AFT samples
resolve), so the cost does not grow with H. A contact's tangent is a pulse per period whose
Fourier series converges slowly; the exponents follow the harmonics of the perturbation, not
the solution's. On the cantilever's curve at H = 20, 10 harmonics put the leading multiplier
within 6e-4 of the monodromy matrix's, 20 within 4e-4 at five times the cost.

The eigenvalues alone are computed (the eigenvectors cost as much again). The physical
exponents are picked by Hill's own shift invariance: each Floquet exponent ``lambda`` appears
in the truncated matrix as a ladder of copies ``lambda + i j omega_b``, one per harmonic that
the truncation holds, converged in the middle and worst at the ends; the truncation's
artefacts do not form ladders. The eigenvalue whose rungs above and below are matched most
closely by other eigenvalues is the best converged copy of its ladder (the one whose
eigenvector sits on the central harmonics: Lazarus & Thomas's criterion, without the
eigenvector); it is taken, its ladder walked one eigenvalue per rung and set aside, and so on
until ``2 m_kept`` exponents are taken. They are reported folded into the band
``|Im| <= omega_b / 2``.

``method="hill_full"``: Hill's matrix of every DOF of the model with eigenvectors, the band's
exponents picked by their weight on the central harmonic, at the problem's own truncation by
default (whose real exponent then crosses zero exactly at the folds of the computed branch).
It costs a dense complex eigen-decomposition of ``2 (2 n_hill + 1) m`` (``m`` the model's
size). ``method="monodromy"`` multiplies the exact transition matrices of the
piecewise-constant linearisation over the AFT samples, on the full model: the independent
reference, first order in ``1 / n_time``.

References
----------
A. Lazarus, O. Thomas, "A harmonic-based method for computing the stability of periodic
solutions of dynamical systems", C. R. Mecanique 338 (2010) 510-517.
L. Peletan, S. Baguet, M. Torkhani, G. Jacquet-Richardet, "A comparison of stability
computational methods for periodic solution of nonlinear problems with application to
rotordynamics", Nonlinear Dynamics 72 (2013) 671-682.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.linalg as sla
from numba import njit

from analysis.linear.reduced import SecondOrderModel
from analysis.mhb.harmonics import HarmonicBasis
from analysis.mhb.problem import HarmonicProblem
from analysis.mhb.solver import MHBPoint
from analysis.mhb.time_integration import time_domain_model

__all__ = [
    "METHODS",
    "HILL_HARMONICS",
    "MODE_CUTOFF",
    "CrossCheck",
    "Stability",
    "cross_check",
    "floquet_exponents",
]

#: Modes kept dynamic by the default method: natural frequency up to this multiple of the top
#: harmonic frequency ``n_hill * omega_b``.
MODE_CUTOFF = 1.0
#: Harmonics in Hill's matrix by default, whatever the solution's: the tangent of a contact law
#: (a pulse per period) has a slowly converging Fourier series, and the exponents converge with
#: the harmonics of the perturbation, not with those of the solution.
HILL_HARMONICS = 10
#: Walking an exponent's ladder of copies in the truncated Hill matrix, the next rung is the
#: eigenvalue nearest ``lambda + i omega_b``, if within this fraction of ``omega_b``.
_RUNG_TOL = 0.25


@dataclass(frozen=True)
class Stability:
    """Floquet exponents of a periodic solution.

    Attributes
    ----------
    exponents : ndarray, shape (2 m,), complex
        Floquet exponents [1/s], folded into the band ``|Im| <= omega_b / 2``. ``m`` is the
        number of modes kept dynamic (``"hill"``) or the model's size (the other methods).
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

    def leading_multiplier(self, omega_base: float) -> complex:
        """The Floquet multiplier of largest modulus, ``exp(lambda T)``, ``T = 2 pi /
        omega_base`` (the base period); of a complex pair, the one with ``Im >= 0``."""
        lead = self.exponents[np.argmax(self.exponents.real)]
        mu = complex(np.exp(lead * (2 * np.pi / omega_base)))
        return mu.conjugate() if mu.imag < 0 else mu


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


METHODS = ("hill", "hill_full", "monodromy")


def floquet_exponents(
    problem: HarmonicProblem,
    point: MHBPoint,
    *,
    method: str = "hill",
    n_hill: int | None = None,
    model: SecondOrderModel | None = None,
    tol: float = 1e-6,
    mode_cutoff: float | None = MODE_CUTOFF,
) -> Stability:
    """Floquet exponents and stability of a converged periodic solution.

    Parameters
    ----------
    problem, point : HarmonicProblem, MHBPoint
    method : {"hill", "hill_full", "monodromy"}
        See the module's description.
    n_hill : int, optional
        Harmonics in Hill's matrix, at most ``(n_time - 1) // 2``. Default: for ``"hill"``
        :data:`HILL_HARMONICS` (within that bound), for the others the problem's
        ``n_harmonics``.
    model : SecondOrderModel, optional
        Default: the problem's time-domain model.
    tol : float
        Stability threshold on ``max Re(lambda) / omega_base``.
    mode_cutoff : float or None
        ``"hill"`` only: modes with natural frequency up to this multiple of
        ``n_hill * omega_base`` keep their dynamics (at least the lowest); None keeps every
        mode (Hill's matrix of the whole model, its exponents picked as by ``"hill"``).
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {list(METHODS)}, got {method!r}")
    if mode_cutoff is not None and not mode_cutoff > 0:
        raise ValueError(f"mode_cutoff: expected a positive number or None, got {mode_cutoff!r}")
    nh = _hill_harmonics(problem, method, n_hill)
    mdl = model or _cached_model(problem)
    Kt, Ct = _tangents(problem, point)
    wb = point.omega / problem.denominator
    if method == "hill":
        lam = _hill_modal(_modes(mdl), mdl.T[problem.nl_dofs], Kt, Ct, wb, nh, mode_cutoff)
    else:
        B = mdl.T[problem.nl_dofs]  # (n_nl, m)
        Kz = np.einsum("ia,tij,jb->tab", B, Kt, B)
        Cz = np.einsum("ia,tij,jb->tab", B, Ct, B)
        kernel = _hill_full if method == "hill_full" else _monodromy
        lam = kernel(mdl, Kz, Cz, wb, nh)
    mr = float(lam.real.max())
    return Stability(lam, bool(mr < tol * wb), mr, method)


@dataclass(frozen=True)
class CrossCheck:
    """One method's exponents against another's along a set of periodic solutions.

    Attributes
    ----------
    disagree : list of int
        Indices of the points whose stable/unstable verdicts differ.
    multiplier_rel_err : float
        Largest ``|mu - mu_ref| / |mu_ref|`` of the leading Floquet multipliers.
    n_points : int
    """

    disagree: list[int]
    multiplier_rel_err: float
    n_points: int

    @property
    def agrees(self) -> bool:
        return not self.disagree


def cross_check(
    problem: HarmonicProblem,
    points: list[MHBPoint],
    method: str = "hill",
    reference: str = "monodromy",
) -> CrossCheck:
    """Compare the stability verdicts and leading multipliers of ``method`` with those of
    ``reference`` (both with their defaults) at every point."""
    disagree, worst = [], 0.0
    for i, p in enumerate(points):
        st = floquet_exponents(problem, p, method=method)
        ref = floquet_exponents(problem, p, method=reference)
        wb = p.omega / problem.denominator
        mu = ref.leading_multiplier(wb)
        worst = max(worst, abs(st.leading_multiplier(wb) - mu) / abs(mu))
        if st.stable != ref.stable:
            disagree.append(i)
    return CrossCheck(disagree, worst, len(points))


def _hill_harmonics(problem: HarmonicProblem, method: str, n_hill: int | None) -> int:
    """Harmonics of Hill's matrix: as asked, or by default :data:`HILL_HARMONICS` for
    ``"hill"`` (at most as many as the AFT samples resolve) and the problem's own for the
    others."""
    most = (problem.basis.n_time - 1) // 2
    if n_hill is None:
        return min(HILL_HARMONICS, most) if method == "hill" else problem.n_harmonics
    if not 1 <= n_hill <= most:
        raise ValueError(
            f"n_hill: expected an integer from 1 to {most} (the problem's n_time = "
            f"{problem.basis.n_time} samples resolve (n_time - 1) // 2 harmonics), got {n_hill!r}"
        )
    return n_hill


# -- the modal reduction (once per model) ---------------------------------------------------
_MEMO: dict[tuple[int, str], object] = {}


def _memo(owner: object, what: str, make):
    """``make()``, kept while ``owner`` lives (keyed by identity: the models are mutable
    dataclasses, not hashable)."""
    key = (id(owner), what)
    if key not in _MEMO:
        _MEMO[key] = make()
        weakref.finalize(owner, _MEMO.pop, key, None)
    return _MEMO[key]


def _cached_model(problem: HarmonicProblem) -> SecondOrderModel:
    """The problem's time-domain model, made once per linear model and set of loaded DOFs."""
    what = f"model {problem.nl_dofs} {problem.force_dofs}"
    return _memo(problem.linear, what, lambda: time_domain_model(problem))


@dataclass(frozen=True)
class _Modes:
    """Undamped modes of a second-order model, mass-normalised, by rising frequency."""

    omega: np.ndarray  # (m,) rad/s
    psi: np.ndarray  # (m, m): z = psi y
    C: np.ndarray  # (m, m): psi^T C psi


def _modes(mdl: SecondOrderModel) -> _Modes:
    def make() -> _Modes:
        w2, psi = sla.eigh(mdl.K, mdl.M)
        if w2[0] <= 0:
            raise ValueError(
                "floquet_exponents: the model has a rigid-body or unstable mode "
                f"(omega^2 = {w2[0]:.3g}); Hill's modal form needs a supported structure"
            )
        return _Modes(np.sqrt(w2), psi, psi.T @ mdl.C @ psi)

    return _memo(mdl, "modes", make)


def _hill_modal(
    modes: _Modes,
    T_nl: np.ndarray,
    Kt: np.ndarray,
    Ct: np.ndarray,
    wb: float,
    nh: int,
    cutoff: float | None,
) -> np.ndarray:
    """Exponents from Hill's matrix of the kept modes (see the module's description)."""
    n_keep = modes.omega.size
    if cutoff is not None:
        n_keep = max(1, int(np.searchsorted(modes.omega, cutoff * nh * wb, side="right")))
    Phi = T_nl @ modes.psi  # mode shapes at the nonlinear DOFs, (n_nl, m)
    keep, drop = Phi[:, :n_keep], Phi[:, n_keep:]
    R = (drop / modes.omega[n_keep:] ** 2) @ drop.T  # static flexibility of the modes above
    Kt, Ct = _quasi_static(Kt, Ct, R)
    basis = _basis(nh, Kt.shape[0])
    A = _hill_matrix(basis, wb, modes.omega[:n_keep], modes.C[:n_keep, :n_keep], keep, Kt, Ct)
    return _ladder_exponents(np.linalg.eigvals(A), wb, 2 * n_keep)


@lru_cache(maxsize=8)
def _basis(n_hill: int, n_time: int) -> HarmonicBasis:
    return HarmonicBasis(n_hill, n_time)


def _quasi_static(Kt: np.ndarray, Ct: np.ndarray, R: np.ndarray):
    """Tangents seen by the kept modes when the modes of flexibility ``R`` follow
    quasi-statically: ``f = k (q_kept + R f)`` gives ``(I - k R)^-1 k``; the damping term to
    first order in the rate, ``(I - k R)^-1 c (I - R k)^-1``."""
    if not R.any():
        return Kt, Ct
    eye = np.eye(R.shape[0])
    S = np.linalg.inv(eye - Kt @ R)  # (N, n, n)
    S2 = np.linalg.inv(eye - R @ Kt)
    return S @ Kt, S @ Ct @ S2


def _hill_matrix(
    basis: HarmonicBasis,
    wb: float,
    omega: np.ndarray,
    Cm: np.ndarray,
    Phi: np.ndarray,
    Kt: np.ndarray,
    Ct: np.ndarray,
) -> np.ndarray:
    """Real first-order Hill matrix, unknowns ``[p, lambda p]`` with ``p`` the cosine/sine
    coefficients (harmonic-major) of the perturbation's modal coordinates.

    With ``y = exp(lambda t) p(t)``: ``lambda^2 p + lambda A1 p + A0 p = 0``,
    ``A1 = 2 D + C - G_c``, ``A0 = D^2 + D C + Omega^2 - G_k - G_c D``, where ``D`` is the time
    derivative on the coefficients and ``G_k``, ``G_c`` the Galerkin products with the modal
    tangents ``Phi^T k_t(t) Phi``, ``Phi^T c_t(t) Phi``.
    """
    nc, m = basis.size, omega.size
    Dt = wb * (basis.P @ basis.dE)  # exact: the derivative of a basis function is in the basis
    Gk = _galerkin(basis, Phi, Kt)
    Gc = _galerkin(basis, Phi, Ct)
    Im_, Ic = np.eye(m), np.eye(nc)
    D = np.kron(Dt, Im_)
    A1 = 2 * D + np.kron(Ic, Cm) - Gc
    A0 = np.kron(Dt @ Dt, Im_) + np.kron(Dt, Cm) + np.kron(Ic, np.diag(omega**2)) - Gk - Gc @ D
    n = nc * m
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = -A0
    A[n:, n:] = -A1
    return A


def _galerkin(basis: HarmonicBasis, Phi: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Coefficients of ``Phi^T G(t) Phi p(t)`` from those of ``p``: (nc m, nc m)."""
    nc, m = basis.size, Phi.shape[1]
    out = np.zeros((nc, m, nc, m))
    n_nl = Phi.shape[0]
    for i in range(n_nl):
        for j in range(n_nl):
            g = G[:, i, j]
            if not g.any():
                continue
            conv = (basis.P * g) @ basis.E  # (nc, nc): coefficients of g(t) * phi_d(t)
            out += conv[:, None, :, None] * np.outer(Phi[i], Phi[j])[None, :, None, :]
    return out.reshape(nc * m, nc * m)


def _ladder_exponents(mu: np.ndarray, wb: float, count: int) -> np.ndarray:
    """The ``count`` exponents among Hill's eigenvalues ``mu``, folded into the band.

    Each pick is the eigenvalue whose neighbouring rungs ``mu +- i wb`` are matched most
    closely by other eigenvalues (the best converged copy of its ladder); its ladder is then
    walked up and down, one eigenvalue per rung, and set aside, so that every exponent is
    picked once (two exponents that coincide keep two eigenvalues per rung, one each).
    """
    # shift[i, k]: distance of mu_k from the rung above mu_i
    shift = np.abs(mu[None, :] - (mu[:, None] + 1j * wb))
    picks = _walk_ladders(shift, shift.min(axis=1) + shift.min(axis=0), count, _RUNG_TOL * wb)
    lam = mu[picks]
    return lam - 1j * wb * np.round(lam.imag / wb)


@njit(cache=True)
def _walk_ladders(shift, defect, count, tol):
    n = defect.size
    left = np.ones(n, np.bool_)
    picks = np.empty(min(count, n), np.int64)
    n_picks = 0
    while n_picks < picks.size:
        i, best = -1, np.inf
        for k in range(n):
            if left[k] and defect[k] < best:
                i, best = k, defect[k]
        if i < 0:
            break
        picks[n_picks] = i
        n_picks += 1
        left[i] = False
        for up in (True, False):
            cur = i
            while True:
                k, gap = -1, tol
                for j in range(n):
                    d = shift[cur, j] if up else shift[j, cur]
                    if left[j] and d <= gap:
                        k, gap = j, d
                if k < 0:
                    break
                left[k] = False
                cur = k
    return picks[:n_picks]


# -- the full model's Hill matrix and the monodromy matrix --------------------------------
def _hill_full(
    mdl: SecondOrderModel, Kz: np.ndarray, Cz: np.ndarray, wb: float, nh: int
) -> np.ndarray:
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
