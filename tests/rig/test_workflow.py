"""The main job, ``rig workflow``, end to end on the simulated rig: the shipped random test, the
'quick' stepped-sine plan."""

import json

import pytest

from rig.cli.workflow import run_workflow

TRUTH_GAP_M = 0.60e-3  # the reference truth's gap
TRUTH_KC = 4.51e5


# every test shares the whole workflow run (several minutes)
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def workflow(tmp_path_factory):
    d = tmp_path_factory.mktemp("workflow")
    # the shipped random test, the 'quick' stepped-sine plan (2 and 8 N)
    out = d / "out"
    summary = run_workflow(out, plan="quick", starts=6, quiet=True, lock_dir=d / "locks")
    return out, summary


def test_every_stage_writes_its_files(workflow):
    out, summary = workflow
    for name in (
        "truth.json",
        "linear.h5",
        "paper.h5",
        "linear/calibrated_model.toml",
        "planning.json",
        "nonlinear/calibration.json",
        "nonlinear/crossval.json",
        "nonlinear/validation.json",
        "nonlinear/report.html",
        "summary.md",
        "workflow.json",
    ):
        assert (out / name).is_file(), name
    stages = [s["stage"] for s in json.loads((out / "workflow.json").read_text())["stages"]]
    assert stages == [
        "reference values",
        "random test",
        "linear calibration",
        "pretest planning",
        "stepped-sine run",
        "nonlinear calibration",
        "validation",
        "report",
    ]
    md = (out / "summary.md").read_text()
    headings = (
        "Verdict",
        "Linear calibration (Table 2)",
        "Pretest planning (Table 4)",
        "Nonlinear calibration (Table 5)",
        "Cross-validation",
        "Validation",
    )
    for heading in headings:
        assert f"## {heading}" in md


def test_the_calibrated_contact_is_near_the_truth(workflow):
    """From one calibration level (2 N) and 6 starts: gap within 5 %, k_c within 15 %."""
    _, summary = workflow
    p = summary["calibration"]["parameters"]
    assert abs(p["gap"] / TRUTH_GAP_M - 1) < 0.05
    assert abs(p["k_c"] / TRUTH_KC - 1) < 0.15
    assert summary["validation"]["level_n"] == 8.0
    ratios = summary["crossval"]["std_ratio"]
    assert len(ratios) == 3 and all(r > 0 for r in ratios)  # the folds moved


def test_every_parameter_is_shown_against_the_truth(workflow):
    """On the simulated rig the summary and the report compare every parameter, linear and
    nonlinear, with the truth the backend reported; the measurement files do not carry it."""
    import h5py

    out, summary = workflow
    truth = json.loads((out / "truth.json").read_text())["parameters"]
    table = summary["comparison"]
    assert set(table) == set(truth)
    for name, row in table.items():
        assert row["reference"] == pytest.approx(truth[name])
        lo, hi = row["interval_95"]
        assert lo < row["value"] < hi
        assert row["inside_95"] == (lo <= truth[name] <= hi)
    md = (out / "summary.md").read_text()
    assert (
        "| parameter | status | calibrated | 95 % interval | truth | error | error / sigma |" in md
    )
    for held in summary["linear"].get("held", {}):
        assert f"**{held}**" in md
    with h5py.File(out / "paper.h5") as f:
        names = []
        f.visit(names.append)
    assert not any("truth" in n.lower() for n in names)
