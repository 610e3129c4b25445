"""Modal identification of the FRFs of one input: poles, modal constants and residual terms.

Each in-band mode ``r`` contributes to channel ``c`` the real-coefficient second-order term

    H_rc(omega) = (a_rc + i omega b_rc) / (omega_r^2 - omega^2 + 2 i zeta_r omega_r omega),

the general form of a conjugate pole pair ``lambda_r = -zeta_r omega_r + i omega_r
sqrt(1 - zeta_r^2)`` with a complex residue (``b_rc`` is zero for real, normal modes, when
``a_rc = phi_r(c) phi_r(drive)`` is the modal constant). Modes outside the band enter as
residual terms with real coefficients, ``u0 + u2 (omega / omega_hi)^2 + u4 (omega / omega_hi)^4
- l (omega_lo / omega)^2 + i v (omega / omega_hi)``: the series of the modes above the band
(their stiffness, the next two terms of their expansion and their damping) and the mass line
of the modes below.

The fit is a separable nonlinear least-squares problem: for given ``(omega_r, zeta_r)`` the
coefficients follow by linear least squares channel by channel, and only the poles are iterated
(variable projection with Kaufman's Jacobian). Residuals are relative errors ``(H_fit - H) / |H|``
unless weights are given. Starting poles come from a sub-band LSCF stabilisation diagram
(:mod:`analysis.calibration.linear.lscf`); poles that carry less than ``min_contribution`` of the
response at their resonance in every channel are dropped, and the fit is repeated.

References
----------
G. H. Golub, V. Pereyra, "Separable nonlinear least squares: the variable projection method
and its applications", Inverse Problems 19 (2003) R1-R26.
L. Kaufman, "A variable projection method for solving separable nonlinear least squares
problems", BIT 15 (1975) 49-57.
D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research Studies
Press 2000, sec. 4.4 (residual terms).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from analysis.calibration.linear.lscf import starting_poles

__all__ = ["ModalFit", "fit_poles", "identify_modes"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ModalFit:
    """Pole-residue model of the FRFs of one input in a band (all arrays read-only).

    Attributes
    ----------
    omega : ndarray, shape (m,), rad/s
        Undamped natural angular frequencies ``|lambda_r|``, ascending.
    zeta : ndarray, shape (m,)
        Damping ratios.
    a, b : ndarray, shape (m, C), unit of H times rad^2/s^2 and rad/s
        Numerator coefficients (``a`` the modal constants).
    residual : ndarray, shape (5, C)
        Residual terms ``u0, u2, u4, l, v`` (unit of H).
    band_hz : (float, float)
    x, cost, nfev, success, message
        Of the final pole iteration (``x = [log omega_r, log zeta_r]``, cost as scipy).
    rms_relative_error : float
        RMS of ``|H_fit - H| / |H|`` over the fitted points.
    x_std : ndarray, shape (2 m,) or None
        Standard deviations of ``x`` (so of ``ln omega_r`` and ``ln zeta_r``: relative ones)
        from the pole iteration's Jacobian, ``(J^T J)^-1`` scaled by the chi-square per
        degree of freedom where that exceeds 1 (the residuals are weighted by the FRFs'
        standard errors when they are given); None without poles.
    """

    omega: np.ndarray
    zeta: np.ndarray
    a: np.ndarray
    b: np.ndarray
    residual: np.ndarray
    band_hz: tuple[float, float]
    x: np.ndarray
    cost: float
    nfev: int
    success: bool
    message: str
    rms_relative_error: float
    x_std: np.ndarray | None = None

    @property
    def frequency_hz(self) -> np.ndarray:
        """Undamped natural frequencies [Hz], shape (m,)."""
        return self.omega / (2 * np.pi)

    @property
    def poles(self) -> np.ndarray:
        """Upper-half-plane poles ``lambda_r`` [rad/s], shape (m,)."""
        return -self.zeta * self.omega + 1j * self.omega * np.sqrt(1 - self.zeta**2)

    @property
    def n_modes(self) -> int:
        return int(self.omega.size)

    def mode_terms(self, frequency_hz: np.ndarray, zeta: float | np.ndarray | None = None):
        """Each mode's contribution, shape (nf, m, C), with the given damping (default: fitted)."""
        w = 2 * np.pi * np.asarray(frequency_hz, dtype=float)
        z = self.zeta if zeta is None else np.broadcast_to(np.asarray(zeta, float), self.zeta.shape)
        g = 1.0 / (self.omega**2 - w[:, None] ** 2 + 2j * z * self.omega * w[:, None])
        return g[:, :, None] * (self.a[None] + 1j * w[:, None, None] * self.b[None])

    def synthesize(
        self, frequency_hz: np.ndarray, zeta: float | np.ndarray | None = None
    ) -> np.ndarray:
        """The fitted FRFs, shape (nf, C), optionally with every mode at damping ``zeta``.

        Parameters
        ----------
        frequency_hz : ndarray, shape (nf,), Hz
        zeta : float or ndarray of shape (m,), optional
            Damping ratios replacing the fitted ones (damping equalization: one value for all);
            natural frequencies, numerators and residual terms are kept.
        """
        w = 2 * np.pi * np.asarray(frequency_hz, dtype=float)
        return (
            self.mode_terms(frequency_hz, zeta).sum(axis=1)
            + _residual_basis(w, self.band_hz) @ self.residual
        )


