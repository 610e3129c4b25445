"""Time integration of the coupled rig with its nonlinear elements, sample by sample.

The linear part (structure, shaker, amplifier) advances exactly per mode
(:meth:`sim_backend.statespace.ModalStateSpace.discretise`) with the DAQ output and the element
forces taken linear over a step (first-order hold). The force at the end of a step is implicit,

    f[j+1] = F(u[j+1], v[j+1]),   (u, v)[j+1] = a[j] + D f[j+1],

and solved by Newton's method on the few element forces (``D`` is the instantaneous
compliance of the elements' relative motion to their own forces over a step). The scheme is
second-order accurate in the step for smooth laws and unconditionally stable for the linear
part, however stiff its modes; a switch (contact entry) within a step costs local accuracy of
first order. ``substeps`` divide each sample for more accuracy.

A run advances one instant at a time, a million element evaluations in a stepped test that
leaves the balance. When every element has a compiled law (``compiled_law``, or a stateful
``compiled_instant_law`` such as the simulator's Jenkins element), the whole loop runs
compiled with numba; otherwise it runs in Python with the elements' numpy code. Both do the
same arithmetic in the same order (a test holds them together to rounding). The compiled loop
is compiled once per process and set of laws (a few seconds: a loop over laws handed in as
arguments cannot be cached by numba, so it is kept thin and the arithmetic it calls is cached),
which a run that integrates pays back many times.

References
----------
E. Hairer, G. Wanner, *Solving Ordinary Differential Equations II*, 2nd ed., Springer 1996,
sec. IV.7 (exponential integrators for stiff linear parts).
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass

import numpy as np
from numba import literal_unroll, njit
from numba.core.errors import NumbaExperimentalFeatureWarning

from analysis.mhb.problem import HarmonicProblem
from sim_backend.statespace import ModalStateSpace

__all__ = ["ElementSet", "TimeStepper"]

logger = logging.getLogger(__name__)

_NEWTON_ITERATIONS = 8


class ElementSet:
    """The problem's elements, grouped so that equal laws are evaluated in one call.

    Parameters
    ----------
    problem : HarmonicProblem
        Its attachments give the elements, in order of the rows of ``problem.L``.
    """

    def __init__(self, problem: HarmonicProblem) -> None:
        groups: dict[tuple, list[int]] = {}
        elements = [a.element for a in problem.attachments]
        for i, el in enumerate(elements):
            key = (type(el), tuple(el.p.tolist()), tuple(sorted(el.options.items())))
            groups.setdefault(key, []).append(i)
        self._groups = [(elements[idx[0]], np.array(idx)) for idx in groups.values()]
        self.size = len(elements)

    def evaluate(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, ...]:
        """Forces and tangents of every element, each shape (n_el,) (N, N/m, N s/m)."""
        if len(self._groups) == 1:
            ev = self._groups[0][0].evaluate(u, v)
            return ev.f, ev.df_du, ev.df_dv
        f = np.empty(self.size)
        du = np.empty(self.size)
        dv = np.empty(self.size)
        for el, idx in self._groups:
            ev = el.evaluate(u[idx], v[idx])
            f[idx], du[idx], dv[idx] = ev.f, ev.df_du, ev.df_dv
        return f, du, dv

    def compiled(self) -> tuple[tuple, tuple] | None:
        """The groups for :func:`_run_compiled`: memoryless ones as ``(law, idx, p)``
        (``law(u, v, p)``, the element's ``compiled_law``), those with memory as ``(law, idx,
        p, state)`` (``compiled_instant_law``: ``law(u, v, p, state)`` advances ``state`` in
        place); ``None`` when an element has neither."""
        memoryless, stateful = [], []
        for el, idx in self._groups:
            own = getattr(el, "compiled_instant_law", None)
            if own is not None:
                law, p, state = own(idx.size)
                stateful.append((law, idx, np.asarray(p, dtype=float), state))
                continue
            compiled = el.compiled_law()
            if compiled is None:
                return None
            memoryless.append((compiled[0], idx, np.asarray(compiled[1], dtype=float)))
        # numba cannot iterate over an empty tuple: a group of no elements stands in
        none = np.zeros(0, dtype=np.int64), np.zeros(0)
        return (
            tuple(memoryless) or ((_no_memoryless, *none),),
            tuple(stateful) or ((_no_stateful, *none, np.zeros(0)),),
        )


@njit
def _evaluate_groups(groups, u, v, f, du, dv):
    """Every group's law at the elements' motion ``u``, ``v``, into ``f``, ``du``, ``dv``."""
    memoryless, stateful = groups
    for g in literal_unroll(memoryless):
        law, idx, p = g
        _put(idx, law(_take(u, idx), _take(v, idx), p), f, du, dv)
    for g in literal_unroll(stateful):
        law, idx, p, state = g
        _put(idx, law(_take(u, idx), _take(v, idx), p, state), f, du, dv)


@njit(cache=True)
def _no_memoryless(u, v, p):
    return u.copy(), u.copy(), u.copy()


@njit(cache=True)
def _no_stateful(u, v, p, state):
    return u.copy(), u.copy(), u.copy()


@njit(cache=True)
def _take(a, idx):
    return a[idx]


@njit(cache=True)
def _put(idx, values, f, du, dv):
    f[idx], du[idx], dv[idx] = values


# The loops below take the laws as arguments, which numba cannot cache (a function's type is
# its identity in this process): they are kept thin, and the arithmetic they call is compiled
# once for all processes.


@njit(cache=True)
def _predict(E, eta, gA, gB, u0, u1, H0, Cu, Cv, f):
    """The linear step with the forces held (``pred``) and the elements' motion there."""
    pred = E * eta + gA * u0 + gB * u1 + H0 @ f.astype(np.complex128)
    return pred, (Cu @ pred).real, (Cv @ pred).real


