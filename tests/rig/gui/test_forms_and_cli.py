"""Settings forms against the settings dataclasses, the live-data accumulator, and ``rig gui``."""

from __future__ import annotations

import dataclasses

import pytest
from PySide6 import QtWidgets

from rig.config.plan_settings import AcquisitionSettings, PretestSettings
from rig.config.plans import load_plan, plan_from_dict
from rig.config.setup import load_setup, setup_from_dict
from rig.gui.live_data import LiveRun
from rig.gui.settings_fields import dataclass_fields, label_of, parse_value


def test_fields_are_generated_from_the_dataclasses():
    fields = dataclass_fields(AcquisitionSettings, "acquisition")
    assert [f.name for f in fields] == [f.name for f in dataclasses.fields(AcquisitionSettings)]
    kinds = {f.name: f.kind for f in fields}
    assert kinds["average_blocks"] == "integer" and kinds["ramp_s"] == "number"
    assert kinds["store_raw"] == "flag"
    labels = {f.name: f.label for f in dataclass_fields(PretestSettings)}
    assert labels["loop_check_drive_v"] == "loop check drive [V]"
    assert labels["noise_s"] == "noise [s]" and labels["min_snr"] == "min snr"
    assert label_of("acceleration_alarm_m_s2") == "acceleration alarm [m/s²]"
    tips = {f.name: f.tooltip for f in fields}
    assert "Base periods waited after a frequency or level change" in tips["settle_periods"]


def test_text_that_is_not_a_number_reaches_the_loader_as_typed():
    assert parse_value("numbers", "2, 8") == [2.0, 8.0]
    assert parse_value("numbers", "2, x") == [2.0, "x"]
    assert parse_value("integer", "2.5") == 2.5 and parse_value("integer", "") is None
    assert parse_value("words", "1, 1/2") == ["1", "1/2"]
    assert parse_value("flag", "no") is False


@pytest.mark.parametrize(
    "change, path, problem",
    [
        (
            lambda d: d["excitation"].update(levels_n=[2.0, -2.0]),
            ("excitation", "levels_n", 1),
            "must be > 0, got -2.0",
        ),
        (
            lambda d: d["frequencies"]["ranges"][0].update(stop_hz=20.0),
            ("frequencies", "ranges", 0, "stop_hz"),
            "is below start_hz (21.0), got 20.0",
        ),
        (
            lambda d: d["control"].update(max_iterations=0),
            ("control", "max_iterations"),
            "must be >= 1, got 0",
        ),
        (
            lambda d: d["control"].update(orders=[1]),
            ("control", "orders"),
            "set by excitation.orders, not here",
        ),
        (lambda d: d["excitation"].update(orders=[1, "x"]), ("excitation", "orders", 1), None),
        (
            lambda d: d["pretest"].update(noise_s="abc"),
            ("pretest", "noise_s"),
            "expected a number, got 'abc'",
        ),
    ],
)
def test_a_settings_error_carries_its_key_path(change, path, problem):
    from rig.config.tomlconfig import ConfigError

    data = load_plan("paper").to_dict()
    change(data)
    with pytest.raises(ConfigError) as err:
        plan_from_dict(data, "plan form")
    assert err.value.path == path
    assert str(err.value).startswith(f"plan form: {err.value.key}: ")
    if problem is not None:
        assert err.value.problem == problem


@pytest.mark.parametrize("name", ["paper", "quick", "linear"])
def test_every_setting_of_a_plan_goes_through_the_form_unchanged(qtbot, name):
    from rig.gui.plan_editor import PlanEditor

    editor = PlanEditor()
    qtbot.addWidget(editor)
    assert editor.load(name)
    plan, error = editor.check()
    assert error == "" and plan.to_dict() == load_plan(name).to_dict()
    assert plan_from_dict(editor.document() | {"kind": plan.kind}).to_dict() == plan.to_dict()


def test_every_setting_of_a_setup_goes_through_the_form_unchanged(qtbot, tmp_path):
    from rig.gui.setup_editor import SetupEditor

    editor = SetupEditor()
    qtbot.addWidget(editor)
    assert editor.load("reference")
    setup, error = editor.check()
    assert error == "" and setup.to_dict() == load_setup("reference").to_dict()
    saved = editor.save(tmp_path / "lab.toml")
    assert load_setup(saved).to_dict() == setup.to_dict()
    assert setup_from_dict(editor.document()).to_dict() == setup.to_dict()


def test_live_run_progress_and_time_left():
    from types import SimpleNamespace

    import numpy as np

    from rig.config.plans import PlannedStep
    from rig.run.events import RunPaused, RunResumed, RunStarted, StepFinished, StepStarted

    live = LiveRun()
    live.add(RunStarted("quick", "stepped-sine", 10, 2, "run.h5"), now=0.0)
    for i, t in enumerate((1.0, 3.0)):
        step = PlannedStep(2 + i, 0, 2.0, 23.0 + i, 1, i == 0)
        live.add(StepStarted(step, 10), now=t)
        record = SimpleNamespace(
            plan_index=2 + i,
            level_index=0,
            sweep_direction=1,
            frequency_hz=23.0 + i,
            force=np.array([2.0, 0.04, 0.04]),
            response=np.ones((2, 3)),
            control_iterations=3,
            control_converged=True,
            control_error=0.005,
        )
        live.add(StepFinished(record, None, ("force3", "acc7"), 3 + i, 10), now=t + 2.0)
    assert live.n_done == 4 and live.fraction_done == 0.4
    # 2 steps in this run took 4 s from the first step's start: 2 s per step, 6 steps left
    assert live.time_left_s(now=5.0) == pytest.approx(12.0)
    live.add(RunPaused("operator"), now=5.0)
    live.add(RunResumed(), now=15.0)
    assert live.time_left_s(now=15.0) == pytest.approx(12.0)  # the pause does not count
    f, lv, sweep, h = live.frf(1)
    assert f.tolist() == [23.0, 24.0] and np.allclose(h[:, 0], 0.5)
    assert live.levels_n() == {0: 2.0}


@pytest.mark.slow
def test_rig_gui_command_starts_the_window(qtbot, monkeypatch, damper_run, reference_model_file):
    from rig.cli.main import main
    from rig.gui.app import LabWindow
    from rig.gui.controller import LocalRunController

    with pytest.raises(SystemExit) as ended:
        main(["gui", "--help"])
    assert ended.value.code == 0
    shown: list[LabWindow] = []

    def event_loop(app) -> int:  # the window is up: look at it instead of waiting for the user
        shown.extend(w for w in app.topLevelWidgets() if isinstance(w, LabWindow))
        return 0

    monkeypatch.setattr(QtWidgets.QApplication, "exec", event_loop)
    args = ["gui", "--truth", "damper_p5", "--open", str(damper_run)]
    assert main([*args, "--model", str(reference_model_file)]) == 0
    window = shown[-1]
    qtbot.addWidget(window)
    assert isinstance(window.acquisition.controller, LocalRunController)
    panel = window.acquisition.setup_panel
    assert panel.valid and panel.plan.name == "quick" and panel.setup.name == "reference"
    assert panel.run_box.backend == "sim" and panel.run_box.options()["truth"] == "damper_p5"
    assert window.browser.path == damper_run and window.browser.step_count() == 15
    assert window.workbench.model is not None