def _residual_basis(w: np.ndarray, band_hz: tuple[float, float]) -> np.ndarray:
    """Columns 1, (w/w_hi)^2, (w/w_hi)^4, -(w_lo/w)^2, i w/w_hi, shape (nf, 5), complex."""
    w_lo, w_hi = 2 * np.pi * band_hz[0], 2 * np.pi * band_hz[1]
    u = w / w_hi
    return np.column_stack([np.ones_like(w), u**2, u**4, -((w_lo / w) ** 2), 1j * u])


class _Projection:
    """Variable projection: coefficients by linear least squares for given poles."""

    def __init__(self, w: np.ndarray, H: np.ndarray, weights: np.ndarray, band_hz) -> None:
        self.w, self.H, self.W = w, H, weights
        self.R = _residual_basis(w, band_hz)

    def columns(self, wr: np.ndarray, zr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w = self.w[:, None]
        g = 1.0 / (wr**2 - w**2 + 2j * zr * wr * w)
        return g, 1j * w * g

    def solve(self, x: np.ndarray, want_jac: bool):
        m = x.size // 2
        wr, zr = np.exp(x[:m]), np.exp(x[m:])
        g, ig = self.columns(wr, zr)
        Phi = np.concatenate([g, ig, self.R], axis=1)  # (nf, 2m + 5) complex
        nf, C = self.H.shape
        coef = np.empty((Phi.shape[1], C))
        res = np.empty((2 * nf, C))
        jac = np.empty((2 * nf, C, 2 * m)) if want_jac else None
        if want_jac:
            w = self.w[:, None]
            dg_dw = -(2 * wr + 2j * zr * w) * g**2 * wr  # d g / d log omega_r
            dg_dz = -(2j * wr * w) * g**2 * zr  # d g / d log zeta_r
        for c in range(C):
            A = Phi * self.W[:, c : c + 1]
            Ar = np.concatenate([A.real, A.imag])
            scale = np.linalg.norm(Ar, axis=0)
            scale[scale == 0] = 1.0
            y = self.H[:, c] * self.W[:, c]
            yr = np.concatenate([y.real, y.imag])
            Q, Rm = np.linalg.qr(Ar / scale)
            if np.all(np.abs(np.diag(Rm)) > 1e-14):
                cs = np.linalg.solve(Rm, Q.T @ yr)
            else:  # dependent columns (coincident poles): minimum-norm coefficients
                cs = np.linalg.lstsq(Ar / scale, yr, rcond=None)[0]
            coef[:, c] = cs / scale
            res[:, c] = (Ar / scale) @ cs - yr
            if want_jac:
                a_, b_ = coef[:m, c], coef[m : 2 * m, c]
                num = a_ + 1j * self.w[:, None] * b_  # (nf, m)
                D = np.concatenate([dg_dw * num, dg_dz * num], axis=1) * self.W[:, c : c + 1]
                Dr = np.concatenate([D.real, D.imag])
                jac[:, c, :] = Dr - Q @ (Q.T @ Dr)  # Kaufman: P_perp dA/dx c
        return res, coef, jac


def fit_poles(
    frequency_hz: np.ndarray,
    H: np.ndarray,
    frequency0_hz: Sequence[float],
    zeta0: Sequence[float],
    *,
    band_hz: tuple[float, float] | None = None,
    weights: np.ndarray | None = None,
    max_nfev: int = 100,
) -> ModalFit:
    """Refine poles and fit numerators and residual terms by variable projection.

    Parameters
    ----------
    frequency_hz : ndarray, shape (nf,), Hz
        Frequencies of the fitted points (all > 0).
    H : ndarray, shape (nf, C), complex
        FRFs of one input (receptance for the residual terms to mean mass and stiffness).
    frequency0_hz, zeta0 : sequence of float, length m
        Starting natural frequencies [Hz] and damping ratios.
    band_hz : (float, float), optional
        Scales the residual terms (default: the range of ``frequency_hz``).
    weights : ndarray, shape (nf, C), optional
        Residual weights (default ``1 / |H|``: relative errors).

    Returns
    -------
    ModalFit
    """
    f = np.asarray(frequency_hz, dtype=float)
    H = np.asarray(H, dtype=complex)
    band = (float(f.min()), float(f.max())) if band_hz is None else tuple(map(float, band_hz))
    if weights is None:
        weights = 1.0 / np.maximum(np.abs(H), 1e-12 * np.abs(H).max(axis=0))
    proj = _Projection(2 * np.pi * f, H, np.asarray(weights, dtype=float), band)
    m = len(frequency0_hz)
    x0 = np.concatenate(
        [np.log(2 * np.pi * np.asarray(frequency0_hz, float)), np.log(np.asarray(zeta0, float))]
    )
    if m:
        cache: dict = {}

        def fun(x):
            r, _, J = proj.solve(x, True)
            cache["jac"] = J.reshape(-1, x.size)
            return r.ravel()

        def jac(x):
            if "jac" not in cache:
                fun(x)
            return cache.pop("jac")

        lo = np.concatenate([x0[:m] - 0.2, np.full(m, np.log(1e-5))])
        hi = np.concatenate([x0[:m] + 0.2, np.full(m, np.log(0.5))])
        x0 = np.clip(x0, lo + 1e-9, hi - 1e-9)
        sol = least_squares(
            fun,
            x0,
            jac=jac,
            bounds=(lo, hi),
            method="trf",
            x_scale=1.0,
            xtol=1e-12,
            ftol=1e-12,
            gtol=1e-12,
            max_nfev=max_nfev,
        )
        x, nfev, ok, msg = sol.x, sol.nfev, sol.success, sol.message
        dof = max(sol.fun.size - x.size, 1)
        scale = max(1.0, float(sol.fun @ sol.fun) / dof)
        x_std = np.sqrt(np.maximum(np.diag(np.linalg.pinv(sol.jac.T @ sol.jac)), 0) * scale)
    else:
        x, nfev, ok, msg = x0, 1, True, "no poles: residual terms only"
        x_std = None
    res, coef, _ = proj.solve(x, False)
    cost = 0.5 * float(np.sum(res**2))
    order = np.argsort(x[:m])
    wr, zr = np.exp(x[:m])[order], np.exp(x[m:])[order]
    rel = res[: f.size] + 1j * res[f.size :]
    rel = rel / np.maximum(np.abs(H * weights), 1e-300)
    return ModalFit(
        omega=_ro(wr),
        zeta=_ro(zr),
        a=_ro(coef[:m][order]),
        b=_ro(coef[m : 2 * m][order]),
        residual=_ro(coef[2 * m :]),
        band_hz=band,
        x=_ro(np.concatenate([np.log(wr), np.log(zr)])),
        cost=cost,
        nfev=int(nfev),
        success=bool(ok),
        message=str(msg),
        rms_relative_error=float(np.sqrt(np.mean(np.abs(rel) ** 2))),
        x_std=None if x_std is None else _ro(np.concatenate([x_std[:m][order], x_std[m:][order]])),
    )


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a)
    a.setflags(write=False)
    return a


