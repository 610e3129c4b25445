"""Normal modes of the underlying linear structure and their exact parameter sensitivities."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

__all__ = ["Modes", "modal_analysis", "mode_sensitivities"]

#: ``(dlam, dphi)`` of :func:`mode_sensitivities`, by parameter name.
Sensitivities = tuple[dict[str, np.ndarray], dict[str, np.ndarray]]


@dataclass(frozen=True)
class Modes:
    """Mass-normalised real modes with modal damping.

    Attributes
    ----------
    omega : ndarray, shape (m,), rad/s
        Undamped natural angular frequencies, ascending.
    phi : ndarray, shape (n_dof, m)
        Mode shapes, ``phi.T @ M @ phi = I``.
    zeta : ndarray, shape (m,)
        Modal damping ratios.
    """

    omega: np.ndarray
    phi: np.ndarray
    zeta: np.ndarray

    @property
    def frequency_hz(self) -> np.ndarray:
        """Natural frequencies [Hz], shape (m,)."""
        return self.omega / (2 * np.pi)

    def __len__(self) -> int:
        return self.omega.size


def modal_analysis(
    M: np.ndarray,
    K: np.ndarray,
    zeta: float | np.ndarray | dict[int, float] = 0.01,
    *,
    default_zeta: float = 0.01,
) -> Modes:
    """All real modes of ``(K, M)`` with damping ratios.

    Parameters
    ----------
    M, K : ndarray, shape (n, n)
        Symmetric mass [kg] and stiffness [N/m] matrices; ``M`` positive definite.
    zeta : float, ndarray of shape (n,), or dict
        One ratio for all modes, one per mode, or ``{mode_number (1-based): ratio}`` with
        ``default_zeta`` for the others.

    Returns
    -------
    Modes
    """
    # Symmetric diagonal scaling to unit mass diagonal: rotational and translational DOFs
    # differ by orders of magnitude, and unscaled the reduction to standard form loses digits.
    d = 1.0 / np.sqrt(np.abs(np.diag(M)))
    lam, phi_s = sla.eigh(K * np.outer(d, d), M * np.outer(d, d))
    phi = phi_s * d[:, None]
    if lam[0] < -1e-8 * abs(lam[-1]):
        raise ValueError(
            f"stiffness matrix is not positive semi-definite (lowest eigenvalue {lam[0]:.3g})"
        )
    lam = np.clip(lam, 0.0, None)
    omega = np.sqrt(lam)
    n = lam.size
    if isinstance(zeta, dict):
        z = np.full(n, float(default_zeta))
        for mode, value in zeta.items():
            if 1 <= int(mode) <= n:
                z[int(mode) - 1] = float(value)
    else:
        z = np.broadcast_to(np.asarray(zeta, dtype=float), (n,)).copy()
    if np.any(z < 0):
        raise ValueError("modal damping ratios must be >= 0")
    return Modes(omega=omega, phi=phi, zeta=z)


def mode_sensitivities(
    M: np.ndarray,
    K: np.ndarray,
    modes: Modes,
    dM: dict[str, np.ndarray],
    dK: dict[str, np.ndarray],
    which: np.ndarray | None = None,
) -> Sensitivities:
    """Exact derivatives of eigenvalues and mass-normalised mode shapes.

    ``dlam = phi^T (dK - lam dM) phi``. The shape derivative: when ``modes`` holds every mode
    of ``(K, M)`` (as :func:`modal_analysis` returns them), by the expansion over all of
    them, exact with a complete basis::

        dphi_r = sum_{s != r} phi_s phi_s^T (dK - lam_r dM) phi_r / (lam_r - lam_s)
                 - phi_r phi_r^T dM phi_r / 2

    (three matrix products per parameter for all modes at once); otherwise from the
    bordered system of Nelson's method (one solve of size ``n + 1`` per mode), its border
    scaled by ``s`` to the magnitude of ``K - lam M``::

        [K - lam M   -s M phi] [dphi ]   [-(dK - lam dM) phi + dlam M phi]
        [-s phi^T M      0   ] [ c/s ] = [ s/2 phi^T dM phi             ]

    (``c`` vanishes for exact data; it absorbs round-off).

    Parameters
    ----------
    M, K : ndarray, shape (n, n)
    modes : Modes
        The modes; all ``n`` of them for the expansion.
    dM, dK : dict name -> ndarray, shape (n, n)
        Derivatives of the matrices with respect to each parameter.
    which : ndarray of int, optional
        Indices of the modes to differentiate (default: all in ``modes``).

    Returns
    -------
    dlam : dict name -> ndarray, shape (len(which),)
        Derivatives of ``omega**2`` [rad^2/s^2 per parameter unit].
    dphi : dict name -> ndarray, shape (n, len(which))

    Notes
    -----
    Valid for distinct eigenvalues (repeated ones have no unique shape derivative).
    """
    which = np.arange(len(modes)) if which is None else np.asarray(which)
    if modes.phi.shape[1] == M.shape[0]:
        return _expanded(modes, dM, dK, which)
    return _nelson(M, K, modes, dM, dK, which)


def _expanded(
    modes: Modes, dM: dict[str, np.ndarray], dK: dict[str, np.ndarray], which: np.ndarray
) -> Sensitivities:
    """:func:`mode_sensitivities` by the expansion over every mode."""
    phi = modes.phi
    lam = modes.omega**2
    lam_w = lam[which]
    phi_w = phi[:, which]
    cols = np.arange(which.size)
    gap = lam_w[None, :] - lam[:, None]
    gap[which, cols] = 1.0  # the mode itself: its coefficient is set below
    dlam, dphi = {}, {}
    for p, dKp in dK.items():
        A = phi.T @ (dKp @ phi_w)  # phi_s^T dK phi_r
        dMp = dM.get(p)
        B = phi.T @ (dMp @ phi_w) if dMp is not None else np.zeros_like(A)
        A -= B * lam_w[None, :]  # phi_s^T (dK - lam_r dM) phi_r
        dlam[p] = A[which, cols].copy()
        C = A / gap
        C[which, cols] = -0.5 * B[which, cols]
        dphi[p] = phi @ C
    return dlam, dphi


def _nelson(
    M: np.ndarray,
    K: np.ndarray,
    modes: Modes,
    dM: dict[str, np.ndarray],
    dK: dict[str, np.ndarray],
    which: np.ndarray,
) -> Sensitivities:
    """:func:`mode_sensitivities` by Nelson's method, mode by mode."""
    names = list(dK)
    n = M.shape[0]
    dlam = {p: np.empty(which.size) for p in names}
    dphi = {p: np.empty((n, which.size)) for p in names}
    A = np.empty((n + 1, n + 1))
    for j, r in enumerate(which):
        lam = modes.omega[r] ** 2
        ph = modes.phi[:, r]
        Mph = M @ ph
        Z = K - lam * M
        # balance the border against Z (K ~ 1e9 N/m next to M phi ~ 1 loses all accuracy)
        s = np.abs(Z).max() / max(np.abs(Mph).max(), 1e-300)
        A[:n, :n] = Z
        A[:n, n] = -s * Mph
        A[n, :n] = -s * Mph
        A[n, n] = 0.0
        rhs = np.zeros((n + 1, len(names)))
        for i, p in enumerate(names):
            dMp = dM.get(p)
            dMph = dMp @ ph if dMp is not None else np.zeros(n)
            t = dK[p] @ ph - lam * dMph
            dlam[p][j] = ph @ t  # exact: phi^T (dK - lam dM) phi
            rhs[:n, i] = -t + dlam[p][j] * Mph
            rhs[n, i] = 0.5 * s * (ph @ dMph)
        sol = np.linalg.solve(A, rhs)
        for i, p in enumerate(names):
            dphi[p][:, j] = sol[:n, i]
    return dlam, dphi
