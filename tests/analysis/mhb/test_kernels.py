"""The compiled Newton iteration and forces (analysis.mhb.kernels) against the element-by-element
Python path they replace, and the cache key that keeps them in step with the laws' sources."""

from __future__ import annotations

import importlib
import sys

import numpy as np
import pytest

from analysis.elements import make_element
from analysis.elements.compiled import LAWS, law_code, source_stamp
from analysis.mhb.aft import nonlinear_forces
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.mhb.solver import NewtonSettings, solve_point
from tests.analysis.mhb.systems import contact_chain
from tests.analysis.test_elements import EXAMPLES


def _python_path(problem: HarmonicProblem) -> HarmonicProblem:
    """The same problem, balanced element by element in Python (as a law outside the
    library is)."""
    twin = problem.with_elements([a.element for a in problem.attachments])
    twin._element_arrays = None
    return twin


def _every_law_problem(kind_values) -> HarmonicProblem:
    """Three masses in a chain to ground with the given elements placed in turn to ground,
    between two masses and between them the other way round."""
    from analysis.linear.receptance import DirectLinearModel

    M = np.diag([1.0, 0.5, 0.8])
    K = 4e4 * np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]])
    lin = DirectLinearModel(M, 2e-4 * K + 0.5 * M, K)
    places = [(2, None), (1, 2), (0, 1), (2, 0)]
    atts = [
        Attachment(make_element(kind, **values), *places[i % len(places)], f"e{i}")
        for i, (kind, values) in enumerate(kind_values)
    ]
    return HarmonicProblem(lin, atts, [0], [0, 1, 2], n_harmonics=7, n_time=128)


def test_every_library_law_has_a_code():
    """Every law an element of the library compiles to is one the kernels can call."""
    for kind, values, *_ in EXAMPLES:
        law, _ = make_element(kind, **values).compiled_law()
        assert law_code(law) is not None, kind
    assert len({law_code(law) for law in LAWS}) == len(LAWS)


@pytest.mark.parametrize("start", range(0, len(EXAMPLES), 4))
def test_compiled_forces_equal_the_element_by_element_path(start):
    """Forces and Jacobian of four elements at once (each law of the library in some group,
    placed to ground and between DOFs both ways) against the Python path, to 1e-12 of their
    largest, on random motions of the examples' sizes."""
    group = [EXAMPLES[(start + i) % len(EXAMPLES)] for i in range(4)]
    pb = _every_law_problem([(k, v) for k, v, *_ in group])
    slow = _python_path(pb)
    assert pb.element_arrays() is not None
    u_scale = max(g[2] for g in group)
    v_scale = min(g[3] for g in group)
    rng = np.random.default_rng(start)
    for _ in range(20):
        X = rng.normal(0.0, u_scale, (pb.basis.size, pb.n_nl))
        X /= np.arange(1, pb.basis.size + 1)[:, None]
        wb = v_scale / u_scale * rng.uniform(0.5, 2.0)
        F, dF = nonlinear_forces(pb, X, wb)
        F_py, dF_py = nonlinear_forces(slow, X, wb)
        assert np.abs(F - F_py).max() <= 1e-12 * np.abs(F_py).max()
        assert np.abs(dF - dF_py).max() <= 1e-12 * np.abs(dF_py).max()
        F_only, none = nonlinear_forces(pb, X, wb, jacobian=False)
        assert none is None and np.array_equal(F_only, F)


def _sweep(pb: HarmonicProblem, omegas, force, settings=None):
    X, out = None, []
    for w in omegas:
        p = solve_point(pb, w, force, X, settings)
        out.append(p)
        X = p.X if p.converged else None
    return out


