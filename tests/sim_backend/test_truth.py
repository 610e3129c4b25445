"""Truth structures: loading, the reference values, refusal by analysis, hidden effects."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.model import ModelFileError, load_model
from analysis.settings import ConfigError, build, dotted, dump
from sim_backend.amplifier import AmplifierConstants
from sim_backend.shaker import ShakerConstants
from sim_backend.sizing import PaperTest, second_mode_frequencies, truth_misfit
from sim_backend.truth import (
    TRUTH_DIR,
    NoiseFloors,
    SensorDefaults,
    TruthTable,
    list_truths,
    load_truth,
)

HIDDEN = ("hardening_mounts", "clamp_friction", "two_sided_stop", "damper_p5", "mass_loading")
# Hidden effects at the locations the diagnosis is to reach: one spring of a group, a beam
# point no sensor of the paper's test is at, an element between two nodes, a tie of points
# that a second test separates.
LOCATED = ("one_mount_hardens", "stop_above_p5", "tip_to_frame_stop", "damper_p4")
# A hidden effect outside the analysis library (a Jenkins element in the clamp).
OUTSIDE_LIBRARY = ("hysteretic_joint",)

# The paper's bump stop, in every truth: (kind, at, to, parameter values, options).
BUMP_STOP = ("hertz_contact", ("tip", "y"), None, {"k_c": 4.51e5, "gap": 0.60e-3, "v": 25.21},
             {"side": -1})  # fmt: skip
# Each truth's nonlinear elements besides the bump stop, as its header states them.
HIDDEN_ELEMENTS = {
    "reference": {},
    "hardening_mounts": {
        f"mount_{c}_{d}_hardening": ("cubic_spring", (f"{c}_bottom", d), None, {"k3": 1.5e12}, {})
        for c in ("left", "right")
        for d in ("x", "y")
    },
    "clamp_friction": {
        "clamp_friction": ("coulomb_friction", ("beam_root", "rz"), ("left_top", "rz"),
                           {"f_slip": 3.0}, {"v_reg": 0.01}),
    },
    "two_sided_stop": {
        "upper_stop": ("hertz_contact", ("tip", "y"), None,
                       {"k_c": 4.51e5, "gap": 1.2e-3, "v": 25.21}, {"side": 1}),
    },
    "damper_p5": {"damper_p5": ("quadratic_damper", ("p5", "y"), None, {"c2": 6.0}, {})},
    "mass_loading": {},
    "hysteretic_joint": {
        "clamp_microslip": ("jenkins", ("beam_root", "rz"), ("left_top", "rz"),
                            {"k_t": 1e5, "f_s": 1.5}, {}),
    },
    "one_mount_hardens": {
        "mount_right_y_hardening": ("cubic_spring", ("right_bottom", "y"), None, {"k3": 1e12}, {}),
    },
    "stop_above_p5": {
        "stop_above_p5": ("hertz_contact", ("p5", "y"), None,
                          {"k_c": 4.51e5, "gap": 1.2e-3, "v": 25.21}, {"side": 1}),
    },
    "tip_to_frame_stop": {
        "tip_to_frame_stop": ("hertz_contact", ("tip", "y"), ("right_top", "y"),
                              {"k_c": 4.51e5, "gap": 2.0e-3, "v": 25.21}, {"side": 1}),
    },
    "damper_p4": {"damper_p4": ("quadratic_damper", ("p4", "y"), None, {"c2": 30.0}, {})},
}  # fmt: skip
# Linear hidden parts: the clamp's rotational spring [N m/rad]; the extra mass at point 6 [kg].
CLAMP_RZ = {"clamp_friction": 50000.0, "hysteretic_joint": 30000.0}
EXTRA_MASS = {"mass_loading": ("p6", 0.06)}


def test_shipped_truths_are_listed_and_load() -> None:
    names = list_truths()
    assert set(names) == {"reference", *HIDDEN, *LOCATED, *OUTSIDE_LIBRARY}
    assert set(names) == set(HIDDEN_ELEMENTS)
    for name in names:
        truth = load_truth(name)
        assert truth.name == name
        assert truth.hidden_effect == ("none" if name == "reference" else name)
        assert truth.model.truth is not None


def test_reference_truth_holds_the_calibrated_values_and_the_analyst_nominals() -> None:
    truth = load_truth("reference")
    values = truth.model.values()
    expected = {
        "E_frame": 205e9,
        "E_corner": 128e9,
        "E_beam": 201e9,
        "rho_corner": 5175.0,
        "k_mount": 57989.0,
        "k_c": 4.51e5,
        "gap": 0.60e-3,
        "v_c": 25.21,
    }
    for name, value in expected.items():
        assert values[name] == pytest.approx(value, rel=1e-12), name
    analyst = load_model()
    for name, p in analyst.parameters.items():
        assert truth.model.parameters[name].nominal == p.nominal, name
    zeta = truth.model.damping.zeta(5)
    assert 0.005 <= zeta[3] <= 0.01 and 0.005 <= zeta[4] <= 0.01  # beam modes


def test_first_beam_mode_of_the_reference_is_in_the_papers_range() -> None:
    f, phi = load_truth("reference").model.assemble().normal_modes(6)
    assert 24.0 < f[3] < 28.0  # modes 1-3: the frame on its mounts


def test_analysis_refuses_a_truth_file() -> None:
    with pytest.raises(ModelFileError, match="truth"):
        load_model(TRUTH_DIR / "reference.toml")


def test_unknown_truth_names_the_shipped_ones() -> None:
    with pytest.raises(ValueError, match="reference"):
        load_truth("no_such_truth")


def test_a_model_file_without_truth_table_is_refused(tmp_path) -> None:
    path = tmp_path / "plain.toml"
    path.write_text(load_model().to_toml())
    with pytest.raises(ValueError, match="no \\[truth\\] table"):
        load_truth(path)


@pytest.mark.slow
@pytest.mark.parametrize("name", HIDDEN)
def test_hidden_effect_misfits_the_reference_far_beyond_the_noise(name: str) -> None:
    # stepped sine of the paper at 2 and 4 N (the full 2/4/6/8 N sizing is in the report)
    misfit = truth_misfit(name, test=PaperTest(levels_n=(2.0, 4.0)))
    assert misfit.rms_sigma > 10.0, misfit


def _elements(truth) -> dict[str, tuple]:
    out = {}
    for spec, element in truth.model.build_elements():
        to = None if spec.to is None else (spec.to.node, spec.to.direction)
        out[spec.name] = (spec.kind, (spec.at.node, spec.at.direction), to, element.params,
                          element.options)  # fmt: skip
    return out


def _same(found: tuple, expected: tuple) -> bool:
    kind, at, to, params, options = expected
    return (
        found[:3] == (kind, at, to)
        and found[3].keys() == params.keys()
        and all(found[3][k] == pytest.approx(v, rel=1e-12) for k, v in params.items())
        and all(found[4].get(k) == v for k, v in options.items())
    )


@pytest.mark.parametrize("name", sorted(HIDDEN_ELEMENTS))
def test_each_truth_hides_the_elements_its_header_states_at_their_dofs(name: str) -> None:
    truth = load_truth(name)
    elements = _elements(truth)
    assert _same(elements.pop("bump_stop"), BUMP_STOP), "the paper's stop is unchanged"
    expected = HIDDEN_ELEMENTS[name]
    assert elements.keys() == expected.keys()
    for key, found in elements.items():
        assert _same(found, expected[key]), (key, found)
    # every element names DOFs of the structure (assembly raises on an unknown node)
    asm = truth.model.assemble()
    for spec, _ in truth.model.build_elements():
        asm.dof_index(spec.at.node, spec.at.direction)
    (clamp,) = truth.model.frame.joints
    rz = clamp.connection("rz")
    if name in CLAMP_RZ:
        assert truth.model.values()[rz] == CLAMP_RZ[name]
    else:
        assert rz == "rigid"
    masses = {(m.node, m.m_kg) for m in truth.model.frame.masses if m.name != "clamped_length"}
    assert masses == ({EXTRA_MASS[name]} if name in EXTRA_MASS else set())
    header = TRUTH_DIR.joinpath(f"{name}.toml").read_text().split("\n[", 1)[0]
    assert ("# Hidden effect" in header) == (name != "reference")


@pytest.mark.slow
@pytest.mark.parametrize("name", LOCATED)
def test_located_effects_misfit_the_papers_test_far_beyond_the_noise(name: str) -> None:
    # Against the reference, before any calibration. The 8-30 x noise each is sized to is the
    # residual of the paper-way calibration on the simulated rig's run (each truth's header),
    # which absorbs most of this misfit in the bump stop's k_c, gap and v_c: the misfit here is
    # a lower bound's check only.
    misfit = truth_misfit(name)
    assert misfit.rms_sigma > 8.0, misfit


def _moved_damper(tmp_path, point: int, c2: float):
    """damper_p4 with its damper moved to ``point`` at ``c2``: a look-alike."""
    text = TRUTH_DIR.joinpath("damper_p4.toml").read_text()
    old_at, old_value = "at = { point = 4 }", "[parameters.c2_p4]\nvalue = 30.0\n"
    assert old_at in text and old_value in text
    text = text.replace(old_at, f"at = {{ point = {point} }}")
    text = text.replace(old_value, f"[parameters.c2_p4]\nvalue = {c2}\n")
    path = tmp_path / f"damper_at_{point}.toml"
    path.write_text(text)
    return load_truth(path)


@pytest.mark.slow
def test_damper_p4_ties_with_its_neighbours_in_the_papers_band_not_in_the_second_mode(
    tmp_path,
) -> None:
    # c2 scaled by (phi_4 / phi_j)^3 of the first bending mode (header of damper_p4): the
    # look-alikes at points 3 and 5 misfit the truth by 0.93 and 0.96 x noise in the paper's
    # test and by 87 and 31 around the second mode, where point 5 is on the node. Tolerances:
    # under 2 in the paper's band (the effect itself is 46 there), over 10 in the second.
    truth = load_truth("damper_p4")
    band = second_mode_frequencies()
    for point, c2 in ((3, 138.9), (5, 10.03)):
        look_alike = _moved_damper(tmp_path, point, c2)
        paper = truth_misfit(look_alike, reference=truth)
        second = truth_misfit(look_alike, reference=truth, frequencies_hz=band)
        assert paper.rms_sigma < 2.0, (point, paper)
        assert second.rms_sigma > 10.0, (point, second)
    # and the second band sees the damper itself, so the separation is not the band's noise
    assert truth_misfit(truth, frequencies_hz=band).rms_sigma > 10.0


@pytest.mark.slow
def test_one_mount_ties_with_the_group_in_the_papers_band_not_in_the_suspension_modes(
    tmp_path,
) -> None:
    # The same cubic under all four mount springs: in the paper's band the other three hardly
    # move (0.01 x noise measured); over the frame's suspension modes (9-17 Hz) the left corner
    # moves as much as the right (52 x noise measured). Tolerances: under 1 and over 10.
    text = TRUTH_DIR.joinpath("one_mount_hardens.toml").read_text()
    one = 'at = { node = "right_bottom", direction = "y" }\nparams = { k3 = "k3_mount_right_y" }\n'
    assert one in text
    group = "".join(
        f'\n[[nonlinear]]\nname = "mount_{c}_{d}_hardening"\nkind = "cubic_spring"\n'
        f'at = {{ node = "{c}_bottom", direction = "{d}" }}\n'
        'params = { k3 = "k3_mount_right_y" }\n'
        for c, d in (("left", "x"), ("left", "y"), ("right", "x"))
    )
    path = tmp_path / "all_mounts_harden.toml"
    path.write_text(text.replace(one, one + group))
    look_alike, truth = load_truth(path), load_truth("one_mount_hardens")
    assert len(look_alike.model.nonlinear) == len(truth.model.nonlinear) + 3
    suspension = np.round(np.arange(9.0, 17.01, 0.25), 6)
    assert truth_misfit(look_alike, reference=truth).rms_sigma < 1.0
    assert truth_misfit(look_alike, reference=truth, frequencies_hz=suspension).rms_sigma > 10.0


# -- the [truth] table, read through the declared settings ---------------------------------


def test_reference_truth_table_reads_to_the_values_the_file_gives() -> None:
    truth = load_truth("reference")
    assert (truth.seed, truth.drive_point, truth.hidden_effect) == (20160919, 3, "none")
    assert truth.noise == NoiseFloors(0.0008, 0.06, 1.0e-5)
    assert truth.shaker == ShakerConstants()  # the file repeats the shaker's defaults
    assert truth.amplifier == AmplifierConstants(
        gain_v_per_v=10.0, bandwidth_hz=20000.0, current_limit_a=5.0, output_resistance_ohm=0.05
    )
    assert truth.sensors == SensorDefaults(0.0055, 0.01, 16)
    assert truth.model.damping.per_mode == {1: 0.04, 2: 0.04, 3: 0.04, 4: 0.006, 5: 0.008}
    assert isinstance(truth.shaker.armature_mass_kg, float)


@pytest.mark.parametrize("name", ["reference", "clamp_friction", "mass_loading"])
def test_truth_table_round_trips_through_its_plain_data(name: str) -> None:
    truth = load_truth(name)
    table = build(TruthTable, truth.model.truth, name, at=("truth",))
    assert build(TruthTable, dump(table), name) == table
    assert (table.noise, table.shaker, table.amplifier, table.sensors) == (
        truth.noise,
        truth.shaker,
        truth.amplifier,
        truth.sensors,
    )


def _with_truth_lines(tmp_path, old: str, new: str):
    text = TRUTH_DIR.joinpath("reference.toml").read_text()
    assert old in text
    path = tmp_path / "edited.toml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize(
    ("old", "new", "path", "problem"),
    [
        ("force_n_per_rthz = 0.0008", "force_n_per_rthz = -1.0",
         ("truth", "noise", "force_n_per_rthz"), "must be >= 0"),
        ("coil_resistance_ohm = 1.5", "coil_resistance_ohm = 0.0",
         ("truth", "shaker", "coil_resistance_ohm"), "must be > 0"),
        ("bandwidth_hz = 20000.0", 'bandwidth_hz = "fast"',
         ("truth", "amplifier", "bandwidth_hz"), "expected a number"),
        ("gain_v_per_v = 10.0", "gain_v_per_v = 30.0",
         ("truth", "amplifier", "gain_v_per_v"), "outside the settable range"),
        ("adc_bits = 16", "adc_bits = 64", ("truth", "sensors", "adc_bits"), "must be <= 32"),
        ("seed = 20160919", "seed = -1", ("truth", "seed"), "must be >= 0"),
        ("drive_point = 3", "drive_point = 99", ("truth", "drive_point"), "is not a point"),
        ("drive_point = 3", "drive_point = 3\ndrive_pont = 4", ("truth",), "unknown key"),
        ("adc_bits = 16", "adc_bits = 16\nbits = 4", ("truth", "sensors"), "unknown key"),
    ],
)  # fmt: skip
def test_a_bad_truth_value_names_the_file_and_its_key_path(tmp_path, old, new, path, problem):
    with pytest.raises(ConfigError, match=problem) as info:
        load_truth(_with_truth_lines(tmp_path, old, new))
    assert info.value.path == path
    assert str(info.value).startswith(f"{tmp_path / 'edited.toml'}: {dotted(path)}: ")
