"""Small standard systems for the balance tests (Duffing oscillator, 2-DOF contact chain)."""

from __future__ import annotations

import numpy as np

from analysis.elements import make_element
from analysis.linear.receptance import DirectLinearModel
from analysis.mhb.problem import Attachment, HarmonicProblem


def duffing(k3=0.5, c=0.05, orders=(1,), n_harmonics=5, n_time=64) -> HarmonicProblem:
    """m x'' + c x' + k x + k3 x^3 = f (m = k = 1)."""
    lin = DirectLinearModel([[1.0]], [[c]], [[1.0]])
    att = Attachment(make_element("cubic_spring", k3=k3), 0, None, "cubic", {"k3": "k3"})
    return HarmonicProblem(
        lin, [att], [0], [0], orders=orders, n_harmonics=n_harmonics, n_time=n_time
    )


def contact_chain(gap=1e-3, k_c=2e6, v=5.0, n_harmonics=12, n_time=512) -> HarmonicProblem:
    """Two masses in a chain to ground, a unilateral Hertzian stop under mass 2, force on 1."""
    m1, m2, k1, k2 = 1.0, 0.5, 4e4, 2e4
    M = np.diag([m1, m2])
    K = np.array([[k1 + k2, -k2], [-k2, k2]])
    C = 2e-4 * K + 0.5 * M
    dK = {"k1": np.array([[1.0, 0], [0, 0]]), "k2": np.array([[1.0, -1], [-1, 1]])}
    lin = DirectLinearModel(M, C, K, dK=dK, dC={"k1": 2e-4 * dK["k1"], "k2": 2e-4 * dK["k2"]})
    el = make_element("hertz_contact", k_c=k_c, gap=gap, v=v)
    att = Attachment(el, 1, None, "stop", {"k_c": "k_c", "gap": "gap", "v": "v"})
    return HarmonicProblem(
        lin, [att], [0], [0, 1], orders=(1, 2, 3), n_harmonics=n_harmonics, n_time=n_time
    )
