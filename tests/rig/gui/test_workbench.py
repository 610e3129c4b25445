"""The workbench: a run against a model, the diagnosis with its evidence, adding the effect with
the error falling, calibration and planning results."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PySide6 import QtCore

from analysis.events import Event, Iteration
from analysis.model import load_model
from tests.rig.gui.gui_helpers import make_window, screenshot

# a diagnosis and a calibration, each through the GUI
pytestmark = pytest.mark.slow

TASK_MS = 120_000


def _run_task(qtbot, bench, button, name: str) -> list:
    """Click ``button``, collect the task's progress events, wait for it to succeed."""
    reports: list = []
    with qtbot.waitSignal(bench.task_finished, timeout=TASK_MS) as blocker:
        qtbot.mouseClick(button, QtCore.Qt.MouseButton.LeftButton)
        assert bench.task is not None and bench.busy
        bench.task.progress.connect(reports.append)
    assert blocker.args == [name, True], bench.stage.text()
    assert not bench.busy
    return reports


def test_diagnosis_finds_the_damper_and_adding_it_brings_the_residual_to_the_noise(
    qtbot, lock_dir, damper_run, reference_model_file, tmp_path
):
    window = make_window(qtbot, lock_dir)
    bench = window.workbench
    window.tabs.setCurrentWidget(bench)
    assert not bench.compare_button.isEnabled()
    assert bench.open_run(damper_run) and bench.open_model(reference_model_file)

    _run_task(qtbot, bench, bench.compare_button, "compare")
    cmp = bench.comparison
    assert cmp.rms_over_noise > 5  # the model misses the damper
    assert bench.frfs.channel.currentText() == "acc7"
    assert len(bench.frfs.frf.magnitude[0].getPlotItem().listDataItems()) == 6  # 3 levels x 2
    grid = bench.residuals.map.values
    assert grid.shape == (3, 9) and np.nanmax(grid) > 5  # sensors x (orders x levels)

    form = bench.options.form
    for key, value in {
        "n_verify": "2",
        "n_refine": "4",
        "n_starts": "0",
        "workers": "1",
        "verify_iterations": "8",
    }.items():
        form.widget(f"diagnosis.{key}").setText(value)
    bench.options.locations.setText("point 5, point 6, point 7")
    bench.options.laws.setText("quadratic_damper, linear_damper, cubic_spring")
    reports = _run_task(qtbot, bench, bench.diagnose_button, "diagnosis")
    stages = {e.stage for e in reports}
    assert {"compared", "screen", "verified"} <= stages, stages
    assert all(isinstance(e, Event) for e in reports)
    d = bench.diagnosis
    assert d.verdict == "explained", d.summary()
    assert d.group[0].candidate.law.kind == "quadratic_damper"
    view = bench.diagnosis_view
    assert "EXPLAINED" in view.verdict.text() and "quadratic_damper" in view.verdict.text()
    assert view.evidence.count() == len(d.evidence.findings) > 0
    assert view.ranking.rowCount() == len(d.ranking) >= 2
    assert view.ranking.item(0, 2).text().startswith(d.ranking[0].candidate.label)
    assert bench.augment_button.isEnabled()
    screenshot(window, "workbench-diagnosis.png")
    bench.tabs.setCurrentWidget(bench.residuals)
    screenshot(window, "workbench-residual-map.png")

    bench.options.starts.setValue(0)
    reports = _run_task(qtbot, bench, bench.augment_button, "recalibration")
    assert any(isinstance(e, Iteration) for e in reports)
    assert bench.diagnosis_view.error.getPlotItem().listDataItems()  # the cost drawn
    added = bench.augmented
    assert added.candidate.law.kind == "quadratic_damper"
    assert added.after.rms_over_noise < 1.5 < 5 < added.before.rms_over_noise
    assert "→" in view.augment_summary.text()
    assert len(view.error.getPlotItem().listDataItems()) >= 1
    assert bench.comparison is added.after
    # measured, the model before (grey) and the augmented model, per level
    assert len(bench.frfs.frf.magnitude[0].getPlotItem().listDataItems()) == 9
    bench.tabs.setCurrentIndex(0)
    screenshot(window, "workbench-frfs.png")
    bench.tabs.setCurrentWidget(view)
    screenshot(window, "workbench-recalibrated.png")

    saved = bench.save_augmented(tmp_path / "augmented.toml")
    model = load_model(saved)
    assert any(name.startswith("c2_quadratic_damper") for name in model.parameters)


def test_planning_and_calibration_results(
    qtbot, lock_dir, damper_run, reference_model_file, calibration_file, tmp_path
):
    window = make_window(qtbot, lock_dir)
    bench = window.workbench
    window.tabs.setCurrentWidget(bench)
    assert bench.open_calibration(calibration_file)
    cal = bench.calibration_view
    assert cal.table.rowCount() == 3
    assert [cal.table.item(r, 0).text() for r in range(3)] == ["k_c", "gap", "v_c"]
    assert bench.data is not None  # the calibration's measurement was opened with it
    qtbot.mouseClick(cal.use_button, QtCore.Qt.MouseButton.LeftButton)
    assert bench.model_label.startswith("calibrated")
    gap = json.loads(calibration_file.read_text())["parameters"]["gap"]
    assert bench.model.parameters["gap"].value == gap

    view = bench.planning_view
    _run_task(qtbot, bench, view.run_button, "planning")
    result = view.result
    assert view.top.rowCount() == len(result["top"]) == 5
    assert view.top.item(0, 0).text() == "1"
    mac = view.mac.values
    assert mac.shape == (3, 3) and np.allclose(np.diag(mac), 1.0)
    assert "configurations" in view.summary.text()
    window.tabs.setCurrentWidget(bench)
    bench.tabs.setCurrentWidget(view)
    screenshot(window, "workbench-planning.png")

    saved = tmp_path / "plan.json"
    saved.write_text(json.dumps(result))
    view.top.setRowCount(0)
    assert bench.open_plan_json(saved) and view.top.rowCount() == 5
    assert not bench.open_plan_json(damper_run)  # not a plan: said, not raised
    assert "not a plan result" in bench.stage.text()
