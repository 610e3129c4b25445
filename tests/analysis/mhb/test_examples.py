"""Standard harmonic-balance examples beyond the Duffing oscillator, and rig sensitivities."""

from fractions import Fraction

import numpy as np
import pytest

from analysis.elements import make_element
from analysis.linear.receptance import DirectLinearModel
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.mhb.sensitivity import point_sensitivities
from analysis.mhb.solver import solve_point
from analysis.mhb.sweep import solve_steps
from analysis.mhb.time_integration import integrate_steady_state
from analysis.model import Model, load_model
from analysis.system import build_linear, build_problem

CANTILEVER = """
[parameters.E]
value = 2.1e11
nominal = 2.1e11
lower = 1e11
upper = 3e11
group = "linear"
[parameters.k_gap]
value = 2e4
nominal = 2e4
lower = 1e3
upper = 1e6
group = "nonlinear"
[sections.bar]
shape = "rect"
b = 0.03
h = 0.012
[materials.steel]
E = "E"
rho = 7900.0
[nodes]
root = [0.0, 0.0]
tip = [0.6, 0.0]
[[members]]
nodes = ["root", "tip"]
section = "bar"
material = "steel"
elements = 10
[supports]
root = "all"
[points.1]
node = "tip"
direction = "y"
[points.2]
xy = [0.3, 0.0]
direction = "y"
[damping]
default_zeta = 0.01
[[nonlinear]]
name = "tip_stop"
kind = "gap_spring"
at = { point = 1 }
params = { k = "k_gap", gap = 5e-4 }
"""


def test_sub_harmonic_force_orders_in_the_linear_limit():
    """Orders 1/2, 1 and 2 of a linear system equal the direct solves at w/2, w, 2w (1e-12)."""
    rng = np.random.default_rng(5)
    n = 4
    A = rng.standard_normal((n, n))
    K = A @ A.T + n * np.eye(n)
    M = np.eye(n)
    C = 0.02 * K
    gap = make_element("gap_spring", k=1.0, gap=1e3)
    orders = (Fraction(1, 2), Fraction(1), Fraction(2))
    pb = HarmonicProblem(
        DirectLinearModel(M, C, K),
        [Attachment(gap, 0)],
        [1],
        [2, 3],
        orders=orders,
        n_harmonics=6,
        n_time=32,
    )
    F = np.array([0.3, 1.0, 0.1j])
    w = 2.0
    p = solve_point(pb, w, F)
    for o, Fo, q in zip(orders, F, p.outputs(), strict=True):
        wo = float(o) * w
        ref = np.linalg.solve(K - wo**2 * M + 1j * wo * C, np.eye(n)[:, 1] * Fo)[[2, 3]]
        assert np.allclose(q, ref, rtol=1e-12, atol=1e-15)


@pytest.mark.slow
def test_clamped_beam_with_tip_gap_matches_time_integration():
    """A cantilever (10 beam elements) hitting a linear stop 0.5 mm under its tip."""
    model = Model.from_toml_text(CANTILEVER)
    pb = build_problem(
        model, drive_point=2, output_points=(1, 2), n_harmonics=15, n_time=256, f_max_hz=800.0
    )
    f1 = build_linear(model, f_max_hz=800.0).modes.frequency_hz[0]
    F = np.array([4.0, 0.08, 0.08])
    grid = 2 * np.pi * np.linspace(0.85 * f1, 1.02 * f1, 12)
    sweep = solve_steps(pb, grid, F)
    assert sweep.converged.all()
    p = sweep.points[-1]
    assert pb.basis.to_time(p.X)[:, 0].min() < -5e-4  # the stop closes
    ti = integrate_steady_state(pb, grid[-1], F, rtol=1e-8)
    fund = np.abs(p.outputs()[0]).max()
    assert np.abs(ti.outputs() - p.outputs()).max() < 0.01 * fund


@pytest.fixture(scope="module")
def rig_point():
    values = {"k_c": 4.51e5, "gap": 0.6e-3, "v_c": 25.21, "k_mount": 57989.0}
    model = load_model().with_values(values)
    pb = build_problem(model, f_max_hz=600.0)
    F = np.array([6.0, 0.12, 0.12])
    sweep = solve_steps(pb, 2 * np.pi * np.arange(24.0, 27.61, 0.2), F)
    p = sweep.points[-1]
    assert p.converged and pb.basis.to_time(p.X)[:, 0].min() < -0.6e-3  # contact closed
    return model, pb, F, p


@pytest.mark.parametrize(
    "name, rel_step",
    [("k_c", 1e-4), ("gap", 1e-5), ("v_c", 1e-4), ("E_beam", 1e-3), ("k_mount", 1e-2)],
)
def test_rig_sensitivities_match_finite_differences(rig_point, name, rel_step):
    """Implicit differentiation on the modal rig model with the paper's contact (2e-3).

    Structural steps are larger: the rig's eigen-solution carries ~1e-7 relative round-off
    (cond(K) ~ 3e10), which smaller central differences amplify beyond the tolerance.
    """
    model, pb, F, p = rig_point
    an = point_sensitivities(pb, p, [name])[name].d_outputs(pb.order_k)
    v0 = model.values()[name]
    h = rel_step * v0

    def outputs(v):
        m = model.with_values({name: v})
        q = build_problem(m, f_max_hz=600.0)
        assert len(q.linear.modes) == len(pb.linear.modes)
        return solve_point(q, p.omega, F, p.X).outputs()

    fd = (outputs(v0 + h) - outputs(v0 - h)) / (2 * h)
    assert np.abs(an - fd).max() <= 2e-3 * np.abs(fd).max()
