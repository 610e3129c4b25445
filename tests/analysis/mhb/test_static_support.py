"""The static support (the shaker holding the drive point at its mean) against direct solves."""

import numpy as np
import pytest

from analysis.linear.receptance import DirectLinearModel
from analysis.linear.static_support import StaticSupport
from tests.analysis.mhb.test_receptance import _system


def _direct(M, K, C, dM=None, dK=None):
    return DirectLinearModel(M, C, K, dM=dM, dK=dK)


def test_static_receptance_is_that_of_the_supported_structure_and_dynamics_are_unchanged():
    M, K, dM, dK = _system()
    C = 1e-3 * K
    d, k = 4, 3e3
    free = _direct(M, K, C)
    supported = StaticSupport(free, d, k)
    Ks = K.copy()
    Ks[d, d] += k
    rows, cols = [0, 4, 7], [4, 11]
    w = np.array([0.0, 30.0, 200.0])
    H = supported.block(rows, cols)(w)
    # at omega = 0 the spring is there (relative 1e-12)
    ref0 = np.linalg.inv(Ks)[np.ix_(rows, cols)]
    assert np.abs(H[0] - ref0).max() <= 1e-12 * np.abs(ref0).max()
    # at every other frequency the measured force already carries the shaker: unchanged
    ref = free.block(rows, cols)(w[1:])
    assert np.array_equal(H[1:], ref)


def test_static_support_derivatives_match_finite_differences():
    M, K, dM, dK = _system()
    C = np.zeros_like(K)
    dK_all = {**dK, "m3": 0 * K}
    d, k = 5, 2e3
    blk = StaticSupport(_direct(M, K, C, dM=dM, dK=dK_all), d, k).block([0, 5], [5, 9])
    w = np.array([0.0, 40.0])
    for p, h in (("kg", 1.0), ("ks", 1.0)):

        def H(s, p=p):
            return StaticSupport(_direct(M, K + s * dK_all[p], C), d, k).block([0, 5], [5, 9])(w)

        fd = (H(h) - H(-h)) / (2 * h)
        an = blk.derivative(w, p)
        assert np.abs(an - fd).max() <= 1e-6 * np.abs(fd).max(), p


def test_negative_stiffness_is_refused():
    M, K, _, _ = _system()
    with pytest.raises(ValueError, match="stiffness"):
        StaticSupport(_direct(M, K, 0 * K), 0, -1.0)
