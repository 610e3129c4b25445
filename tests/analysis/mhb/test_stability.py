"""Floquet exponents: Hill's method on the modes that matter against the monodromy matrix,
the linear limit's closed form and direct time integration."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from analysis.elements import make_element
from analysis.linear.receptance import DirectLinearModel
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.mhb.solver import solve_point
from analysis.mhb.stability import cross_check, floquet_exponents

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
#: the leading Floquet multiplier of the fast method within this of the monodromy matrix's
MULTIPLIER_RTOL = 0.02


def _example(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _fold(lam: np.ndarray, wb: float) -> np.ndarray:
    return lam - 1j * wb * np.round(lam.imag / wb)


def test_linear_system_exponents_are_the_state_matrix_eigenvalues():
    """No nonlinear force (a cubic spring at zero stiffness): the exponents are the
    eigenvalues of the linear state matrix, folded into the band, to round-off (1e-9 of the
    base frequency), with a non-proportional damping matrix and every mode kept; with the
    default cutoff at a base frequency that leaves the top mode out, the kept modes'
    eigenvalues (this damping couples no kept mode to a dropped one: it is proportional)."""
    M = np.diag([1.0, 0.5, 2.0])
    K = np.array([[3.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 5.0]]) * 10.0
    C = np.array([[0.3, 0.0, -0.1], [0.0, 0.2, 0.0], [-0.1, 0.0, 0.1]])
    att = Attachment(make_element("cubic_spring", k3=0.0), 1, None, "none")
    for damping, cutoff, wb in ((C, None, 1.3), (0.01 * K + 0.1 * M, 1.0, 0.6)):
        lin = DirectLinearModel(M, damping, K)
        pb = HarmonicProblem(lin, [att], [0], [0], orders=(1,), n_harmonics=3, n_time=32)
        p = solve_point(pb, wb, np.array([0.2]))
        A = np.block(
            [[np.zeros((3, 3)), np.eye(3)], [-np.linalg.solve(M, K), -np.linalg.solve(M, damping)]]
        )
        exact = _fold(np.linalg.eigvals(A), wb)
        st = floquet_exponents(pb, p, mode_cutoff=cutoff)
        if cutoff is not None:
            # the kept modes: natural frequency up to the cutoff times n_hill * wb
            w_n = np.sqrt(np.linalg.eigvals(np.linalg.solve(M, K)).real)
            top = w_n[w_n <= cutoff * 10 * wb].max()  # n_hill = 10 by default
            assert top < w_n.max()
            exact = exact[np.abs(np.linalg.eigvals(A).imag) <= top * 1.001]
        assert st.exponents.size == exact.size
        for lam in exact:
            assert np.abs(st.exponents - lam).min() < 1e-9 * wb
        assert st.stable


def test_period_doubling_curve_verdicts_and_multipliers_agree_with_the_monodromy_matrix():
    """The impact oscillator's period-1 branch crosses two period-doubling points: the fast
    method's verdict equals the monodromy matrix's at every point, and its leading multiplier
    is within 2 %; both see multipliers below -1 between 2.05 and 2.65 rad/s."""
    pb, br = _example("impact_oscillator").curve(stability=False)
    assert br.message == "reached the end frequency"
    check = cross_check(pb, br.points)
    assert check.agrees and check.multiplier_rel_err < MULTIPLIER_RTOL
    doubling = [
        p.omega for p in br.points if floquet_exponents(pb, p).leading_multiplier(p.omega).real < -1
    ]
    assert doubling and 2.05 < min(doubling) and max(doubling) < 2.65


def _poincare(pb: HarmonicProblem, omega: float, force: float, x0: np.ndarray, periods: int):
    """States at the starts of ``periods`` forcing periods, by DOP853 on the oscillator's own
    equation (the stop's law evaluated by its element)."""
    el = pb.attachments[0].element
    mass, damping, stiffness = 1.0, 0.02, 1.0  # examples/impact_oscillator.toml

    def rhs(t, y):
        f = float(el.evaluate(np.array([y[0]]), np.array([y[1]])).f[0])
        acc = (force * np.cos(omega * t) - damping * y[1] - stiffness * y[0] + f) / mass
        return [y[1], acc]

    T = 2 * np.pi / omega
    sol = solve_ivp(
        rhs,
        (0, periods * T),
        x0,
        method="DOP853",
        rtol=1e-10,
        atol=1e-12,
        t_eval=T * np.arange(periods + 1),
    )
    return sol.y.T


@pytest.mark.slow
def test_period_doubling_is_seen_by_time_integration():
    """Started on the balance's period-1 orbit plus 1e-6, direct integration stays on it
    where the exponents say stable (2.9 rad/s) and settles on a period-2 orbit where they
    say period doubling (2.3 rad/s): after 400 periods, successive Poincare states differ by
    more than 1e-2 while every second one repeats to 1e-4 (the transient's last trace)."""
    pb, _ = _example("impact_oscillator").curve(stability=False)
    for omega, doubled in ((2.9, False), (2.3, True)):
        p = solve_point(pb, omega, np.array([0.9]))
        assert p.converged
        st = floquet_exponents(pb, p)
        mu = st.leading_multiplier(omega)
        assert st.stable is not doubled and (mu.real < -1) is doubled
        X = pb.basis.to_time(p.X[:, 0])
        V = pb.basis.rate_to_time(p.X[:, 0], omega)
        y = _poincare(pb, omega, 0.9, np.array([X[0] + 1e-6, V[0]]), 420)
        step1 = np.abs(y[-1] - y[-2]).max()
        step2 = np.abs(y[-1] - y[-3]).max()
        if doubled:
            assert step1 > 1e-2 and step2 < 1e-4
        else:
            assert step1 < 1e-6 and np.abs(y[-1] - [X[0], V[0]]).max() < 1e-6


@pytest.mark.slow
@pytest.mark.parametrize("n_harmonics", [5, 10])
def test_beam_curve_verdicts_and_multipliers_agree_with_the_monodromy_matrix(n_harmonics):
    """The cantilever with a tip stop through its folds (about 510 points): the verdict equals
    the monodromy matrix's on the full 24-DOF model and the leading multiplier is within 2 %
    at every point where the verdict changes (two points either side) and at every eighth
    point elsewhere (the speed benchmark checks every point); the branch between the folds is
    unstable."""
    pb, br = _example("cantilever_tip_contact").curve(stability=False, n_harmonics=n_harmonics)
    stable = [floquet_exponents(pb, p).stable for p in br.points]
    assert not all(stable) and any(stable)
    changes = [i for i in range(1, len(stable)) if stable[i] != stable[i - 1]]
    near = {j for i in changes for j in range(i - 2, i + 2) if 0 <= j < len(stable)}
    picked = sorted(near | set(range(0, len(stable), 8)))
    check = cross_check(pb, [br.points[i] for i in picked])
    assert check.agrees and check.multiplier_rel_err < MULTIPLIER_RTOL


def test_bad_options_are_named():
    pb, br = _example("impact_oscillator").curve(stability=False)
    p = br.points[0]
    with pytest.raises(ValueError, match="n_hill: expected an integer from 1 to 127"):
        floquet_exponents(pb, p, n_hill=200)
    with pytest.raises(ValueError, match="method: expected one of"):
        floquet_exponents(pb, p, method="floquet")
    with pytest.raises(ValueError, match="mode_cutoff: expected a positive number"):
        floquet_exponents(pb, p, mode_cutoff=0.0)
