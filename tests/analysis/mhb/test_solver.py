"""Balance solutions against independent references."""

import numpy as np
import pytest

from analysis.elements import make_element
from analysis.linear.receptance import DirectLinearModel
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.mhb.solver import NewtonSettings, solve_point
from analysis.mhb.sweep import solve_steps
from analysis.mhb.time_integration import integrate_steady_state

from .systems import contact_chain, duffing


def test_linear_limit_equals_direct_solve():
    """An open gap exerts no force: every harmonic equals (K - w^2 M + i w C)^-1 F (1e-12)."""
    rng = np.random.default_rng(3)
    n = 5
    A = rng.standard_normal((n, n))
    K = A @ A.T + n * np.eye(n)
    M = np.diag(1 + rng.random(n))
    C = 0.01 * K + 0.02 * M
    lin = DirectLinearModel(M, C, K)
    gap = make_element("gap_spring", k=1e3, gap=10.0)  # never closes
    pb = HarmonicProblem(
        lin, [Attachment(gap, 2)], [1], [0, 2, 4], orders=(1, 2, 3), n_harmonics=5, n_time=32
    )
    F = np.array([1.0, 0.02j, 0.02])
    w = 1.3
    p = solve_point(pb, w, F)
    assert p.converged
    for k, Fk in zip((1, 2, 3), F, strict=True):
        ref = np.linalg.solve(K - (k * w) ** 2 * M + 1j * k * w * C, np.eye(n)[:, 1] * Fk)
        assert np.allclose(p.q_out[k], ref[[0, 2, 4]], rtol=1e-12, atol=1e-15)


def test_duffing_single_harmonic_matches_the_analytic_relation():
    """H = 1: ((k - w^2 m + 3/4 k3 a^2)^2 + (c w)^2) a^2 = F^2 to 1e-8 (Newton rtol 1e-10)."""
    pb = duffing(k3=0.5, c=0.05, n_harmonics=1, n_time=16)
    F = 0.1
    res = solve_steps(pb, np.linspace(0.7, 1.6, 40), np.array([F]))
    assert res.converged.all()
    for p in res.points:
        a = abs(p.q_out[1, 0])
        w = p.omega
        rel = ((1 - w * w + 0.75 * 0.5 * a * a) ** 2 + (0.05 * w) ** 2) * a * a / F**2 - 1
        assert abs(rel) < 1e-8


def test_duffing_multi_harmonic_matches_time_integration():
    """Weakly nonlinear multi-sine: every order within 1e-4 of the fundamental."""
    pb = duffing(k3=0.2, c=0.05, orders=(1, 2, 3), n_harmonics=9, n_time=64)
    F = np.array([0.1, 0.002, 0.002j])
    state = None
    for w in (0.7, 1.4):
        p = solve_point(pb, w, F)
        ti = integrate_steady_state(pb, w, F, state, periodic_tol=1e-9)
        state = ti.state
        assert p.converged and ti.converged
        err = np.abs(ti.outputs() - p.outputs()).max() / abs(p.outputs()[0, 0])
        assert err < 1e-4


def test_unconverged_point_is_flagged_with_reason():
    pb = duffing(k3=5.0)
    p = solve_point(pb, 1.2, np.array([1.0]), settings=NewtonSettings(max_iterations=1))
    assert not p.converged
    assert "maximum iterations" in p.message


@pytest.mark.slow
def test_two_dof_hertz_contact_chain_matches_time_integration():
    """The standard unilateral-contact example: orders 1-3 within 1 % of the fundamental."""
    pb = contact_chain()
    # first mode of the chain ~ 17 Hz; drive near it so the stop closes
    F = np.array([30.0, 0.6, 0.6])
    for f_hz in (15.0, 19.0):
        w = 2 * np.pi * f_hz
        p = solve_point(pb, w, F)
        ti = integrate_steady_state(pb, w, F, periodic_tol=1e-8)
        assert p.converged
        assert pb.basis.to_time(p.X)[:, 0].min() < -1e-3  # the stop closes (gap 1 mm)
        diff = np.abs(ti.outputs() - p.outputs()).max() / np.abs(p.outputs()[0]).max()
        assert diff < 0.01


def test_mean_response_is_resolved_for_a_one_sided_stop():
    pb = contact_chain()
    p = solve_point(pb, 2 * np.pi * 19.0, np.array([30.0, 0.6, 0.6]))
    # the stop pushes up only: the mean nonlinear force is positive and shifts the mean up
    assert p.f_nl[0, 0].real > 0
    assert p.q_out[0, 1].real > 0


def _with_linear(pb: HarmonicProblem, linear) -> HarmonicProblem:
    """``pb`` with another linear structure (the same elements, DOFs, orders and balance)."""
    return HarmonicProblem(
        linear,
        pb.attachments,
        pb.force_dofs,
        pb.output_dofs,
        pb.orders,
        pb.n_harmonics,
        pb.n_time,
    )


