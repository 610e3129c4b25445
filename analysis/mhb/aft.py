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

The crossings and the jump integrals are a handful of numbers per crossing, computed by small
loops compiled with numba (in numpy they were some fifty calls on arrays of two, most of the
time of a contact model's balance). A law with a compiled form
(:meth:`~analysis.elements.base.NonlinearElement.compiled_law`) is evaluated between two
compiled halves, the samples and the projection; the others, and every evaluation with
parameter derivatives, go through the element's numpy code on a batch of states.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from analysis.mhb.harmonics import HarmonicBasis

__all__ = ["element_forces", "element_forces_batch", "nonlinear_forces", "parameter_forces"]

_NONE = np.zeros((0, 0))  # a derivative not wanted (the kernels skip size-0 arrays)
_NO_PARAMS = np.zeros(0)


@njit(cache=True)
def _series(k, Ue, t):
    """``u``, ``du/dtau`` and ``d2u/dtau2`` of the coefficients ``Ue`` at the phase ``t``."""
    u, d, dd = Ue[0], 0.0, 0.0
    for h in range(k.size):
        ch, sh = np.cos(k[h] * t), np.sin(k[h] * t)
        a, b = Ue[2 * h + 1], Ue[2 * h + 2]
        u += a * ch + b * sh
        d += k[h] * (b * ch - a * sh)
        dd -= k[h] * k[h] * (a * ch + b * sh)
    return u, d, dd


@njit(cache=True)
def _locate_jumps(tau, k, Ue, u_t, u_s):
    """Threshold crossings between consecutive samples, refined on the Fourier series.

    Each sign change of ``u_t - u_s`` (cyclic) starts at the chord's root and takes one
    Newton step on ``u(tau) - u_s`` (error O(dtau^4)), kept inside its cell.

    Returns
    -------
    idx : ndarray of int, shape (n_c,)
        Sample before each crossing.
    t : ndarray, shape (n_c,)
        Phase of the crossing.
    rows : ndarray, shape (2, n_c, 2H+1)
        Basis rows ``phi(t)`` and their tau-derivatives.
    up, upp : ndarray, shape (n_c,)
        ``du/dtau`` and ``d2u/dtau2`` there. Crossings with ``du/dtau = 0`` (tangent to the
        threshold, no jump to integrate) are left out.
    """
    N, H = u_t.size, k.size
    dtau = 2.0 * np.pi / N
    idx = np.empty(N, np.int64)
    n = 0
    for m in range(N):
        if (u_t[m] > u_s) != (u_t[(m + 1) % N] > u_s):
            idx[n] = m
            n += 1
    t = np.empty(n)
    rows = np.zeros((2, n, Ue.size))
    up = np.empty(n)
    upp = np.empty(n)
    kept = 0
    for c in range(n):
        m = idx[c]
        g0, g1 = u_t[m] - u_s, u_t[(m + 1) % N] - u_s
        lo = tau[m]
        tc = lo + dtau * g0 / (g0 - g1)
        u, d, _ = _series(k, Ue, tc)
        if d != 0.0:
            tc -= (u - u_s) / d
        tc = min(max(tc, lo), lo + dtau)
        _, d, dd = _series(k, Ue, tc)
        if d == 0.0:
            continue
        rows[0, kept, 0] = 1.0
        for h in range(H):
            ch, sh = np.cos(k[h] * tc), np.sin(k[h] * tc)
            rows[0, kept, 2 * h + 1], rows[0, kept, 2 * h + 2] = ch, sh
            rows[1, kept, 2 * h + 1], rows[1, kept, 2 * h + 2] = -k[h] * sh, k[h] * ch
        idx[kept], t[kept], up[kept], upp[kept] = m, tc, d, dd
        kept += 1
    return idx[:kept], t[:kept], rows[:, :kept], up[:kept], upp[:kept]


@njit(cache=True)
def _add_jumps(w, rows, up, upp, offset, J, dJ_dvel, dJ_dp, dus_dp, F, D, dFp):
    """Add the jumps' integrals and their derivatives to ``F``, ``D`` and ``dFp`` in place.

    The sampled sum puts the jump ``J`` of crossing ``c`` at its cell boundary, ``offset``
    before the crossing ``tau*``: ``-J offset phi(tau*)`` is added. ``tau*`` moves with the
    coefficients (``dtau*/dU = -phi / u'``) and with the parameters through the threshold
    (``dtau*/dp = du_s/dp / u'``); ``J`` changes with the velocity there (``dJ_dvel``, the
    velocity ``u'`` moving by ``phi' + u'' dtau*``) and with the parameters (``dJ_dp``).
    ``D`` (``dFp``) of size 0 is not wanted.
    """
    nc, s = up.size, w.size
    for c in range(nc):
        e, de = rows[0, c], rows[1, c]
        Js = J[c] * offset[c]
        for i in range(s):
            F[i] -= w[i] * e[i] * Js
        for j in range(D.shape[1]):
            dt = -e[j] / up[c]
            dJ = dJ_dvel[c] * (de[j] + upp[c] * dt)
            a, b = -(dJ * offset[c] + J[c] * dt), -Js * dt
            for i in range(s):
                D[i, j] += w[i] * (e[i] * a + de[i] * b)
        for p in range(dFp.shape[1]):
            dt = dus_dp[p] / up[c]
            dJ = dJ_dp[c, p] + dJ_dvel[c] * upp[c] * dt
            a, b = -(dJ * offset[c] + J[c] * dt), -Js * dt
            for i in range(s):
                dFp[i, p] += w[i] * (e[i] * a + de[i] * b)


@njit(cache=True)
def _project(P, E, dE, f, df_du, df_dv, D):
    """``F = P f`` and, unless ``D`` has size 0, ``D = P diag(df_du) E + P diag(df_dv) dE``
    (``D`` zeroed on entry), over the samples where the law acts: a clearance law is zero on
    most of the period, where dense products would multiply zeros. ``D`` is one matrix product
    of the acting samples' columns of ``P`` and rows of the law's derivatives (BLAS): summed
    sample by sample it cost five times as much for a law that acts all period."""
    s, N = P.shape
    act = np.empty(N, np.int64)
    na = 0
    for m in range(N):
        if not (f[m] == 0.0 and df_du[m] == 0.0 and df_dv[m] == 0.0):
            act[na] = m
            na += 1
    F = np.zeros(s)
    for a in range(na):
        m = act[a]
        for i in range(s):
            F[i] += P[i, m] * f[m]
    if D.size > 0 and na > 0:
        nc = E.shape[1]
        Pa = np.empty((s, na))
        R = np.empty((na, nc))
        for a in range(na):
            m = act[a]
            for i in range(s):
                Pa[i, a] = P[i, m]
            for j in range(nc):
                R[a, j] = df_du[m] * E[m, j] + df_dv[m] * dE[m, j]
        D[:, :] = np.dot(Pa, R)
    return F


@njit(cache=True)
def _project_batch(P, E, dE, f, df_du, df_dv, D):
    """:func:`_project` of many states: ``f``, ``df_du``, ``df_dv`` of shape (n, N), ``D``
    of shape (n, s, s), or (n, 0, 0) when not wanted. Returns ``F`` (n, s)."""
    n = f.shape[0]
    F = np.empty((n, P.shape[0]))
    for i in range(n):
        F[i] = _project(P, E, dE, f[i], df_du[i], df_dv[i], D[i])
    return F


@njit(cache=True)
def _jump_sides(u_t, v_t, idx, up, u_s, omega_b):
    """The samples followed by both sides of every jump (just after, then just before the
    crossing ``idx``), to evaluate the law at all of them at once."""
    N, nc = u_t.size, idx.size
    eps = 1e-9 * max(abs(u_s), np.abs(u_t).max(), 1e-300)
    u = np.empty(N + 2 * nc)
    v = np.empty(N + 2 * nc)
    u[:N], v[:N] = u_t, v_t
    for c in range(nc):
        after = 1.0 if u_t[(idx[c] + 1) % N] > u_s else -1.0
        u[N + c], u[N + nc + c] = u_s + after * eps, u_s - after * eps
        v[N + c] = v[N + nc + c] = omega_b * up[c]
    return u, v


@njit(cache=True)
def _locate_jumps_batch(tau, k, U, u_t, v_t, u_s, omega_b):
    """:func:`_locate_jumps` and :func:`_jump_sides` of many states: the crossings of all
    of them in one list (``start[i]:start[i + 1]`` are state ``i``'s), with the displacement
    and velocity just after (``u_hi``, ``v``) and just before (``u_lo``) each, and its
    state's base frequency (``om``)."""
    n, N = U.shape[0], tau.size
    found = []
    start = np.zeros(n + 1, np.int64)
    for i in range(n):
        found.append(_locate_jumps(tau, k, U[i], u_t[i], u_s))
        start[i + 1] = start[i] + found[i][0].size
    total = start[n]
    idx = np.empty(total, np.int64)
    t = np.empty(total)
    rows = np.empty((2, total, U.shape[1]))
    up = np.empty(total)
    upp = np.empty(total)
    u_hi = np.empty(total)
    u_lo = np.empty(total)
    vel = np.empty(total)
    om = np.empty(total)
    for i in range(n):
        a, b = start[i], start[i + 1]
        if a == b:
            continue
        idx_i, t_i, rows_i, up_i, upp_i = found[i]
        idx[a:b], t[a:b], rows[:, a:b], up[a:b], upp[a:b] = idx_i, t_i, rows_i, up_i, upp_i
        u, v = _jump_sides(u_t[i], v_t[i], idx_i, up_i, u_s, omega_b[i])
        u_hi[a:b], u_lo[a:b], vel[a:b] = u[N : N + b - a], u[N + b - a :], v[N : N + b - a]
        om[a:b] = omega_b[i]
    return start, idx, t, rows, up, upp, u_hi, u_lo, vel, om


@njit(cache=True)
def _add_jumps_batch(w, start, rows, up, upp, offset, J, dJ_dvel, dJ_dp, dus_dp, F, D, dFp):
    """:func:`_add_jumps` of many states (crossings as :func:`_locate_jumps_batch` lists
    them) into ``F`` (n, s), ``D`` (n, s, s) and ``dFp`` (n, s, p); a derivative not wanted
    has shape (n, 0, 0)."""
    for i in range(start.size - 1):
        a, b = start[i], start[i + 1]
        if a == b:
            continue
        _add_jumps(
            w,
            rows[:, a:b],
            up[a:b],
            upp[a:b],
            offset[a:b],
            J[a:b],
            dJ_dvel[a:b],
            dJ_dp[a:b],
            dus_dp,
            F[i],
            D[i],
            dFp[i],
        )


@njit(cache=True)
def _samples(EdE, tau, k, Ue, omega_b, u_s):
    """The displacement and velocity samples of one state for a compiled law, with both sides
    of every crossing of ``u_s`` appended (``u_s`` NaN: no jump), and the crossings as
    :func:`_locate_jumps` gives them."""
    N = tau.size
    uv = EdE @ Ue
    u_t, v_t = uv[:N].copy(), omega_b * uv[N:]
    if np.isnan(u_s):
        return (
            u_t,
            v_t,
            np.empty(0, np.int64),
            np.empty(0),
            np.empty((2, 0, Ue.size)),
            np.empty(0),
            np.empty(0),
        )
    idx, t, rows, up, upp = _locate_jumps(tau, k, Ue, u_t, u_s)
    if idx.size:
        u_t, v_t = _jump_sides(u_t, v_t, idx, up, u_s, omega_b)
    return u_t, v_t, idx, t, rows, up, upp


@njit(cache=True)
def _samples_to_harmonics(
    f, df_du, df_dv, P, E, dE, tau, jw, omega_b, idx, t, rows, up, upp, dus_dp, D
):
    """The law's samples (from :func:`_samples`) projected on the harmonics, with the jumps'
    integrals; ``D`` (zeroed) receives ``dF/dUe`` unless of size 0."""
    N, nc = tau.size, idx.size
    F = _project(P, E, dE, f[:N], df_du[:N], omega_b * df_dv[:N], D)
    if nc:
        hi, lo = slice(N, N + nc), slice(N + nc, N + 2 * nc)
        _add_jumps(
            jw,
            rows,
            up,
            upp,
            t - (tau[idx] + np.pi / N),
            f[hi] - f[lo],
            omega_b * (df_dv[hi] - df_dv[lo]),
            np.zeros((nc, 0)),
            dus_dp,
            F,
            D,
            np.zeros((0, 0)),
        )
    return F


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
    compiled = None if want_params else element.compiled_law()
    sw = element.switch_threshold()
    if compiled is not None:
        D = np.zeros((b.size, b.size)) if jacobian else None
        u_s, dus_dp = (np.nan, _NO_PARAMS) if sw is None else sw
        law, p = compiled
        omega_b = float(omega_b)
        u_t, v_t, idx, t, rows, up, upp = _samples(
            b.EdE, b.tau, b.k, np.ascontiguousarray(Ue, dtype=float), omega_b, float(u_s)
        )
        # the law is called from here, between two compiled halves: numba types a compiled
        # function passed as an argument anew at every call (numba issue #2952), some 10 us,
        # as long as the whole evaluation of a contact law
        f, df_du, df_dv = law(u_t, v_t, p)
        F = _samples_to_harmonics(
            f,
            df_du,
            df_dv,
            b.P,
            b.E,
            b.dE,
            b.tau,
            b.jump_weights,
            omega_b,
            idx,
            t,
            rows,
            up,
            upp,
            np.asarray(dus_dp, dtype=float),
            _NONE if D is None else D,
        )
        return F, D, None
    F, D, dFp = element_forces_batch(
        b, element, np.asarray(Ue, dtype=float)[None], np.array([omega_b]), jacobian, want_params
    )
    return F[0], None if D is None else D[0], None if dFp is None else dFp[0]


def element_forces_batch(
    b: HarmonicBasis,
    element,
    U: np.ndarray,
    omega_b: np.ndarray,
    jacobian: bool = True,
    want_params: bool = False,
):
    """:func:`element_forces` of one element at many states at once (the law evaluated on
    every state's samples and jump sides in one call, the projections as batched products):
    what a screen of many steps needs, where a loop over the steps spends its time in the
    calls.

    Parameters
    ----------
    b : HarmonicBasis
    element : NonlinearElement
    U : ndarray, shape (n, 2H+1)
        Coefficients of the element's relative displacement at each state [m].
    omega_b : ndarray, shape (n,)
        Base angular frequency of each state [rad/s].

    Returns
    -------
    F : ndarray, shape (n, 2H+1)
    D : ndarray, shape (n, 2H+1, 2H+1) or None
    dFp : ndarray, shape (n, 2H+1, n_params) or None
    """
    U = np.ascontiguousarray(U, dtype=float)
    omega_b = np.asarray(omega_b, dtype=float)
    n, N = U.shape[0], b.n_time
    uv = U @ b.EdE.T
    u_t, v_t = uv[:, :N], omega_b[:, None] * uv[:, N:]
    sw = element.switch_threshold()
    nc = 0
    if sw is not None:
        u_s, dus_dp = sw
        start, idx, t, rows, up, upp, u_hi, u_lo, vel, om = _locate_jumps_batch(
            b.tau, b.k, U, u_t, v_t, float(u_s), omega_b
        )
        nc = idx.size
    # the samples and both sides of every jump in one evaluation
    u_all = np.concatenate([u_t.ravel(), u_hi, u_lo]) if nc else u_t.ravel()
    v_all = np.concatenate([v_t.ravel(), vel, vel]) if nc else v_t.ravel()
    ev = element.evaluate(u_all, v_all, want_params)
    nN = n * N
    D = np.zeros((n, b.size, b.size)) if jacobian else None
    F = _project_batch(
        b.P,
        b.E,
        b.dE,
        ev.f[:nN].reshape(n, N),
        ev.df_du[:nN].reshape(n, N),
        omega_b[:, None] * ev.df_dv[:nN].reshape(n, N),
        np.zeros((n, 0, 0)) if D is None else D,
    )
    dFp = None
    if want_params:
        dp = ev.df_dp[:, :nN].reshape(-1, n, N)
        dFp = np.ascontiguousarray(np.einsum("sm,pnm->nsp", b.P, dp))
    if nc:
        hi, lo = slice(nN, nN + nc), slice(nN + nc, nN + 2 * nc)
        _add_jumps_batch(
            b.jump_weights,
            start,
            rows,
            up,
            upp,
            t - (b.tau[idx] + np.pi / N),  # from the cell boundary the sum assumes
            ev.f[hi] - ev.f[lo],
            om * (ev.df_dv[hi] - ev.df_dv[lo]),
            np.ascontiguousarray((ev.df_dp[:, hi] - ev.df_dp[:, lo]).T) if want_params else _NONE,
            np.asarray(dus_dp, dtype=float),
            F,
            np.zeros((n, 0, 0)) if D is None else D,
            np.zeros((n, 0, 0)) if dFp is None else dFp,
        )
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
    if problem.L.shape == (1, 1) and problem.L[0, 0] == 1.0:  # one element to ground
        # as the paper's: its own call passes fewer arrays than the problem's kernel
        Fe, De, _ = element_forces(b, problem.attachments[0].element, X[:, 0], omega_b, jacobian)
        return Fe[:, None], De
    compiled = problem.compiled_forces(X, omega_b, jacobian)
    if compiled is not None:
        return compiled
    U = X @ problem.L.T
    n, s = problem.n_nl, b.size
    m = len(problem.attachments)
    Fs = np.empty((s, m))
    Ds = np.empty((m, s * s)) if jacobian else None
    for e, att in enumerate(problem.attachments):
        Fe, De, _ = element_forces(b, att.element, U[:, e], omega_b, jacobian)
        Fs[:, e] = Fe
        if jacobian:
            Ds[e] = De.ravel()
    F = Fs @ problem.L  # sum_e outer(Fe, L[e])
    if not jacobian:
        return F, None
    # dF[k, i, l, j] = sum_e De[k, l] L[e, i] L[e, j]: one product over the elements
    dF = (Ds.T @ problem.incidence_products).reshape(s, s, n, n).transpose(0, 2, 1, 3)
    return F, dF.reshape(s * n, s * n)


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
