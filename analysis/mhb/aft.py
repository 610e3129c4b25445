"""Alternating frequency-time evaluation of the nonlinear forces, with exact jumps.

Forces are sampled at ``N`` points of the base period and projected on the harmonics. A law
whose force *jumps* at a displacement threshold (the paper's contact: its damping term jumps at
entry and exit) would make this projection, and so the balance residual, a discontinuous
function of the unknowns: every time a sample crosses the threshold the residual jumps by
``~J/N``, and Newton stalls far above its tolerance. Each threshold crossing between two
samples is therefore located on the Fourier series itself (``u(tau*) = u_s``) and the jump's
contribution is integrated: the sampled sum puts the jump at the cell boundary ``tau_m``, so
``-J (tau* - tau_m) phi(tau*)`` is added (error O(dtau^2), the order of the sampling error of a
kink), with its exact derivatives. The residual
becomes continuous, Newton converges to its tolerance and the Jacobian includes the jump term
``J phi(tau*) e(tau*)^T / u'(tau*)`` (the delta function of ``df/du`` at the jump).
"""

from __future__ import annotations

import numpy as np

from analysis.mhb.harmonics import HarmonicBasis

__all__ = ["element_forces", "nonlinear_forces", "parameter_forces"]


def _rows(b: HarmonicBasis, tau: np.ndarray, second: bool = True):
    """Basis rows and their first (and second) tau-derivatives, each shape (n, 2H+1)."""
    k = np.arange(1.0, b.n_harmonics + 1)
    kt = np.multiply.outer(np.atleast_1d(tau), k)
    c, s = np.cos(kt), np.sin(kt)
    n = kt.shape[0]
    e = np.empty((n, b.size))
    de = np.empty((n, b.size))
    e[:, 0], de[:, 0] = 1.0, 0.0
    e[:, 1::2], e[:, 2::2] = c, s
    ks, kc = k * s, k * c
    de[:, 1::2], de[:, 2::2] = -ks, kc
    if not second:
        return e, de, None
    dde = np.empty((n, b.size))
    dde[:, 0] = 0.0
    dde[:, 1::2], dde[:, 2::2] = -k * kc, -k * ks
    return e, de, dde


def _weights(b: HarmonicBasis) -> np.ndarray:
    """Integral weights: coefficient c = w[c] * integral over the period of f * phi_c dtau."""
    w = np.full(b.size, 1.0 / np.pi)
    w[0] = 1.0 / (2 * np.pi)
    return w


def _crossings(b: HarmonicBasis, Ue: np.ndarray, u_t: np.ndarray, u_s: float):
    """Threshold crossings between consecutive samples, refined on the Fourier series.

    Returns the sample index before each crossing, shape (n_c,), and the phase, shape (n_c,).
    """
    g = u_t - u_s
    above = g > 0
    change = np.empty(above.size, bool)
    np.not_equal(above[:-1], above[1:], out=change[:-1])
    change[-1] = above[-1] != above[0]
    idx = np.flatnonzero(change)
    dtau = 2 * np.pi / b.n_time
    if idx.size == 0:
        return idx, np.zeros(0)
    g0, g1 = g[idx], g[(idx + 1) % g.size]
    lo = b.tau[idx]
    t = lo + dtau * g0 / (g0 - g1)
    for _ in range(1):  # Newton on u(tau) - u_s from the chord: error O(dtau^4)
        e, de, _ = _rows(b, t, second=False)
        d = de @ Ue
        ok = d != 0
        t = np.where(ok, t - (e @ Ue - u_s) / np.where(ok, d, 1.0), t)
        t = np.clip(t, lo, lo + dtau)
    return idx, t