@pytest.mark.parametrize("case", ["contact_chain", "every_law"])
def test_compiled_newton_takes_the_python_iterations_steps(case):
    """Up and down through the resonance (contact, folds skipped by the step), every point as
    the Python Newton iteration: the same outcome, message and iteration count, a converged
    solution and its outputs within 1e-8 of their largest (the two differ by rounding only; Newton
    stops at a residual of 1e-10 of the largest coefficient, and where the contact stiffens
    the response the conditioning of the balance amplifies that difference)."""
    if case == "contact_chain":
        pb = contact_chain()
        omegas = np.linspace(150.0, 260.0, 45)
        force = np.array([6.0, 0.12, 0.12])
    else:
        pb = _every_law_problem(
            [
                ("hertz_contact", {"k_c": 1e7, "gap": 2e-4, "v": 10.0}),
                ("cubic_spring", {"k3": 2e9}),
                ("coulomb_friction", {"f_slip": 0.3}),
                ("two_sided_gap", {"k": 1e4, "gap": 3e-4}),
            ]
        )
        omegas = np.linspace(60.0, 300.0, 50)
        force = np.array([2.0, 0.04, 0.04])
    slow = _python_path(pb)
    converged = 0
    for grid in (omegas, omegas[::-1]):
        fast_pts, slow_pts = _sweep(pb, grid, force), _sweep(slow, grid, force)
        for p, q in zip(fast_pts, slow_pts, strict=True):
            assert (p.converged, p.message, p.iterations) == (q.converged, q.message, q.iterations)
            if p.converged:  # a failed point's last iterate is anyone's guess
                assert np.abs(p.X - q.X).max() <= 1e-8 * np.abs(q.X).max()
                assert np.abs(p.q_out - q.q_out).max() <= 1e-8 * np.abs(q.q_out).max()
            # a converged residual is rounding (a thousandth of the tolerance and below)
            tol = 1e-13 * np.abs(q.X).max()
            assert p.residual == pytest.approx(q.residual, rel=1e-6, abs=tol)
            converged += p.converged
    assert converged >= len(omegas)  # most points converge: the comparison is not vacuous


def test_compiled_newton_fails_where_and_as_the_python_iteration_does():
    """Started from the linear response at a force the contact chain cannot follow there,
    with the default settings and with one iteration allowed: every point ends as in the
    Python iteration (outcome, message, iterations, residual), and the points cover
    convergence, a failed line search, a stall and the iteration limit."""
    pb = contact_chain()
    slow = _python_path(pb)
    force = np.array([20.0, 0.4, 0.4])
    seen = set()
    for settings in (NewtonSettings(), NewtonSettings(max_iterations=1)):
        for w in np.linspace(120.0, 300.0, 19):
            p = solve_point(pb, w, force, settings=settings)
            q = solve_point(slow, w, force, settings=settings)
            assert (p.converged, p.message, p.iterations) == (q.converged, q.message, q.iterations)
            assert p.residual == pytest.approx(q.residual, rel=1e-6, abs=1e-13 * np.abs(q.X).max())
            seen.add(p.message.split(" (")[0])
    assert {"converged", "line search failed", "stalled", "maximum iterations reached"} <= seen


def test_a_law_outside_the_library_takes_the_python_path():
    """An element whose compiled law is its own has no code: the problem has no arrays and
    is balanced by the Python path."""
    from analysis.elements.polynomial import CubicSpring

    base = CubicSpring(k3=1e9).compiled_law()[0]

    class Mine(CubicSpring):
        def compiled_law(self):
            law, p = super().compiled_law()
            return (lambda u, v, q: law(u, v, q)), p

    assert law_code(Mine(k3=1e9).compiled_law()[0]) is None and law_code(base) is not None
    pb = contact_chain()
    mine = Attachment(Mine(k3=1e9), 1, None, "mine")
    assert HarmonicProblem(pb.linear, [*pb.attachments, mine], [0], [0, 1]).element_arrays() is None


def test_the_cache_key_follows_the_sources_the_kernels_call_into(tmp_path, monkeypatch):
    """numba keys a cached function on its own file; the kernels carry a digest of the files
    they call into, which changes when one of them does."""
    monkeypatch.syspath_prepend(str(tmp_path))
    src = tmp_path / "some_law_module.py"
    src.write_text("def law(u):\n    return u\n")
    importlib.import_module("some_law_module")
    try:
        before = source_stamp(["some_law_module"])
        assert source_stamp(["some_law_module"]) == before
        src.write_text("def law(u):\n    return 2 * u\n")
        assert source_stamp(["some_law_module"]) != before
    finally:
        sys.modules.pop("some_law_module", None)