@njit(cache=True)
def _newton_step(f, F, ku, kv, Du, Dv):
    """``(done, f)``: one Newton update of the step's forces ``f`` from the laws' ``F`` and
    tangents, or ``done`` once ``f`` is their fixed point (to ``1e-12 + 1e-10 max|F|``)."""
    r = f - F
    if np.abs(r).max() <= 1e-12 + 1e-10 * np.abs(F).max():
        return True, f
    n = f.size
    J = np.empty((n, n))
    for i in range(n):
        for k in range(n):
            J[i, k] = (1.0 if i == k else 0.0) - ku[i] * Du[i, k] - kv[i] * Dv[i, k]
    return False, f - np.linalg.solve(J, r)


@njit(cache=True)
def _store(out, j, row):
    out[j] = row


@njit(cache=True)
def _hold(u, j, frac):
    """The input at the substeps of sample ``j`` (first-order hold)."""
    return u[j] + (u[j + 1] - u[j]) * frac


@njit(cache=True)
def _at(a, D, f):
    """``a + D f``: the elements' motion with the forces ``f``."""
    return a + D @ f


@njit(cache=True)
def _advance(pred, H1, f):
    return pred + H1 @ f.astype(np.complex128)


@njit
def _run_compiled(groups, E, gA, gB, H0, H1, Cu, Cv, Du, Dv, frac, u, eta0, f0):
    """:meth:`TimeStepper.run`'s loop and :meth:`TimeStepper._solve_force`, compiled:
    ``(eta_out, f_out)``."""
    n, m = u.size - 1, f0.size
    eta_out = np.empty((n, E.size), dtype=np.complex128)
    f_out = np.empty((n, m))
    F, ku, kv = np.empty(m), np.empty(m), np.empty(m)
    eta = eta0.copy()
    f = f0.copy()
    for j in range(n):
        us = _hold(u, j, frac)
        for s in range(frac.size - 1):
            pred, au, av = _predict(E, eta, gA, gB, us[s], us[s + 1], H0, Cu, Cv, f)
            for _ in range(_NEWTON_ITERATIONS):
                _evaluate_groups(groups, _at(au, Du, f), _at(av, Dv, f), F, ku, kv)
                done, f = _newton_step(f, F, ku, kv, Du, Dv)
                if done:
                    break
            f = F.copy()
            eta = _advance(pred, H1, f)
        _store(eta_out, j, eta)
        _store(f_out, j, f)
    return eta_out, f_out


@dataclass
class StepResult:
    """States at the sample instants of one run.

    Attributes
    ----------
    eta : ndarray, shape (n, p), complex
        Modal state at samples ``1..n`` of the run (after each sample step).
    forces : ndarray, shape (n, n_el), N
        Element forces at the same instants.
    """

    eta: np.ndarray
    forces: np.ndarray


