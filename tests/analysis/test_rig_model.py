"""The shipped reference rig against the data of the paper (docs/rig.md)."""

from __future__ import annotations

import numpy as np
import pytest
import tomli_w

from analysis.model import load_model
from analysis.model_file import to_document

# Table 1 of the paper: point -> ((x, y) in m, measured direction, our assumption for the latter).
RIG_POINTS = {
    1: ((0.100, 0.0), "y"),
    2: ((0.200, 0.0), "y"),
    3: ((0.300, 0.0), "y"),
    4: ((0.400, 0.0), "y"),
    5: ((0.500, 0.0), "y"),
    6: ((0.600, 0.0), "y"),
    7: ((0.633, 0.0), "y"),
    8: ((0.0, -0.047), "x"),
    9: ((0.0, -0.179), "x"),
    10: ((0.035, -0.219), "y"),
    11: ((0.342, -0.219), "y"),
    12: ((0.670, -0.179), "x"),
    13: ((0.670, -0.047), "x"),
}
LINEAR = ("E_frame", "E_corner", "E_beam", "rho_corner", "k_mount")
CALIBRATED = {
    "E_frame": 205e9,
    "E_corner": 128e9,
    "E_beam": 201e9,
    "rho_corner": 5175.0,
    "k_mount": 57989.0,
}


@pytest.fixture(scope="module")
def rig():
    return load_model()


def beam_modes(asm, n_modes=12, share=0.5):
    """Frequencies [Hz] of modes with more than ``share`` of their kinetic energy in the beam."""
    freq, phi = asm.normal_modes(n_modes)
    beam = asm.group_mass_matrix(["beam", "clamp"])
    energy = np.einsum("im,ij,jm->m", phi, beam, phi)  # phi is mass-normalised: total = 1
    return freq[energy > share]


def test_masses_match_the_rig(rig):
    report = rig.assemble().mass_report()
    frame = report["frame structural"] + report["frame non-structural"] + report["corners"]
    beam = report["beam"] + report["clamp"]
    assert frame == pytest.approx(20.78, abs=0.01)
    assert beam == pytest.approx(1.98, abs=0.01)
    assert report["total"] == pytest.approx(frame + beam + report["sensors"], rel=1e-12)
    # Tube centrelines alone: about 15.3 kg at 7795 kg/m^3 (docs/rig.md).
    tube_area = 0.080**2 - 0.068**2
    assert report["frame structural"] == pytest.approx(0.958 * tube_area * 7795, rel=1e-9)


def test_total_mass_equals_rigid_translation_mass(rig):
    asm = rig.assemble()
    total = asm.mass_report()["total"]
    for direction in ("x", "y"):
        r = np.array([d == direction for _, d in asm.dofs], dtype=float)
        assert r @ asm.M @ r == pytest.approx(total, rel=1e-12)


def test_mesh_has_the_papers_element_counts_and_beam_nodes(rig):
    assert rig.structure.n_elements == {"beam": 13, "frame": 36, "corners": 6}
    xy = rig.assemble().node_xy.values()
    beam_x = sorted({round(x, 12) for x, y in xy if y == 0.0 and x < 0.65})
    np.testing.assert_allclose(beam_x, [*np.arange(13) * 0.05, 0.633], atol=1e-12)


def test_points_have_the_listed_positions_and_directions(rig):
    asm = rig.assemble()
    assert sorted(rig.points) == list(RIG_POINTS)
    for number, (xy, direction) in RIG_POINTS.items():
        point = rig.points[number]
        assert point.direction == direction
        np.testing.assert_allclose(point.xy, xy, atol=1e-12)
        np.testing.assert_allclose(asm.node_xy[point.node], xy, atol=1e-12)
        assert asm.dofs[asm.point_dof(number)] == (point.node, direction)


def test_clamp_ties_beam_root_to_post_top(rig):
    asm = rig.assemble()
    for d in ("x", "y", "rz"):
        assert asm.dof_index("beam_root", d) == asm.dof_index("left_top", d)
    assert rig.frame.joints[0].name == "clamp"


def test_nominal_beam_modes_in_the_papers_bands(rig):
    f = beam_modes(rig.assemble())
    assert 21.0 < f[0] < 40.0
    assert 141.0 < f[1] < 160.0


def test_calibrated_values_keep_first_beam_mode_in_band(rig):
    f = beam_modes(rig.with_values(CALIBRATED).assemble())
    assert 21.0 < f[0] < 40.0


@pytest.mark.parametrize("name", LINEAR)
def test_parameter_derivatives_match_finite_differences(rig, name):
    asm = rig.assemble()
    h = 1e-4 * rig.parameters[name].value
    up = rig.with_values({name: rig.parameters[name].value + h}).assemble()
    down = rig.with_values({name: rig.parameters[name].value - h}).assemble()
    for exact, plus, minus in ((asm.dK[name], up.K, down.K), (asm.dM[name], up.M, down.M)):
        fd = (plus - minus) / (2 * h)
        # K and M are affine in each parameter: central differences agree to round-off.
        scale = max(np.abs(exact).max(), np.abs(fd).max(), 1e-300)
        assert np.abs(fd - exact).max() <= 1e-6 * scale
    assert np.abs(asm.dK[name]).max() > 0 or np.abs(asm.dM[name]).max() > 0


def test_parameters_follow_table_2(rig):
    nominal = {
        "E_frame": 210e9,
        "E_corner": 150e9,
        "E_beam": 210e9,
        "rho_corner": 4000.0,
        "k_mount": 1e4,
        "k_c": 1e6,
        "gap": 1e-3,
        "v_c": 10.0,
    }
    assert rig.values() == nominal
    assert {n: p.nominal for n, p in rig.parameters.items()} == nominal
    assert set(rig.parameter_names(group="linear")) == set(LINEAR)
    assert set(rig.parameter_names(group="nonlinear")) == {"k_c", "gap", "v_c"}
    assert rig.parameters["k_mount"].scaling == "log" and rig.parameters["k_c"].scaling == "log"
    for p in rig.parameters.values():
        assert p.lower < p.nominal < p.upper


def test_bump_stop_is_hertz_contact_at_the_tip(rig):
    (spec,) = rig.nonlinear
    assert (spec.name, spec.kind, spec.to) == ("bump_stop", "hertz_contact", None)
    assert (spec.at.node, spec.at.direction, spec.at.point) == ("tip", "y", 7)
    assert spec.params == {"k_c": "k_c", "gap": "gap", "v": "v_c"}
    assert rig.damping.default_zeta == 0.01
    ((_, element),) = rig.build_elements()
    assert element.params == {"k_c": 1e6, "gap": 1e-3, "v": 10.0}


def test_compliant_clamp_lowers_the_first_beam_mode_and_converges_to_rigid(rig):
    f_rigid = beam_modes(rig.assemble())[0]
    f = {}
    for k_r in (2.0e4, 1.0e10):  # N m/rad
        doc = to_document(rig)
        (clamp,) = doc["joints"]
        clamp["rz"] = k_r
        f[k_r] = beam_modes(type(rig).from_toml_text(tomli_w.dumps(doc)).assemble())[0]
    assert f[2.0e4] < 0.995 * f_rigid
    assert f[1.0e10] == pytest.approx(f_rigid, rel=1e-4)
