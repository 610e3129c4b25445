"""The workbench's "Run the separating test": on a tie, the separating plan run on the opened
run's simulated rig, the tied candidates ranked again and the answer shown; where the test needs
the rig, the plan is written and the view says so."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import pytest
from PySide6 import QtCore

from analysis.diagnosis import compare
from analysis.diagnosis.candidates import Location
from analysis.measurement_file import read_measurement
from rig.config.plans import FrequencyPlan, FrequencyRange, load_plan
from rig.config.setup import load_setup
from rig.run.session import TestRun, open_rig
from tests.analysis.diagnosis.conftest import truth_as_model
from tests.rig.gui.gui_helpers import make_window, screenshot

# a first run and a separating run on the simulated rig, and two comparisons
pytestmark = pytest.mark.slow

TRUTH = {"truth": "damper_p4", "seed": 3}


@pytest.fixture(scope="module")
def first_run(tmp_path_factory, lock_dir) -> Path:
    """Two steps at 4 N below the first bending mode on damper_p4's simulated rig, recorded as
    the command line records a simulated run (backend, truth and seed)."""
    quick = load_plan("quick")
    plan = dataclasses.replace(
        quick,
        name="first",
        excitation=dataclasses.replace(quick.excitation, levels_n=(4.0,)),
        frequencies=FrequencyPlan((FrequencyRange(22.0, 23.0, 1.0),), "up"),
    )
    path = tmp_path_factory.mktemp("runs") / "first.h5"
    setup = load_setup("reference").with_sample_rate(5120.0)
    options = {**TRUTH, "sensor_masses_kg": setup.sensor_masses_kg()}
    info = {"backend": "sim", "backend_options": TRUTH}
    with open_rig("sim", setup, backend_options=options, lock_dir=lock_dir) as rig:
        summary = TestRun(rig.backend, plan, setup, path, run_info=info).execute()
    assert summary.status == "success" and summary.n_done == 2
    return path


def _candidate(label: str, model) -> SimpleNamespace:
    place = Location(label.split(" at ")[-1])
    return SimpleNamespace(
        candidate=SimpleNamespace(label=label, location=place),
        verified=SimpleNamespace(model_toml=model.to_toml(), parameters={}),
        rank=1,
        group=1,
        rms_over_noise=1.0,
        delta_bic=0.0,
    )


def _damper_at(point: int, c2: float):
    model = truth_as_model("damper_p4")
    text = model.to_toml().replace("point = 4 }", f"point = {point} }}")
    return type(model).from_toml_text(text, "<moved>").with_values({"c2_p4": c2})


def _tie(recommendation, comparison) -> SimpleNamespace:
    """What the workbench reads of a Diagnosis that ties two dampers (their first-mode work is
    alike: c2 phi^3 equal at points 4 and 5)."""
    group = [
        _candidate("quadratic_damper at point 4", _damper_at(4, 10.0)),
        _candidate("quadratic_damper at point 5", _damper_at(5, 3.45)),
    ]
    return SimpleNamespace(
        verdict="explained",
        group=group,
        ranking=group,
        recommendation=recommendation,
        settings=SimpleNamespace(tie_bic=10.0),
        comparison=comparison,
        timings={"total_s": 1.0},
        evidence=SimpleNamespace(findings=[]),
        screen=[],
        baseline=None,
        readout=None,
    )


RECOMMENDATION = {
    # the beam's second bending mode, where a damper at point 5 (on its node) does nothing:
    # two steps at 4 N (6 N would need about 5 A of the amplifier's 5 A)
    "best": {"sensor": 2, "level_n": 4.0, "start_hz": 151.0, "stop_hz": 152.0, "step_hz": 1.0},
    "candidates": ["quadratic_damper at point 4", "quadratic_damper at point 5"],
    "text": "add a sensor at point 2 at 4 N in 151-152 Hz",
}


def test_the_separating_test_runs_on_the_simulated_rig_and_names_the_answer(
    qtbot, lock_dir, first_run, reference_model_file, _runs_folder
):
    window = make_window(qtbot, lock_dir)
    bench = window.workbench
    window.tabs.setCurrentWidget(bench)
    assert bench.open_run(first_run) and bench.open_model(reference_model_file)
    assert not bench.separate_button.isEnabled()  # no diagnosis yet
    # the comparison a diagnosis starts from (the workbench draws it)
    cmp = compare(_damper_at(4, 10.0), read_measurement(first_run))
    no_tie = _tie(None, cmp)
    no_tie.group = no_tie.group[:1]
    bench._diagnosed(no_tie)
    assert not bench.separate_button.isEnabled()  # one candidate: nothing to separate
    bench._diagnosed(_tie(RECOMMENDATION, cmp))
    assert bench.separate_button.isEnabled()
    view = bench.diagnosis_view

    # a window on the acquisition service: the plan is written, the test is not run here
    local = bench.controller
    bench.controller = SimpleNamespace(description="the acquisition service at http://rig:8421")
    qtbot.mouseClick(bench.separate_button, QtCore.Qt.MouseButton.LeftButton)
    assert not bench.busy
    note = view.separation.text().replace("<br>", " ")
    assert "needs the rig" in note and "the acquisition service at http://rig:8421" in note
    plans = sorted(_runs_folder.glob("*.plan.toml"))
    assert [p.name for p in plans] == ["first-separate.plan.toml"]
    assert f"plan: {plans[0]}" in note
    bench.controller = local
    # a run made on the hardware: the same, said of the file
    on_ni = SimpleNamespace(config={"run": {"backend": "ni"}}, path=Path("beam.h5"))
    why = bench._needs_the_rig(on_ni)
    assert "beam.h5 was made on the 'ni' backend" in why and "needs the rig" in why

    with qtbot.waitSignal(bench.task_finished, timeout=180_000) as blocker:
        qtbot.mouseClick(bench.separate_button, QtCore.Qt.MouseButton.LeftButton)
        assert bench.busy and not bench.separate_button.isEnabled()
        reports: list = []
        bench.task.progress.connect(reports.append)
    assert blocker.args == ["separating test", True], bench.stage.text()
    sep = bench.separation
    # the damper at point 5 sits on the second mode's node: the run tells them apart
    assert sep.resolved and sep.tied == ["quadratic_damper at point 4"], sep.summary()
    assert sep.ranking[1]["delta_chi2"] > 10.0
    text = view.separation.text()
    assert "RESOLVED" in text and "quadratic_damper at point 4" in text
    # a numbered file (the plan's name was taken), on the first run's simulated rig
    new = read_measurement(_runs_folder / "first-separate-2.h5")
    assert new.n_steps == 2 and new.exit_status == "success"
    assert new.config["run"]["backend_options"] == TRUTH
    assert {ch.point for ch in new.channels} == {2, 3, 6, 7}
    qtbot.wait(50)  # the layout makes room for the new lines on the event loop
    screenshot(window, "workbench-separating-test.png")
