"""The AFT forces of a law with a force jump (the paper's contact damping), against references.

References: the same law sampled 2**18 times per period (the plain sum's error ~1/N is then
negligible), central finite differences of the forces, and the plain sampled sum's behaviour.
"""

from __future__ import annotations

import numpy as np
import pytest

from analysis.elements import make_element
from analysis.mhb.aft import element_forces
from analysis.mhb.harmonics import HarmonicBasis
from tests.analysis.test_elements import EXAMPLE_IDS, EXAMPLES

OMEGA_B = 2 * np.pi * 30.0


def _motion() -> np.ndarray:
    """Relative displacement coefficients (9 harmonics) that enter a 0.5 mm stop twice."""
    Ue = np.zeros(19)
    Ue[[0, 1, 2, 3, 6]] = 1e-4, 1e-3, 3e-4, 1e-4, -5e-5
    return Ue


def _plain(b: HarmonicBasis, el, Ue: np.ndarray) -> np.ndarray:
    """The sampled sum alone: the jumps land on whole samples."""
    uv = b.EdE @ Ue
    return b.P @ el.force(uv[: b.n_time], OMEGA_B * uv[b.n_time :])


# the damping term dominates: the force jumps by v vel^2 at entry and exit
JUMPY = {"k_c": 1e6, "gap": 0.5e-3, "v": 1e4}


@pytest.mark.parametrize("side", [-1, 1])
def test_jump_integrals_converge_at_second_order_where_the_plain_sum_is_first_order(side):
    el = make_element("hertz_contact", side=side, **JUMPY)
    Ue = _motion() * (1 if side == -1 else -1)
    fine = HarmonicBasis(9, 2**18)
    ref = _plain(fine, el, Ue)
    errors, plain_errors = [], []
    for n in (128, 256, 512):
        b = HarmonicBasis(9, n)
        errors.append(np.abs(element_forces(b, el, Ue, OMEGA_B, False)[0] - ref).max())
        plain_errors.append(np.abs(_plain(b, el, Ue) - ref).max())
    scale = np.abs(ref).max()
    # measured: 2.4e-3, 5.8e-4, 1.6e-4 of the largest harmonic (x ~4 per doubling);
    # the plain sum 5.7e-2, 2.6e-2, 1.2e-2 (x 2)
    assert errors[0] < 5e-3 * scale
    assert errors[0] / errors[2] > 10
    assert plain_errors[0] / plain_errors[2] < 6
    assert all(e < p / 10 for e, p in zip(errors, plain_errors, strict=True))


def test_forces_are_continuous_as_samples_cross_the_threshold():
    """Shifting the mean by 20 um over 2000 steps moves the crossings across samples."""
    el = make_element("hertz_contact", **JUMPY)
    b = HarmonicBasis(9, 128)
    shifts = np.linspace(0.0, 2e-5, 2001)
    moved = [_motion() + x * np.eye(19)[0] for x in shifts]
    F = np.array([element_forces(b, el, Ue, OMEGA_B, False)[0] for Ue in moved])
    P = np.array([_plain(b, el, Ue) for Ue in moved])
    # second differences: smooth (measured 1.4e-5 of the largest) vs jumps (0.12)
    assert np.abs(np.diff(F, 2, axis=0)).max() < 1e-4 * np.abs(F).max()
    assert np.abs(np.diff(P, 2, axis=0)).max() > 1e-2 * np.abs(P).max()


def test_jacobians_match_central_differences_through_the_jumps():
    el = make_element("hertz_contact", **JUMPY)
    b = HarmonicBasis(9, 128)
    Ue = _motion()
    F, D, dFp = element_forces(b, el, Ue, OMEGA_B, True, True)
    h = 1e-9  # m, against coefficients of ~1e-4..1e-3 m
    cols = []
    for j in range(Ue.size):
        step = h * np.eye(Ue.size)[j]
        plus = element_forces(b, el, Ue + step, OMEGA_B, False)[0]
        minus = element_forces(b, el, Ue - step, OMEGA_B, False)[0]
        cols.append((plus - minus) / (2 * h))
    # measured 3.4e-6 of the largest entry
    np.testing.assert_allclose(D, np.column_stack(cols), atol=5e-5 * np.abs(D).max())
    for i, (name, value) in enumerate(el.params.items()):
        hp = 1e-6 * value
        plus = element_forces(b, el.with_params(**{name: value + hp}), Ue, OMEGA_B, False)[0]
        minus = element_forces(b, el.with_params(**{name: value - hp}), Ue, OMEGA_B, False)[0]
        # measured: k_c 7e-10, gap 6e-6, v 9e-11 of the largest entry
        np.testing.assert_allclose(
            dFp[:, i],
            (plus - minus) / (2 * hp),
            atol=5e-5 * np.abs(dFp[:, i]).max(),
            err_msg=name,
        )


