"""Alternating frequency-time evaluation of the nonlinear forces, with exact jumps.

Forces are sampled at ``N`` points of the base period and projected on the harmonics. A law
whose force *jumps* at a displacement threshold (the paper's contact: its damping term jumps at
entry and exit) would make this projection, and so the balance residual, a discontinuous
function of the unknowns: every time a sample crosses the threshold the residual jumps by
``~J/N``, and Newton stalls far above its tolerance. Each threshold crossing between two
samples is therefore located on the Fourier series itself (``u(tau*) = u_s``) and the jump's
contribution is integrated exactly: the sampled sum puts the jump at the cell boundary
``tau_m``, so ``-J (tau* - tau_m) phi(tau_a)`` is added, with its exact derivatives. The residual
becomes continuous, Newton converges to its tolerance and the Jacobian includes the jump term
``J phi(tau*) e(tau*)^T / u'(tau*)`` (the delta function of ``df/du`` at the jump).
"""

from __future__ import annotations

import numpy as np

from analysis.mhb.harmonics import HarmonicBasis

__all__ = ["element_forces", "nonlinear_forces", "parameter_forces"]


def _rows(b: HarmonicBasis, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Basis row, its first and second tau-derivatives at ``tau``, each shape (2H+1,)."""
    k = np.arange(1, b.n_harmonics + 1)
    c, s = np.cos(k * tau), np.sin(k * tau)
    e = np.empty(b.size)
    de = np.zeros(b.size)
    dde = np.zeros(b.size)
    e[0] = 1.0
    e[1::2], e[2::2] = c, s
    de[1::2], de[2::2] = -k * s, k * c
    dde[1::2], dde[2::2] = -(k**2) * c, -(k**2) * s
    return e, de, dde


def _weights(b: HarmonicBasis) -> np.ndarray:
    """Integral weights: coefficient c = w[c] * integral over the period of f * phi_c dtau."""
    w = np.full(b.size, 1.0 / np.pi)
    w[0] = 1.0 / (2 * np.pi)
    return w


def _crossings(b: HarmonicBasis, Ue: np.ndarray, u_t: np.ndarray, u_s: float):
    """Threshold crossings between consecutive samples, refined on the Fourier series."""
    g = u_t - u_s
    nxt = np.roll(g, -1)
    idx = np.flatnonzero((g > 0) != (nxt > 0))
    dtau = 2 * np.pi / b.n_time
    out = []
    for i in idx:
        g0, g1 = g[i], nxt[i]
        t = b.tau[i] + dtau * g0 / (g0 - g1) if g0 != g1 else b.tau[i] + 0.5 * dtau
        for _ in range(3):  # Newton on u(tau) - u_s, safeguarded to the cell
            e, de, _ = _rows(b, t)
            d = de @ Ue
            if d == 0:
                break
            t = np.clip(t - (e @ Ue - u_s) / d, b.tau[i], b.tau[i] + dtau)
        out.append((i, t))
    return out


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
    w = _weights(b)
    dtau = 2 * np.pi / b.n_time
    scale = max(abs(u_s), np.abs(u_t).max(), 1e-300)
    for i, t in _crossings(b, Ue, u_t, u_s):
        e, de, dde = _rows(b, t)
        up = de @ Ue  # du/dtau at the crossing
        if up == 0:
            continue
        vs = omega_b * up
        after = 1.0 if u_t[(i + 1) % b.n_time] > u_s else -1.0
        eps = 1e-9 * scale
        ea = element.evaluate(np.array([u_s + after * eps]), np.array([vs]), want_params)
        eb = element.evaluate(np.array([u_s - after * eps]), np.array([vs]), want_params)
        J = float(ea.f[0] - eb.f[0])
        tm = b.tau[i] + 0.5 * dtau
        s = t - tm
        ta = 0.5 * (t + tm)
        phi, dphi, _ = _rows(b, ta)
        F += w * (-J * s) * phi
        if jacobian:
            dt_dU = -e / up  # from u(tau*) = u_s
            dup_dU = de + (dde @ Ue) * dt_dU
            dJ_dU = float(ea.df_dv[0] - eb.df_dv[0]) * omega_b * dup_dU
            D += np.outer(w * phi, -(dJ_dU * s + J * dt_dU))
            D += np.outer(w * dphi, -J * s * 0.5 * dt_dU)
        if want_params:
            dt_dp = dus_dp / up
            dup_dp = (dde @ Ue) * dt_dp
            dJ_dp = (ea.df_dp[:, 0] - eb.df_dp[:, 0]) + float(
                ea.df_dv[0] - eb.df_dv[0]
            ) * omega_b * dup_dp
            dFp += np.outer(w * phi, -(dJ_dp * s + J * dt_dp))
            dFp += np.outer(w * dphi, -J * s * 0.5 * dt_dp)
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