@pytest.mark.parametrize("system", ["duffing", "contact"])
def test_sensitivities_match_finite_differences(system):
    if system == "duffing":
        pb = duffing(k3=0.3, orders=(1, 2, 3), n_harmonics=7, n_time=64)
        F, w, steps = np.array([0.1, 0.002, 0.002]), 0.9, {"k3": 1e-6}
        values = {"k3": 0.3}
    else:
        pb = contact_chain()
        F, w = np.array([30.0, 0.6, 0.6]), 2 * np.pi * 19.0
        steps = {"k_c": 1e-3 * 2e6, "gap": 1e-9, "v": 1e-4, "k1": 1e-2, "k2": 1e-2}
        values = {"k_c": 2e6, "gap": 1e-3, "v": 5.0}
    from analysis.mhb.sensitivity import point_sensitivities

    p = solve_point(pb, w, F)
    sens = point_sensitivities(pb, p)
    assert set(steps) <= set(sens)
    lin = pb.linear
    for name, h in steps.items():

        def out(s):
            if name in values:
                att = pb.attachments[0]
                el = att.element.with_params(**{att.param_map[name]: values[name] + s})
                q = pb.with_elements([el])
            else:
                q = _with_linear(
                    pb,
                    DirectLinearModel(lin.M, lin.C + s * lin.dC[name], lin.K + s * lin.dK[name]),
                )
            return solve_point(q, w, F, p.X).outputs()

        fd = (out(h) - out(-h)) / (2 * h)
        an = sens[name].d_outputs(pb.order_k)
        assert np.abs(an - fd).max() <= 2e-4 * np.abs(fd).max(), name


@pytest.mark.parametrize("linear", ["direct", "modal with a static support"])
def test_prefetched_receptances_and_derivatives_equal_those_of_each_frequency(linear):
    """:meth:`HarmonicProblem.prefetch` evaluates the blocks and their parameter derivatives
    over many frequencies at once: each frequency's values are those one evaluation at that
    frequency gives (to 1e-14 of the largest, einsum's summation may pair terms otherwise),
    and the solutions and sensitivities of a sweep are the same with and without it."""
    from analysis.linear.receptance import ModalLinearModel
    from analysis.linear.static_support import StaticSupport
    from analysis.mhb.sensitivity import point_sensitivities

    def problem():
        pb = contact_chain(n_harmonics=6, n_time=128)
        if linear == "direct":
            return pb
        lin = pb.linear
        modal = ModalLinearModel(lin.M, lin.K, zeta=0.02, dM={}, dK=lin.dK, f_max_hz=1e3)
        return _with_linear(pb, StaticSupport(modal, 0, 1e4))

    omega = 2 * np.pi * np.linspace(20.0, 30.0, 12)
    F = np.array([40.0, 0.8, 0.8])
    params = ["k_c", "k1", "k2"]
    batched, single = problem(), problem()
    batched.prefetch(omega, params)
    blocks = ("nn", "nf", "on", "of")
    keys = [*blocks, *(("d", n, p) for n in blocks for p in ("k1", "k2"))]
    for w in omega:
        a, b = batched.receptances(w), single.receptances(w)
        for key in keys:
            assert key in dict(a), key
            assert np.abs(a[key] - b[key]).max() <= 1e-14 * np.abs(b[key]).max(), key
        assert ("d", "nn", "k_c") not in dict(a)  # an element's parameter has no block derivative
    sweep_a = solve_steps(batched, omega, F)
    sweep_b = solve_steps(single, omega, F)
    assert sweep_b.converged.sum() >= 8
    for pa, pb_ in zip(sweep_a.points, sweep_b.points, strict=True):
        assert pa.converged == pb_.converged
        assert np.abs(pa.q_out - pb_.q_out).max() <= 1e-12 * np.abs(pb_.q_out).max()
        if not pb_.converged:
            continue
        sa, sb = point_sensitivities(batched, pa, params), point_sensitivities(single, pb_, params)
        for name in params:
            ref = sb[name].d_outputs(single.order_k)
            got = sa[name].d_outputs(batched.order_k)
            assert np.abs(got - ref).max() <= 1e-12 * np.abs(ref).max(), name


def test_a_frequencys_receptances_are_computed_once_and_the_solution_is_unchanged():
    """A stepped test solves every level at the same frequencies: no block is evaluated twice
    at a frequency over two levels, and the second level's solution is the one a fresh
    problem without kept blocks gives, to the last bit; the kept blocks are read-only, bounded
    in number, and shared with the problem's copies with other elements (same linear
    structure)."""
    import analysis.mhb.problem as problem_module

    pb = contact_chain(n_harmonics=6, n_time=128)
    seen = {name: [] for name in pb.blocks}

    def counted(name, block):
        def call(w):  # the harmonics of one or more base frequencies
            seen[name] += [float(x) for x in w.reshape(-1, pb.n_harmonics + 1)[:, 1]]
            return block(w)

        return call

    pb.blocks = {k: counted(k, v) for k, v in pb.blocks.items()}
    omega = 2 * np.pi * np.linspace(20.0, 30.0, 12)
    F = np.array([40.0, 0.8, 0.8])
    solve_steps(pb, omega, F)
    assert all(len(seen[name]) >= len(omega) for name in seen)
    high = solve_steps(pb, omega, 2 * F)  # (it may add substeps: new frequencies)
    for name, ws in seen.items():
        assert len(ws) == len(set(ws)), name  # no frequency's block evaluated twice

    fresh = contact_chain(n_harmonics=6, n_time=128)
    ref = solve_steps(fresh, omega, 2 * F)
    for a, b in zip(high.points, ref.points, strict=True):
        assert np.array_equal(a.X, b.X) and np.array_equal(a.q_out, b.q_out)
    rec = pb.receptances(omega[0])
    assert not rec["G"].flags.writeable and not rec["of"].flags.writeable
    other = pb.with_elements([make_element("hertz_contact", k_c=1e6, gap=2e-3, v=1.0)])
    assert other.receptances(omega[0]) is rec

    small = contact_chain(n_harmonics=3, n_time=32)
    many = 2 * np.pi * np.linspace(1.0, 50.0, problem_module.LINEAR_CACHE_SIZE + 5)
    for w in many:
        small.receptances(w)
    assert len(small._receptances) == problem_module.LINEAR_CACHE_SIZE