class TimeStepper:
    """Sample-by-sample integrator of the coupled rig.

    Parameters
    ----------
    space : ModalStateSpace
    problem : HarmonicProblem
        Elements and their incidence ``L`` on ``problem.nl_dofs`` (the columns of
        ``space.hn``).
    sample_rate_hz : float
    substeps : int
        Integration steps per sample.
    compiled : bool
        Run compiled when every element has a compiled law (default); False: always the
        Python loop (the reference the compiled one is tested against).
    """

    def __init__(
        self,
        space: ModalStateSpace,
        problem: HarmonicProblem,
        sample_rate_hz: float,
        substeps: int = 1,
        compiled: bool = True,
    ) -> None:
        if substeps < 1:
            raise ValueError(f"substeps: must be >= 1, got {substeps}")
        self.space = space
        self.substeps = int(substeps)
        self.compiled = bool(compiled)
        self.elements = ElementSet(problem)
        L = problem.L  # (n_el, n_nl)
        disc = space.discretise(1.0 / (sample_rate_hz * substeps))
        self.E, self.gA, self.gB = disc.E, disc.gA, disc.gB
        self.H0 = disc.H0 @ L.T  # (p, n_el)
        self.H1 = disc.H1 @ L.T
        rows_u = L @ space.displacement_rows(problem.nl_dofs)
        rows_v = L @ space.velocity_rows(problem.nl_dofs)
        self.Cu = space.modal(rows_u)  # (n_el, p)
        self.Cv = space.modal(rows_v)
        self.Du = (self.Cu @ self.H1).real
        self.Dv = (self.Cv @ self.H1).real

    def forces_at(self, eta: np.ndarray) -> np.ndarray:
        """Element forces (n_el,) in the state ``eta`` (p,)."""
        if not self.elements.size:
            return np.zeros(0)
        return self.elements.evaluate((self.Cu @ eta).real, (self.Cv @ eta).real)[0]

    def _solve_force(self, au: np.ndarray, av: np.ndarray, f: np.ndarray) -> np.ndarray:
        Du, Dv, els = self.Du, self.Dv, self.elements
        for _ in range(_NEWTON_ITERATIONS):
            F, ku, kv = els.evaluate(au + Du @ f, av + Dv @ f)
            done, f = _newton_step(f, F, ku, kv, Du, Dv)
            if done:
                break
        return F

    def run(self, eta0: np.ndarray, f0: np.ndarray, u: np.ndarray) -> StepResult:
        """Advance over the held inputs ``u``.

        Parameters
        ----------
        eta0 : ndarray, shape (p,), complex
            Modal state at the first sample.
        f0 : ndarray, shape (n_el,), N
            Element forces at the first sample.
        u : ndarray, shape (n + 1,), V
            Amplifier gain times DAQ output at the first sample and the ``n`` following ones
            (linear in between).

        Returns
        -------
        StepResult
        """
        n = u.size - 1
        p = self.E.size
        S = self.substeps
        frac = np.arange(S + 1) / S
        groups = self.elements.compiled() if self.compiled and self.elements.size else None
        if groups is not None:
            with warnings.catch_warnings():
                # numba's first-class functions (the laws handed to the loop) are "experimental"
                warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
                eta_out, f_out = _run_compiled(
                    groups,
                    self.E,
                    self.gA,
                    self.gB,
                    np.ascontiguousarray(self.H0),
                    np.ascontiguousarray(self.H1),
                    np.ascontiguousarray(self.Cu),
                    np.ascontiguousarray(self.Cv),
                    np.ascontiguousarray(self.Du),
                    np.ascontiguousarray(self.Dv),
                    frac,
                    np.asarray(u, dtype=float),
                    np.array(eta0, dtype=complex),
                    np.array(f0, dtype=float),
                )
            return StepResult(eta_out, f_out)
        eta_out = np.empty((n, p), dtype=complex)
        f_out = np.empty((n, self.elements.size))
        E, gA, gB, H0, H1, Cu, Cv = self.E, self.gA, self.gB, self.H0, self.H1, self.Cu, self.Cv
        eta = np.array(eta0, dtype=complex)
        f = np.array(f0, dtype=float)
        nonlinear = self.elements.size > 0
        for j in range(n):
            us = u[j] + (u[j + 1] - u[j]) * frac
            for s in range(S):
                if nonlinear:
                    pred = E * eta + gA * us[s] + gB * us[s + 1] + H0 @ f
                    f = self._solve_force((Cu @ pred).real, (Cv @ pred).real, f)
                    eta = pred + H1 @ f
                else:
                    eta = E * eta + gA * us[s] + gB * us[s + 1]
            eta_out[j] = eta
            f_out[j] = f
        return StepResult(eta_out, f_out)
