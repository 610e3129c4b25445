"""Truth structures: loading, the reference values, refusal by analysis, hidden effects."""

from __future__ import annotations

import pytest

from analysis.model import ModelFileError, load_model
from sim_backend.sizing import PaperTest, truth_misfit
from sim_backend.truth import TRUTH_DIR, list_truths, load_truth

HIDDEN = ("hardening_mounts", "clamp_friction", "two_sided_stop", "damper_p5", "mass_loading")
# A hidden effect outside the analysis library (a Jenkins element in the clamp).
OUTSIDE_LIBRARY = ("hysteretic_joint",)


def test_shipped_truths_are_listed_and_load() -> None:
    names = list_truths()
    assert set(names) == {"reference", *HIDDEN, *OUTSIDE_LIBRARY}
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
