"""Receptances: modal superposition with residual flexibility against the direct solve."""

import numpy as np
import pytest

from analysis.linear.receptance import DirectLinearModel, ModalLinearModel
from analysis.linear.reduced import reduced_model


def _system(n=12, seed=0):
    rng = np.random.default_rng(seed)
    K = np.diag(2 * np.ones(n)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1)
    K = 1e4 * K + np.diag(rng.random(n) * 1e3)
    M = np.diag(0.1 + 0.05 * rng.random(n))
    dK = {"kg": np.diag(np.r_[1.0, np.zeros(n - 1)]), "ks": np.diag(rng.random(n))}
    dM = {"m3": np.diag(np.eye(n)[3])}
    return M, K, dM, dK


def _modal_C(M, modes, zeta):
    ph = modes.phi
    return M @ ph @ np.diag(2 * zeta * modes.omega) @ ph.T @ M


def test_all_modes_equal_the_direct_solve():
    M, K, dM, dK = _system()
    lm = ModalLinearModel(M, K, 0.02, f_max_hz=1e9)
    d = DirectLinearModel(M, _modal_C(M, lm.all_modes, 0.02), K)
    w = np.array([0.0, 30.0, 200.0, 500.0])
    rows, cols = [0, 4, 7], [4, 11]
    ref = d.block(rows, cols)(w)
    assert np.abs(lm.block(rows, cols)(w) - ref).max() <= 1e-10 * np.abs(ref).max()


def test_residual_flexibility_makes_truncated_static_response_exact():
    M, K, dM, dK = _system()
    lm = ModalLinearModel(M, K, 0.02, f_max_hz=10.0)
    assert 0 < len(lm.modes) < M.shape[0]
    H0 = lm.block([0, 5], [5, 9])(np.array([0.0]))[0]
    assert np.allclose(H0, np.linalg.inv(K)[np.ix_([0, 5], [5, 9])], rtol=1e-12, atol=0)


def test_truncation_error_is_small_below_the_retained_band():
    M, K, dM, dK = _system()
    lm = ModalLinearModel(M, K, 0.02, f_max_hz=40.0)
    d = DirectLinearModel(M, _modal_C(M, lm.all_modes, 0.02), K)
    w = 2 * np.pi * np.array([5.0, 10.0])  # well below the first truncated mode
    ref = d.block([0, 5], [5])(w)
    err = np.abs(lm.block([0, 5], [5])(w) - ref).max() / np.abs(ref).max()
    assert err < 1e-2


@pytest.mark.parametrize("f_max", [1e9, 25.0])
def test_receptance_derivatives_match_finite_differences(f_max):
    M, K, dM, dK = _system()
    n_keep = len(ModalLinearModel(M, K, 0.02, f_max_hz=f_max).modes)
    dK_all = {**dK, "m3": 0 * K}
    lm = ModalLinearModel(M, K, 0.02, f_max_hz=f_max, dM=dM, dK=dK_all)
    blk = lm.block([0, 5], [5, 9])
    w = np.array([0.0, 40.0, 130.0])
    for p, h in (("kg", 1.0), ("ks", 1.0), ("m3", 1e-5)):  # steps ~1e-4 of the entries
        dKp, dMp = dK_all[p], dM.get(p, 0 * M)

        def H(s):
            m = ModalLinearModel(M + s * dMp, K + s * dKp, 0.02, f_max_hz=1e9)
            m.keep = m.keep[:n_keep]
            from analysis.linear.modal import Modes

            m.modes = Modes(
                m.all_modes.omega[:n_keep], m.all_modes.phi[:, :n_keep], m.all_modes.zeta[:n_keep]
            )
            return m.block([0, 5], [5, 9])(w)

        fd = (H(h) - H(-h)) / (2 * h)
        an = blk.derivative(w, p)
        assert np.abs(an - fd).max() <= 1e-5 * np.abs(fd).max(), p