def test_a_law_without_jumps_is_the_plain_sampled_sum():
    el = make_element("cubic_spring", k3=1e12)
    b = HarmonicBasis(9, 128)
    F, _, _ = element_forces(b, el, _motion(), OMEGA_B, False)
    np.testing.assert_allclose(F, _plain(b, el, _motion()), rtol=0, atol=1e-14 * np.abs(F).max())


@pytest.mark.parametrize("side", [-1, 1])
def test_compiled_forces_match_the_numpy_path_on_random_states(side):
    """The compiled AFT (law, samples, jumps and projection in numba) against the numpy path
    (taken when parameter derivatives are wanted), on random motions around the stop."""
    rng = np.random.default_rng(7 + side)
    el = make_element("hertz_contact", side=side, **JUMPY)
    assert el.compiled_law() is not None
    b = HarmonicBasis(9, 128)
    n_jumps = 0
    for _ in range(200):
        Ue = rng.normal(0.0, 4e-4, b.size) / np.arange(1, b.size + 1)
        Ue[0] += side * rng.uniform(0.0, 1e-3)
        F, D, _ = element_forces(b, el, Ue, OMEGA_B)
        F_np, D_np, _ = element_forces(b, el, Ue, OMEGA_B, True, want_params=True)
        uv = b.EdE @ Ue
        n_jumps += int(np.any(np.diff(side * uv[: b.n_time] > JUMPY["gap"])))
        # the same arithmetic summed in another order: rounding only
        assert np.abs(F - F_np).max() <= 1e-12 * max(np.abs(F_np).max(), 1e-300)
        assert np.abs(D - D_np).max() <= 1e-12 * max(np.abs(D_np).max(), 1e-300)
    assert n_jumps > 50  # the states exercise the jump integrals, not only the samples


def test_compiled_law_is_the_array_law():
    """The numba law against the array code (which also gives the parameter derivatives), at
    samples in and out of contact, in any input shape."""
    rng = np.random.default_rng(3)
    for side in (-1, 1):
        el = make_element("hertz_contact", side=side, **JUMPY)
        u = rng.normal(0.0, 1e-3, (7, 9))
        v = rng.normal(0.0, 0.2, (7, 9))
        fast, ref = el.evaluate(u, v), el.evaluate(u, v, want_params=True)
        assert (side * u > JUMPY["gap"]).any() and (side * u <= JUMPY["gap"]).any()
        for a, r in ((fast.f, ref.f), (fast.df_du, ref.df_du), (fast.df_dv, ref.df_dv)):
            assert a.shape == u.shape
            np.testing.assert_allclose(a, r, rtol=1e-15, atol=0.0)
        assert el.evaluate(np.float64(-1e-3), np.float64(0.1)).f.shape == ()