def element_forces(
    b: HarmonicBasis,
    element,
    Ue: np.ndarray,
    omega_b: float,
    jacobian: bool = True,
    want_params: bool = False,
):
    """Harmonics of one element's force on its relative displacement coefficients.

    Parameters
    ----------
    b : HarmonicBasis
    element : NonlinearElement
    Ue : ndarray, shape (2H+1,)
        Coefficients of the element's relative displacement [m].
    omega_b : float
        Base angular frequency [rad/s].

    Returns
    -------
    F : ndarray, shape (2H+1,)
    D : ndarray, shape (2H+1, 2H+1) or None
        ``dF/dUe``.
    dFp : ndarray, shape (2H+1, n_params) or None
        ``dF/dp`` (with ``want_params``).
    """
    u_t = b.E @ Ue
    v_t = omega_b * (b.dE @ Ue)
    ev = element.evaluate(u_t, v_t, want_params)
    F = b.P @ ev.f
    D = None
    if jacobian:
        D = b.P @ (ev.df_du[:, None] * b.E + (omega_b * ev.df_dv)[:, None] * b.dE)
    dFp = (b.P @ ev.df_dp.T) if want_params else None
    sw = element.switch_threshold()
    if sw is None:
        return F, D, dFp
    u_s, dus_dp = sw
    idx, t = _crossings(b, Ue, u_t, u_s)
    if idx.size == 0:
        return F, D, dFp
    w = _weights(b)
    dtau = 2 * np.pi / b.n_time
    e, de, dde = _rows(b, t)
    up = de @ Ue  # du/dtau at each crossing, shape (n_c,)
    keep = up != 0
    idx, t, e, de, dde, up = idx[keep], t[keep], e[keep], de[keep], dde[keep], up[keep]
    vs = omega_b * up
    after = np.where(u_t[(idx + 1) % b.n_time] > u_s, 1.0, -1.0)
    eps = 1e-9 * max(abs(u_s), np.abs(u_t).max(), 1e-300)
    both = element.evaluate(
        np.concatenate([u_s + after * eps, u_s - after * eps]), np.tile(vs, 2), want_params
    )
    nc = idx.size
    J = both.f[:nc] - both.f[nc:]
    dJ_dv = both.df_dv[:nc] - both.df_dv[nc:]
    s = t - (b.tau[idx] + 0.5 * dtau)  # offset from the cell boundary the sum assumes
    phi = e  # phi at tau* (the O(s^2) midpoint term is of the sampling error's order)
    F += (w * phi).T @ (-J * s)
    ddU = dde @ Ue
    if jacobian:
        dt_dU = -e / up[:, None]  # from u(tau*) = u_s
        dup_dU = de + ddU[:, None] * dt_dU
        dJ_dU = (dJ_dv * omega_b)[:, None] * dup_dU
        D += (w * phi).T @ (-(dJ_dU * s[:, None] + J[:, None] * dt_dU))
        D += (w * de).T @ (-(J * s)[:, None] * dt_dU)
    if want_params:
        dt_dp = np.outer(1.0 / up, dus_dp)  # (n_c, n_params)
        dup_dp = ddU[:, None] * dt_dp
        dJ_dp = (both.df_dp[:, :nc] - both.df_dp[:, nc:]).T + (dJ_dv * omega_b)[:, None] * dup_dp
        dFp += (w * phi).T @ (-(dJ_dp * s[:, None] + J[:, None] * dt_dp))
        dFp += (w * de).T @ (-(J * s)[:, None] * dt_dp)
    return F, D, dFp


def nonlinear_forces(problem, X: np.ndarray, omega_b: float, jacobian: bool = True):
    """AFT nonlinear forces on the nonlinear DOFs and their Jacobian.

    Parameters
    ----------
    problem : HarmonicProblem
    X : ndarray, shape (2H+1, n_nl)
    omega_b : float

    Returns
    -------
    F : ndarray, shape (2H+1, n_nl)
    dF : ndarray, shape ((2H+1) n_nl, (2H+1) n_nl) or None
    """
    b = problem.basis
    U = X @ problem.L.T
    n, s = problem.n_nl, b.size
    F = np.zeros((s, n))
    dF = np.zeros((s, n, s, n)) if jacobian else None
    for e, att in enumerate(problem.attachments):
        Fe, De, _ = element_forces(b, att.element, U[:, e], omega_b, jacobian)
        Le = problem.L[e]
        F += np.outer(Fe, Le)
        if jacobian:
            dF += np.einsum("ab,i,j->aibj", De, Le, Le)
    return F, (dF.reshape(s * n, s * n) if jacobian else None)


def parameter_forces(problem, X: np.ndarray, omega_b: float) -> dict[str, np.ndarray]:
    """``dF/dp`` (shape (2H+1, n_nl)) for every model parameter mapped to an element."""
    b = problem.basis
    U = X @ problem.L.T
    out: dict[str, np.ndarray] = {}
    for e, att in enumerate(problem.attachments):
        if not att.param_map:
            continue
        _, _, dFp = element_forces(b, att.element, U[:, e], omega_b, False, True)
        names = att.element.param_names
        for model_p, elem_p in att.param_map.items():
            dF = np.outer(dFp[:, names.index(elem_p)], problem.L[e])
            out[model_p] = out.get(model_p, 0.0) + dF
    return out