def _contribution(fit: ModalFit, H_at: np.ndarray) -> np.ndarray:
    """Largest share of each mode in the response at its own resonance, shape (m,)."""
    terms = fit.mode_terms(fit.frequency_hz)  # (m at f_r, m, C)
    own = np.abs(terms[np.arange(fit.n_modes), np.arange(fit.n_modes)])  # (m, C)
    return np.max(own / np.maximum(np.abs(H_at), 1e-300), axis=1)


def identify_modes(
    frequency_hz: np.ndarray,
    H: np.ndarray,
    band_hz: tuple[float, float] | None = None,
    *,
    weights: np.ndarray | None = None,
    start_weights: np.ndarray | None = None,
    max_order: int = 32,
    zeta_max: float = 0.2,
    min_contribution: float = 0.05,
) -> ModalFit:
    """Identify the modes of FRFs of one input in a band.

    Parameters
    ----------
    frequency_hz : ndarray, shape (nf,), Hz
    H : ndarray, shape (nf, C), complex
        Receptances [m/N] (another quantity works, but then the residual terms lose their
        meaning of mass and stiffness).
    band_hz : (float, float), optional
        Default: the positive frequencies of ``frequency_hz``.
    weights : ndarray, shape (nf, C), optional
        Default ``1 / |H|`` (relative errors).
    start_weights : ndarray, shape (nf, C), optional
        Weights of the LSCF equation errors for the starting poles, e.g. the coherence (absolute
        errors: relative weights would let the anti-resonances and the noise floor dominate the
        linearised fit). Default uniform.
    max_order : int
        Highest LSCF model order per sub-band.
    zeta_max : float
        Poles with more damping are not modes.
    min_contribution : float
        A mode must carry at least this fraction of the response of some channel at its
        resonance.

    Returns
    -------
    ModalFit
        Modes with natural frequency inside the band, ascending.
    """
    f = np.asarray(frequency_hz, dtype=float)
    H = np.asarray(H, dtype=complex)
    if f.ndim != 1 or H.ndim != 2 or H.shape[0] != f.size:
        raise ValueError(f"H must have shape (nf, C) with nf = {f.size}, got {H.shape}")
    lo, hi = (float(f[f > 0].min()), float(f.max())) if band_hz is None else band_hz
    sel = (f >= lo) & (f <= hi) & (f > 0)
    if np.count_nonzero(sel) < 16:
        raise ValueError(f"band {lo:g}-{hi:g} Hz holds {np.count_nonzero(sel)} frequencies")
    f, H = f[sel], H[sel]
    W = None if weights is None else np.asarray(weights, dtype=float)[sel]
    Ws = None if start_weights is None else np.asarray(start_weights, dtype=float)[sel]
    start = starting_poles(f, H, (lo, hi), max_order=max_order, zeta_max=zeta_max, weights=Ws)
    f0 = [p.frequency_hz for p in start]
    z0 = [p.zeta for p in start]
    fit = fit_poles(f, H, f0, z0, band_hz=(lo, hi), weights=W)
    for _ in range(5):
        keep = (fit.zeta < zeta_max) & (fit.frequency_hz >= lo) & (fit.frequency_hz <= hi)
        if fit.n_modes:
            H_at = np.array([H[np.argmin(np.abs(f - fr))] for fr in fit.frequency_hz])
            keep &= _contribution(fit, H_at) >= min_contribution
            dup = np.flatnonzero(np.diff(fit.omega) / fit.omega[1:] < 1e-4) + 1
            keep[dup] = False
        if keep.all():
            break
        log.debug("dropping poles at %s Hz", np.round(fit.frequency_hz[~keep], 3))
        fit = fit_poles(f, H, fit.frequency_hz[keep], fit.zeta[keep], band_hz=(lo, hi), weights=W)
    log.info(
        "identified %d modes in %g-%g Hz (rms relative error %.2g)",
        fit.n_modes,
        lo,
        hi,
        fit.rms_relative_error,
    )
    return fit
