"""Compile the balance's numba code into numba's cache: ``python -m analysis.mhb.warmup``.

The balance's compiled parts (the AFT's samples, jumps and projections, every law of the
element library, the Newton iteration, the forces of several elements, the sorting of the
Floquet exponents) are compiled at
their first use on a machine, some 40 s, and cached beside the sources; later processes load
them in about a second. This compiles them in one go on small problems that take every path:
``make test`` runs it beside the linters, so that the test processes load the code instead
of each compiling it at the same time.
"""

from __future__ import annotations

import time

import numpy as np

from analysis.elements import make_element
from analysis.linear.receptance import DirectLinearModel
from analysis.mhb.aft import element_forces_batch, nonlinear_forces, parameter_forces
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.mhb.solver import solve_point
from analysis.mhb.stability import floquet_exponents

__all__ = ["warm_up"]

#: One element of every law of the library (the contact's and the stops' jumps included).
_ELEMENTS = (
    ("hertz_contact", {"k_c": 1e7, "gap": 2e-4, "v": 10.0}),
    ("cubic_spring", {"k3": 2e9}),
    ("coulomb_friction", {"f_slip": 0.3}),
    ("two_sided_gap", {"k": 1e4, "gap": 3e-4}),
    ("bilinear_spring", {"k_pos": 1e3, "k_neg": 2e3}),
)


def warm_up() -> float:
    """Solve and differentiate small problems with every law; returns the seconds taken."""
    t0 = time.perf_counter()
    M = np.diag([1.0, 0.5])
    K = 4e4 * np.array([[2.0, -1.0], [-1.0, 1.0]])
    lin = DirectLinearModel(M, 2e-4 * K + 0.5 * M, K)
    force = np.array([2.0, 0.04, 0.04])
    for kind, values in _ELEMENTS:
        el = make_element(kind, **values)
        params = {p: p for p in el.param_names}
        alone = HarmonicProblem(lin, [Attachment(el, 1, None, kind, params)], [0], [0, 1])
        # with a second element between the masses: the problem's compiled kernels
        pair = HarmonicProblem(
            lin,
            [Attachment(el, 1, None, kind, params), Attachment(el, 0, 1, "between")],
            [0],
            [0, 1],
        )
        for pb in (alone, pair):
            p = solve_point(pb, 150.0, force)
            nonlinear_forces(pb, p.X, 150.0, False)
            parameter_forces(pb, p.X, 150.0)
        floquet_exponents(pb, p)
        U = np.repeat(p.X[:, :1].T, 2, axis=0)
        element_forces_batch(alone.basis, el, U, np.array([150.0, 160.0]), True, True)
        element_forces_batch(alone.basis, el, U, np.array([150.0, 160.0]), False, False)
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"the balance's compiled code is in numba's cache ({warm_up():.0f} s)")
