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

References
----------
E. Hairer, G. Wanner, *Solving Ordinary Differential Equations II*, 2nd ed., Springer 1996,
sec. IV.7 (exponential integrators for stiff linear parts).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

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
    """

    def __init__(
        self,
        space: ModalStateSpace,
        problem: HarmonicProblem,
        sample_rate_hz: float,
        substeps: int = 1,
    ) -> None:
        if substeps < 1:
            raise ValueError(f"substeps: must be >= 1, got {substeps}")
        self.space = space
        self.substeps = int(substeps)
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
        self._eye = np.eye(self.elements.size)

    def forces_at(self, eta: np.ndarray) -> np.ndarray:
        """Element forces (n_el,) in the state ``eta`` (p,)."""
        if not self.elements.size:
            return np.zeros(0)
        return self.elements.evaluate((self.Cu @ eta).real, (self.Cv @ eta).real)[0]

    def _solve_force(self, au: np.ndarray, av: np.ndarray, f: np.ndarray) -> np.ndarray:
        Du, Dv, els = self.Du, self.Dv, self.elements
        for _ in range(_NEWTON_ITERATIONS):
            F, ku, kv = els.evaluate(au + Du @ f, av + Dv @ f)
            r = f - F
            scale = 1e-12 + 1e-10 * np.abs(F).max()
            if np.abs(r).max() <= scale:
                return F
            J = self._eye - ku[:, None] * Du - kv[:, None] * Dv
            f = f - np.linalg.solve(J, r)
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