def test_direct_model_derivative_matches_finite_differences():
    M, K, dM, dK = _system(6)
    C = 1e-3 * K
    d = DirectLinearModel(M, C, K, dK={"ks": dK["ks"]}, dC={"ks": 1e-3 * dK["ks"]})
    w = np.array([10.0, 100.0])
    h = 1e-4
    fd = DirectLinearModel(M, C + h * 1e-3 * dK["ks"], K + h * dK["ks"]).block([0], [3])(
        w
    ) - DirectLinearModel(M, C - h * 1e-3 * dK["ks"], K - h * dK["ks"]).block([0], [3])(w)
    fd /= 2 * h
    assert np.allclose(d.block([0], [3]).derivative(w, "ks"), fd, rtol=1e-6, atol=0)


def test_augmented_reduced_model_keeps_static_flexibility_at_loaded_dofs():
    M, K, dM, dK = _system()
    lm = ModalLinearModel(M, K, 0.02, f_max_hz=10.0)
    red = reduced_model(lm, [3, 8])
    H0 = red.block([0, 3, 8], [3, 8])(np.array([0.0]))[0].real
    assert np.allclose(H0, np.linalg.inv(K)[np.ix_([0, 3, 8], [3, 8])], rtol=1e-10, atol=0)
    assert red.size == len(lm.modes) + 2


def _blocks_of_every_kind():
    """A receptance block of each linear model the balance meets: modal (retained modes and
    residual flexibility), direct, modal behind a static support, and a reduced model's
    (which has no frequency derivative of its own and is differenced)."""
    from analysis.linear.static_support import StaticSupport

    M, K, dM, dK = _system()
    lm = ModalLinearModel(M, K, 0.02, f_max_hz=25.0)
    d = DirectLinearModel(M, _modal_C(M, lm.all_modes, 0.02) + 1e-4 * K, K)
    rows, cols = [0, 5], [5, 9]
    return {
        "modal": lm.block(rows, cols),
        "direct": d.block(rows, cols),
        "static support": StaticSupport(lm, 5, 2e3).block(rows, cols),
        "reduced": reduced_model(lm, [5, 9]).block([0, 5], [5, 9]),
    }


@pytest.mark.parametrize("kind", ["modal", "direct", "static support", "reduced"])
def test_frequency_derivatives_match_central_differences(kind):
    """``dH/domega`` of every kind of block against central differences of the block at two
    step sizes (their Richardson extrapolation, error O(h^4)), to 1e-7 of the largest, near
    and between the resonances."""
    from analysis.linear.receptance import frequency_derivative

    blk = _blocks_of_every_kind()[kind]
    w = np.array([3.0, 40.0, 130.0, 260.0])
    exact = frequency_derivative(blk, w)
    h = 1e-4 * w
    fd1 = (blk(w + h) - blk(w - h)) / (2 * h)[:, None, None]
    fd2 = (blk(w + 2 * h) - blk(w - 2 * h)) / (4 * h)[:, None, None]
    fd = (4 * fd1 - fd2) / 3
    assert np.abs(exact - fd).max() <= 1e-7 * np.abs(fd).max()


