"""Planar frame element and assembly against analytic beam results."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla

from analysis.fe import Section, mass_matrix, stiffness_matrix
from analysis.model import Model

E = 210e9  # Pa
RHO = 7800.0  # kg/m^3
B, H = 0.030, 0.012  # m; bending in h
AREA = B * H
INERTIA = B * H**3 / 12


def cantilever_text(length_m: float, n_elements: int, angle_deg: float = 0.0) -> str:
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    return f"""
[nodes]
root = [0.0, 0.0]
tip = [{length_m * c!r}, {length_m * s!r}]
[sections.bar]
shape = "rect"
b = {B}
h = {H}
[materials.steel]
E = {E}
rho = {RHO}
[[members]]
nodes = ["root", "tip"]
section = "bar"
material = "steel"
elements = {n_elements}
[supports]
root = "all"
"""


def test_section_properties_match_composite_rectangles():
    outer, wall = 0.080, 0.006
    tube = Section("rect_tube", outer_m=outer, wall_m=wall)
    # Independent: two flanges (parallel-axis theorem) plus two webs.
    web = outer - 2 * wall
    flange_I = outer * wall**3 / 12 + outer * wall * (outer / 2 - wall / 2) ** 2
    expected_I = 2 * flange_I + 2 * wall * web**3 / 12
    assert tube.area_m2 == pytest.approx(2 * outer * wall + 2 * wall * web, rel=1e-12)
    assert tube.inertia_m4 == pytest.approx(expected_I, rel=1e-12)
    rect = Section("rect", b_m=B, h_m=H)
    assert rect.inertia_m4 == pytest.approx(INERTIA, rel=1e-12)
    with pytest.raises(ValueError, match="wall_m"):
        Section("rect_tube", outer_m=0.01, wall_m=0.006)


@pytest.mark.parametrize("n_elements", [1, 4])
def test_static_tip_load_matches_beam_theory(n_elements):
    L, P = 0.8, 125.0  # m, N
    asm = Model.from_toml_text(cantilever_text(L, n_elements)).assemble()
    for direction, expected in (("y", P * L**3 / (3 * E * INERTIA)), ("x", P * L / (E * AREA))):
        f = np.zeros(asm.n_dofs)
        f[asm.dof_index("tip", direction)] = P
        u = np.linalg.solve(asm.K, f)
        # Hermite beam and linear bar elements are nodally exact: tolerance 1e-9 relative.
        assert u[asm.dof_index("tip", direction)] == pytest.approx(expected, rel=1e-9)
    f = np.zeros(asm.n_dofs)
    f[asm.dof_index("tip", "y")] = P
    u = np.linalg.solve(asm.K, f)
    assert u[asm.dof_index("tip", "rz")] == pytest.approx(P * L**2 / (2 * E * INERTIA), rel=1e-9)


def test_cantilever_bending_frequencies_within_half_percent():
    L = 1.0
    asm = Model.from_toml_text(cantilever_text(L, 20)).assemble()
    freq, phi = asm.normal_modes(3)
    roots = np.array([1.8751040687, 4.6940911330, 7.8547574382])
    analytic = roots**2 / (2 * np.pi) * np.sqrt(E * INERTIA / (RHO * AREA * L**4))
    np.testing.assert_allclose(freq, analytic, rtol=5e-3)
    y = [i for i, (_, d) in enumerate(asm.dofs) if d == "y"]
    x = [i for i, (_, d) in enumerate(asm.dofs) if d == "x"]
    # These are bending modes: transverse motion dominates axial motion.
    assert np.all(np.abs(phi[y]).max(axis=0) > 1e3 * np.abs(phi[x]).max(axis=0))


U_FRAME = """
[nodes]
a = [0.0, 0.0]
b = [0.0, -0.3]
c = [0.5, -0.3]
d = [0.5, 0.1]
[sections.tube]
shape = "rect_tube"
outer = 0.05
wall = 0.004
[materials.steel]
E = 2.1e11
rho = 7800.0
[[members]]
nodes = ["a", "b"]
section = "tube"
material = "steel"
max_element_length = 0.1
[[members]]
nodes = ["b", "c"]
section = "tube"
material = "steel"
max_element_length = 0.1
[[members]]
nodes = ["c", "d"]
section = "tube"
material = "steel"
elements = 3
"""


def test_free_frame_has_exactly_three_rigid_body_modes():
    asm = Model.from_toml_text(U_FRAME).assemble()
    lam = sla.eigh(asm.K, asm.M, eigvals_only=True)
    scale = lam[-1]
    assert np.all(np.abs(lam[:3]) < 1e-9 * scale)
    assert lam[3] > 1e-6 * scale
    # The rigid motions themselves produce no elastic force.
    theta = 1.0
    for rigid in ("x", "y", "rz"):
        q = np.zeros(asm.n_dofs)
        for i, (node, d) in enumerate(asm.dofs):
            x, y = asm.node_xy[node]
            if rigid == "rz":
                q[i] = {"x": -y * theta, "y": x * theta, "rz": theta}[d]
            else:
                q[i] = 1.0 if d == rigid else 0.0
        assert np.abs(asm.K @ q).max() < 1e-6 * np.abs(asm.K).max() * np.abs(q).max()


def test_rotated_cantilever_has_the_axis_aligned_eigenvalues():
    ref = Model.from_toml_text(cantilever_text(0.7, 6)).assemble()
    rot = Model.from_toml_text(cantilever_text(0.7, 6, angle_deg=37.0)).assemble()
    lam_ref = sla.eigh(ref.K, ref.M, eigvals_only=True)
    lam_rot = sla.eigh(rot.K, rot.M, eigvals_only=True)
    np.testing.assert_allclose(lam_rot, lam_ref, rtol=1e-9)


def test_rotated_element_mass_is_isotropic_and_stiffness_rotates():
    xa, xb = np.array([0.1, 0.2]), np.array([0.1 + 0.3 * 0.6, 0.2 + 0.3 * 0.8])
    m_per_l = 4.2  # kg/m
    M = mass_matrix(xa, xb, m_per_l)
    for d in (0, 1):
        r = np.zeros(6)
        r[[d, d + 3]] = 1.0
        assert r @ M @ r == pytest.approx(m_per_l * 0.3, rel=1e-12)
    # An axial stretch along the element axis: force EA/L * delta along the axis.
    K = stiffness_matrix(xa, xb, E, AREA, INERTIA)
    q = np.zeros(6)
    q[3:5] = np.array([0.6, 0.8]) * 1e-6
    np.testing.assert_allclose(K @ q, np.r_[-q[3:5], 0, q[3:5], 0] * E * AREA / 0.3, atol=1e-3)
