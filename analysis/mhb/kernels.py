"""The balance's Newton iteration compiled whole, for problems whose laws are the library's.

A point of a stepped test takes two or three Newton iterations on a few dozen unknowns: in
Python each iteration is some twenty calls (the AFT of every element, the Jacobian's assembly,
the solve, the line search's trials), and the calls cost more than their arithmetic. Here the
forces of every element (:func:`problem_forces`) and the damped Newton iteration of
:func:`analysis.mhb.solver.solve_point` (:func:`newton`) are one compiled call each, with the
same steps in the same order: the same samples, law, projection and jump integrals as
:mod:`analysis.mhb.aft`, the same tolerance, stall test and backtracking line search.

The elements travel as arrays (:class:`ElementArrays`): each law by its code in
:data:`analysis.elements.compiled.LAWS` and its settings, the threshold where it jumps (NaN:
none) and the incidence matrix. A problem with a law outside the library has none, and the
balance takes its Python path.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from analysis.elements.compiled import LAW_MODULES, evaluate_law, law_code, stamped
from analysis.mhb.aft import _samples, _samples_to_harmonics

__all__ = ["ElementArrays", "MESSAGES", "element_arrays", "newton", "problem_forces"]

#: :func:`newton`'s outcome codes, in the words of :func:`analysis.mhb.solver.solve_point`.
MESSAGES = (
    "converged",
    "maximum iterations reached",
    "non-finite residual",
    "stalled (residual not halved in {window} iterations)",
    "singular Jacobian",
    "line search failed (no descent)",
)


@dataclass(frozen=True)
class ElementArrays:
    """A problem's elements for the compiled kernels.

    Attributes
    ----------
    codes : ndarray of int, shape (m,)
        Each element's law (:func:`analysis.elements.compiled.law_code`).
    params : ndarray, shape (m, p_max)
        Each law's settings (``compiled_law``'s ``p``), padded with zeros.
    n_params : ndarray of int, shape (m,)
        Length of each row's settings.
    thresholds : ndarray, shape (m,)
        Displacement where each law's force jumps, NaN where it does not.
    L : ndarray, shape (m, n_nl)
        Incidence: element ``e``'s relative displacement is ``L[e] @ q_nl``.
    """

    codes: np.ndarray
    params: np.ndarray
    n_params: np.ndarray
    thresholds: np.ndarray
    L: np.ndarray


def element_arrays(problem) -> ElementArrays | None:
    """The elements of ``problem`` as arrays, or None when one has no law of the library."""
    codes, laws, thresholds = [], [], []
    for att in problem.attachments:
        compiled = att.element.compiled_law()
        code = None if compiled is None else law_code(compiled[0])
        if code is None:
            return None
        codes.append(code)
        laws.append(np.asarray(compiled[1], dtype=float))
        sw = att.element.switch_threshold()
        thresholds.append(np.nan if sw is None else float(sw[0]))
    params = np.zeros((len(laws), max((p.size for p in laws), default=0)))
    for e, p in enumerate(laws):
        params[e, : p.size] = p
    return ElementArrays(
        np.array(codes, dtype=np.int64),
        params,
        np.array([p.size for p in laws], dtype=np.int64),
        np.array(thresholds, dtype=float),
        np.ascontiguousarray(problem.L, dtype=float),
    )


#: the digest of the sources the kernels call into (see :func:`stamped`); the kernels call
#: each other by their module-level names: a function held in a closure would enter numba's
#: cache key, and it pickles differently in every process
_stamped = stamped(("analysis.mhb.aft", "analysis.elements.compiled", *LAW_MODULES))


@_stamped
def _element_terms(stamp: int):
    no_params = np.zeros(0)

    @njit(cache=True)
    def element_terms(X, omega_b, codes, params, n_params, thresholds, L, basis, jacobian):
        """``F`` (s, n) on the nonlinear DOFs and each element's ``dFe/dUe`` (m, s, s), or
        (m, 0, 0) unless ``jacobian``."""
        stamp  # noqa: B018 - the laws' and the AFT's sources in numba's cache key
        EdE, tau, k, P, E, dE, jw = basis
        s, n = X.shape
        m = codes.size
        F = np.zeros((s, n))
        De = np.zeros((m, s, s)) if jacobian else np.zeros((m, 0, 0))
        Ue = np.empty(s)
        for e in range(m):
            for i in range(s):
                acc = 0.0
                for j in range(n):
                    acc += X[i, j] * L[e, j]
                Ue[i] = acc
            u_t, v_t, idx, t, rows, up, upp = _samples(EdE, tau, k, Ue, omega_b, thresholds[e])
            p = np.ascontiguousarray(params[e, : n_params[e]])
            f, df_du, df_dv = evaluate_law(codes[e], u_t, v_t, p)
            Fe = _samples_to_harmonics(
                f, df_du, df_dv, P, E, dE, tau, jw, omega_b, idx, t, rows, up, upp, no_params, De[e]
            )
            for i in range(n):
                if L[e, i] != 0.0:
                    for a in range(s):
                        F[a, i] += Fe[a] * L[e, i]
        return F, De

    return element_terms


@_stamped
def _assemble(stamp: int):
    @njit(cache=True)
    def assemble(De, L):
        """``dF`` ((s n), (s n)) on the nonlinear DOFs from the elements' ``De``, as
        :func:`analysis.mhb.aft.nonlinear_forces` assembles it."""
        stamp  # noqa: B018
        m, s, n = De.shape[0], De.shape[1], L.shape[1]
        dF = np.zeros((s * n, s * n))
        for e in range(m):
            for i in range(n):
                for j in range(n):
                    w = L[e, i] * L[e, j]
                    if w != 0.0:
                        for a in range(s):
                            for b in range(s):
                                dF[a * n + i, b * n + j] += De[e, a, b] * w
        return dF

    return assemble


@_stamped
def problem_forces(stamp: int):
    @njit(cache=True)
    def forces(X, omega_b, codes, params, n_params, thresholds, L, basis, jacobian):
        """``F`` (s, n) and ``dF`` ((s n), (s n)) (size 0 unless ``jacobian``)."""
        stamp  # noqa: B018
        F, De = _element_terms(X, omega_b, codes, params, n_params, thresholds, L, basis, jacobian)
        return F, _assemble(De, L) if jacobian else np.zeros((0, 0))

    return forces


@_stamped
def newton(stamp: int):
    @njit(cache=True)
    def newton(X0, G, X_lin, omega_b, codes, params, n_params, thresholds, L, basis, settings):
        """Damped Newton from ``X0``: ``X, R, F, dF``, the outcome (:data:`MESSAGES`), the
        iterations and the residual's largest coefficient, as ``solve_point`` computes them.
        ``settings`` = (rtol, atol, max_iterations, stall_window, max_halvings).

        Written in loops but for the Jacobian's product and the solve: numba compiles each
        numpy function it meets, and this kernel is compiled on a machine's first run."""
        stamp  # noqa: B018
        rtol, atol = settings[0], settings[1]
        max_it, window, halvings = int(settings[2]), int(settings[3]), int(settings[4])
        s, n = X_lin.shape
        size = s * n
        g, x_lin = G.ravel(), X_lin.ravel()  # coefficient-major, as G acts on them
        jacobian = size > 0  # a boolean, not the literal True: one signature of the forces
        scale = max(_max_abs(x_lin), 1e-300)
        X = X0.copy().reshape(size)
        F, De = _element_terms(
            X.reshape(s, n), omega_b, codes, params, n_params, thresholds, L, basis, jacobian
        )
        R = _balance(X, g, F.ravel(), x_lin)
        rn = _max_abs(R)
        outcome, it, done = 1, 0, False
        history = np.empty(max_it + 1)
        for it in range(1, max_it + 1):
            if not np.isfinite(rn):
                outcome, done = 2, True
                break
            history[it - 1] = rn
            if it > window and rn > 0.5 * history[it - 1 - window]:
                outcome, done = 3, True
                break
            if rn <= rtol * max(_max_abs(X), scale) + atol:
                outcome, it, done = 0, it - 1, True
                break
            J = G @ _assemble(De, L)
            for a in range(size):
                for b in range(size):
                    J[a, b] = (1.0 if a == b else 0.0) - J[a, b]
            try:
                dX = np.linalg.solve(J, -R)
            except Exception:  # noqa: BLE001 - numba raises LinAlgError as Exception
                outcome, done = 4, True
                break
            # backtracking on |R| along the step; every trial with its Jacobian (it costs a
            # fraction of the forces, less than evaluating the trial taken a second time)
            alpha, r2, accepted = 1.0, _norm(R), False
            Xt = np.empty(size)
            for _ in range(halvings + 1):
                for a in range(size):
                    Xt[a] = X[a] + alpha * dX[a]
                Ft, Det = _element_terms(
                    Xt.reshape(s, n),
                    omega_b,
                    codes,
                    params,
                    n_params,
                    thresholds,
                    L,
                    basis,
                    jacobian,
                )
                Rt = _balance(Xt, g, Ft.ravel(), x_lin)
                rt2 = _norm(Rt)
                if np.isfinite(rt2) and rt2 < (1 - 1e-4 * alpha) * r2:
                    accepted = True
                    break
                alpha *= 0.5
            if not accepted and not (np.isfinite(rt2) and rt2 < r2):
                outcome, done = 5, True
                break
            X, R, F, De = Xt, Rt, Ft, Det
            rn = _max_abs(R)
        if not done and rn <= rtol * max(_max_abs(X), scale) + atol:
            outcome = 0
        return X.reshape(s, n), R.reshape(s, n), F, _assemble(De, L), outcome, it, rn

    return newton


# the small helpers below call nothing: numba's own key (their file) keeps them current


@njit(cache=True)
def _balance(x, g, f, x_lin):
    """``R = x - G f - x_lin`` on flat coefficients (``g`` is ``G`` row by row)."""
    size = x.size
    R = np.empty(size)
    for a in range(size):
        acc = 0.0
        for b in range(size):
            acc += g[a * size + b] * f[b]
        R[a] = x[a] - acc - x_lin[a]
    return R


@njit(cache=True)
def _max_abs(x):
    """``max |x|`` of a flat array, NaN if one is NaN (as numpy's)."""
    m = 0.0
    for v in x:
        a = abs(v)
        if a > m:
            m = a
        elif a != a:
            return a
    return m


@njit(cache=True)
def _norm(x):
    """The 2-norm of a flat array."""
    acc = 0.0
    for v in x:
        acc += v * v
    return np.sqrt(acc)