def test_damping_ratio_derivatives_match_central_differences():
    """``dH/dzeta_r`` of a retained mode (``zeta_2``) against Richardson-extrapolated central
    differences of the block at shifted ratios, to 1e-8 of the largest, at rest, near and
    between the resonances, also through the static support; a truncated mode's ratio
    (``zeta_12``) enters nowhere (derivative 0); the structural parameters' derivatives are
    unchanged by naming ratios too."""
    from analysis.linear.static_support import StaticSupport

    M, K, dM, dK = _system()
    f_max = 25.0
    plain = ModalLinearModel(M, K, {2: 0.03}, f_max_hz=f_max, dM=dM, dK={**dK, "m3": 0 * K})
    n_keep = len(plain.modes)
    assert 2 <= n_keep < 12
    lm = ModalLinearModel(
        M, K, {2: 0.03}, f_max_hz=f_max, dM=dM, dK={**dK, "m3": 0 * K}, damping_modes=(2, 12)
    )
    assert lm.param_names == (*plain.param_names, "zeta_2", "zeta_12")
    w = np.array([0.0, 3.0, *plain.modes.omega[:2], 130.0])
    rows, cols = [0, 5], [5, 9]
    for wrap in (lambda m: m, lambda m: StaticSupport(m, 5, 2e3)):
        blk = wrap(lm).block(rows, cols)

        def H(z, wrap=wrap):
            return wrap(ModalLinearModel(M, K, {2: z}, f_max_hz=f_max)).block(rows, cols)(w)

        h = 1e-4 * 0.03
        fd1 = (H(0.03 + h) - H(0.03 - h)) / (2 * h)
        fd2 = (H(0.03 + 2 * h) - H(0.03 - 2 * h)) / (4 * h)
        fd = (4 * fd1 - fd2) / 3
        exact = blk.derivative(w, "zeta_2")
        assert np.abs(exact - fd).max() <= 1e-8 * np.abs(fd).max()
        assert np.all(exact[0] == 0)  # at rest the damping does nothing
        assert np.all(blk.derivative(w, "zeta_12") == 0)
        ref = wrap(plain).block(rows, cols)
        for p in plain.param_names:
            assert np.array_equal(blk.derivative(w, p), ref.derivative(w, p))


def test_mode_shape_derivatives_by_expansion_equal_nelsons_and_central_differences():
    """The expansion over every mode (used when all modes are at hand) and Nelson's method
    (one bordered solve per mode) give the same eigenvalue and shape derivatives: to 1e-12
    and 1e-9 of the largest on a 12-DOF chain, 1e-10 and 1e-6 on the rig's 168-DOF model
    (its rotations and translations differ by orders of magnitude); and both match central
    differences of the modes (Richardson-extrapolated, steps 1e-4 of the entries) to 1e-6."""
    from analysis.linear.modal import _nelson, modal_analysis, mode_sensitivities
    from analysis.model import load_model

    M, K, dM, dK = _system()
    dK = {**dK, "m3": 0 * K}
    modes = modal_analysis(M, K)
    which = np.array([0, 2, 5])
    exp = mode_sensitivities(M, K, modes, dM, dK, which=which)
    nel = _nelson(M, K, modes, dM, dK, which)
    for p, h in (("kg", 1.0), ("ks", 1.0), ("m3", 1e-5)):
        assert np.abs(exp[0][p] - nel[0][p]).max() <= 1e-12 * np.abs(nel[0][p]).max(), p
        assert np.abs(exp[1][p] - nel[1][p]).max() <= 1e-9 * np.abs(nel[1][p]).max(), p

        def shapes(s):
            phi = modal_analysis(M + s * h * dM.get(p, 0 * M), K + s * h * dK[p]).phi[:, which]
            return phi * np.sign(np.sum(phi * modes.phi[:, which], axis=0))

        fd1 = (shapes(1) - shapes(-1)) / (2 * h)
        fd2 = (shapes(2) - shapes(-2)) / (4 * h)
        fd = (4 * fd1 - fd2) / 3
        assert np.abs(exp[1][p] - fd).max() <= 1e-6 * np.abs(fd).max(), p

    asm = load_model().assemble()
    names = ("E_beam", "E_frame", "k_mount", "rho_corner")
    rig = ModalLinearModel(asm.M, asm.K, 0.01)
    dM = {n: asm.dM[n] for n in names}
    dK = {n: asm.dK[n] for n in names}
    exp = mode_sensitivities(asm.M, asm.K, rig.all_modes, dM, dK, which=rig.keep)
    nel = _nelson(asm.M, asm.K, rig.all_modes, dM, dK, rig.keep)
    for p in names:
        assert np.abs(exp[0][p] - nel[0][p]).max() <= 1e-10 * np.abs(nel[0][p]).max(), p
        assert np.abs(exp[1][p] - nel[1][p]).max() <= 1e-6 * np.abs(nel[1][p]).max(), p