def test_many_states_at_once_equal_each_state_alone():
    """The batched evaluation (a screen's steps) against the one-state path, state by state:
    states in and out of contact, with and without jumps, at different frequencies; forces,
    Jacobians and parameter derivatives equal to rounding (1e-12 of each's largest)."""
    from analysis.mhb.aft import element_forces_batch

    el = make_element("hertz_contact", **JUMPY)
    b = HarmonicBasis(9, 128)
    rng = np.random.default_rng(3)
    scales = np.array([0.0, 0.3, 1.0, 1.7, 2.5])  # 0: at rest, far from the stop
    U = np.array([s * _motion() + 1e-5 * rng.standard_normal(19) * s for s in scales])
    omega = OMEGA_B * np.array([0.8, 0.9, 1.0, 1.1, 1.3])
    F, D, dFp = element_forces_batch(b, el, U, omega, True, True)
    for i in range(len(scales)):
        Fi, Di, dFpi = element_forces(b, el, U[i], omega[i], True, True)
        np.testing.assert_allclose(F[i], Fi, rtol=0, atol=1e-12 * max(np.abs(Fi).max(), 1e-300))
        np.testing.assert_allclose(D[i], Di, rtol=0, atol=1e-12 * max(np.abs(Di).max(), 1e-300))
        np.testing.assert_allclose(
            dFp[i], dFpi, rtol=0, atol=1e-12 * max(np.abs(dFpi).max(), 1e-300)
        )
        # the compiled one-state path the balance uses, forces and Jacobian
        Fc, Dc, _ = element_forces(b, el, U[i], omega[i], True)
        np.testing.assert_allclose(F[i], Fc, rtol=0, atol=1e-10 * max(np.abs(Fc).max(), 1e-300))
        np.testing.assert_allclose(D[i], Dc, rtol=0, atol=1e-10 * max(np.abs(Dc).max(), 1e-300))
    assert np.abs(F[0]).max() == 0.0 and np.abs(F[-1]).max() > 0.0


@pytest.mark.parametrize(("kind", "values", "u_scale", "v_scale"), EXAMPLES, ids=EXAMPLE_IDS)
def test_every_laws_compiled_forces_match_the_numpy_path(kind, values, u_scale, v_scale):
    """The compiled AFT of each law of the library against the numpy path (taken when
    parameter derivatives are wanted), on random motions of the example's size: forces and
    Jacobians to 1e-12 of their largest."""
    el = make_element(kind, **values)
    b = HarmonicBasis(9, 128)
    rng = np.random.default_rng(11)
    for _ in range(30):
        Ue = rng.normal(0.0, u_scale, b.size) / np.arange(1, b.size + 1)
        omega = v_scale / u_scale * rng.uniform(0.5, 2.0)
        F, D, _ = element_forces(b, el, Ue, omega)
        F_np, D_np, _ = element_forces(b, el, Ue, omega, True, want_params=True)
        assert np.abs(F - F_np).max() <= 1e-12 * max(np.abs(F_np).max(), 1e-300)
        assert np.abs(D - D_np).max() <= 1e-12 * max(np.abs(D_np).max(), 1e-300)


def test_a_subclass_with_its_own_law_is_evaluated_by_its_own_law():
    """A subclass that writes its own ``_evaluate`` (here a cubic spring made stiffer on one
    side) loses its parent's compiled form: the balance evaluates the new law, not the
    parent's; one that only changes a setting keeps the compiled form."""
    from analysis.elements.polynomial import CubicSpring

    class OneSidedCubic(CubicSpring):
        def _evaluate(self, u, v, want_params):
            ev = super()._evaluate(u, v, want_params)
            scale = np.where(u > 0, 3.0, 1.0)
            dp = None if ev.df_dp is None else ev.df_dp * scale
            return type(ev)(ev.f * scale, ev.df_du * scale, ev.df_dv, dp)

    class Quintic(CubicSpring):
        powers = (5,)

    b = HarmonicBasis(9, 128)
    Ue = 1e-3 * np.array([0.2, 1.0, 0.3, 0.1, 0.0, 0.05, 0.0] + [0.0] * 12)
    one_sided = OneSidedCubic(k3=1e9)
    assert one_sided.compiled_law() is None
    F, _, _ = element_forces(b, one_sided, Ue, OMEGA_B)
    np.testing.assert_allclose(F, _plain(b, one_sided, Ue), rtol=0, atol=1e-12 * np.abs(F).max())
    plain_cubic = _plain(b, CubicSpring(k3=1e9), Ue)
    assert np.abs(F - plain_cubic).max() > 0.1 * np.abs(plain_cubic).max()
    quintic = Quintic(k3=1e9)
    assert quintic.compiled_law() is not None
    F5, _, _ = element_forces(b, quintic, Ue, OMEGA_B)
    np.testing.assert_allclose(F5, _plain(b, quintic, Ue), rtol=0, atol=1e-12 * np.abs(F5).max())
    u = b.EdE[: b.n_time] @ Ue
    np.testing.assert_allclose(quintic.force(u, 0 * u), -1e9 * u**5, rtol=1e-14)
