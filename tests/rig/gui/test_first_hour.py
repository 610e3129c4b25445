"""A lab user's first hour: the GUI says why it cannot open a window instead of aborting, each
run gets a new file, "Compare with a model…" compares, and the expert settings of the diagnosis
wait behind "Advanced"."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from PySide6 import QtCore

from rig.gui.qt_check import XCB_LIBRARIES, display_problem, missing_xcb_libraries
from rig.gui.run_setup import fresh_run_path, next_free_path, runs_folder

ROOT = Path(__file__).resolve().parents[3]

# -- no display, missing system libraries --------------------------------------------------------


def _all_load(_name: str) -> bool:
    return True


def test_no_display_is_said_in_a_sentence():
    problem = display_problem({}, platform="linux", loads=_all_load)
    assert problem.startswith("no display: DISPLAY and WAYLAND_DISPLAY are unset")
    assert "xvfb-run" in problem


def test_headless_platforms_and_other_systems_need_no_display():
    for platform in ("offscreen", "minimal", "vnc"):
        assert display_problem({"QT_QPA_PLATFORM": platform}, platform="linux") == ""
    assert display_problem({}, platform="win32") == ""
    assert display_problem({}, platform="darwin") == ""
    wayland = {"WAYLAND_DISPLAY": "wayland-0", "XDG_SESSION_TYPE": "wayland"}
    assert display_problem(wayland, platform="linux", loads=lambda n: False) == ""


def test_missing_xcb_libraries_are_named_with_the_command_that_installs_them():
    absent = {"libxcb-cursor.so.0", "libxcb-icccm.so.4", "libxcb-keysyms.so.1"}
    problem = display_problem(
        {"DISPLAY": ":0"},
        platform="linux",
        loads=lambda name: name not in absent,
        x_server_answers=lambda d: pytest.fail("the libraries come first"),
    )
    assert "libxcb-cursor.so.0, libxcb-icccm.so.4, libxcb-keysyms.so.1" in problem
    assert problem.endswith("apt-get install -y libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1")


def test_an_x_server_that_does_not_answer_is_said():
    problem = display_problem(
        {"DISPLAY": ":77"}, platform="linux", loads=_all_load, x_server_answers=lambda d: False
    )
    assert problem.startswith("no display: the X server DISPLAY=:77 does not accept")
    fine = display_problem(
        {"DISPLAY": ":77"}, platform="linux", loads=_all_load, x_server_answers=lambda d: True
    )
    assert fine == ""


def test_the_library_check_loads_real_libraries():
    assert missing_xcb_libraries(lambda name: name in XCB_LIBRARIES) == []
    if sys.platform.startswith("linux"):
        missing = missing_xcb_libraries()
        assert set(missing) <= set(XCB_LIBRARIES)


@pytest.mark.slow
def test_rig_gui_without_a_display_exits_with_a_message_not_a_core_dump(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env.pop("QT_QPA_PLATFORM", None)
    env["CLEARANCE_RIG_RUNS"] = str(tmp_path / "runs")
    done = subprocess.run(
        [sys.executable, "-m", "rig", "gui"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2, done.stderr  # a usage error, not 134 (SIGABRT)
    assert "error: no display: DISPLAY and WAYLAND_DISPLAY are unset" in done.stderr
    assert "Could not load the Qt platform plugin" not in done.stderr
    assert not list(tmp_path.iterdir())


# -- a new file for every run ----------------------------------------------------------------------


def test_the_runs_folder_and_new_file_names(tmp_path, monkeypatch):
    monkeypatch.delenv("CLEARANCE_RIG_RUNS")
    assert runs_folder() == Path.home() / "clearance-rig-runs"
    monkeypatch.setenv("CLEARANCE_RIG_RUNS", str(tmp_path))
    assert runs_folder() == tmp_path
    now = time.mktime((2026, 3, 4, 5, 6, 7, 0, 0, -1))
    first = fresh_run_path(now=now)
    assert first == tmp_path / "run-20260304-050607.h5"
    first.touch()
    assert fresh_run_path(now=now) == tmp_path / "run-20260304-050607-2.h5"
    assert next_free_path(first, now=now + 60) == tmp_path / "run-20260304-050707.h5"
    beam = tmp_path / "beam.h5"
    beam.touch()
    assert next_free_path(beam) == tmp_path / "beam-2.h5"
    (tmp_path / "beam-2.h5").touch()
    assert next_free_path(beam) == tmp_path / "beam-3.h5"
    assert next_free_path(tmp_path / "beam-2.h5") == tmp_path / "beam-3.h5"


def test_the_default_file_is_new_and_an_existing_one_says_what_to_do(
    qtbot, tmp_path, monkeypatch, _runs_folder
):
    from rig.gui.run_setup import RunSetupPanel

    monkeypatch.chdir(tmp_path)
    panel = RunSetupPanel()
    qtbot.addWidget(panel)
    box = panel.run_box
    path = Path(box.path.text())
    assert path.parent == _runs_folder and path.name.startswith("run-")
    assert path.suffix == ".h5" and not path.exists()
    # the runs folder does not exist yet: it is made when the run starts
    assert panel.check(), panel.problem
    assert panel.request().path == path and _runs_folder.is_dir()
    assert not (tmp_path / "run.h5").exists()

    path.write_bytes(b"a run")  # the run wrote its file
    panel.after_run(path)
    new = Path(box.path.text())
    assert new != path and new.parent == _runs_folder and not new.exists()
    assert panel.valid and "ready" in panel.status.text()

    box.path.setText(str(path))  # the operator types the old name again
    assert not panel.check()
    assert panel.problem.startswith(f"{path.name} exists")
    assert "press 'New file'" in panel.problem and "'replace an existing file'" in panel.problem
    assert "New file" in box.path_error.text() and box.path_error.isVisibleTo(box)
    qtbot.mouseClick(box.new_file, QtCore.Qt.MouseButton.LeftButton)
    assert Path(box.path.text()) != path and panel.check()
    assert path.read_bytes() == b"a run"  # never overwritten

    box.path.setText(str(path))
    box.overwrite.setChecked(True)  # replacing is the operator's choice
    assert panel.check()
    panel.after_run(path)
    assert Path(box.path.text()) == path

    box.overwrite.setChecked(False)
    box.path.setText(str(tmp_path / "no" / "such" / "folder" / "x.h5"))
    assert not panel.check() and "does not exist" in panel.problem


# -- "Compare with a model…" compares ------------------------------------------------------------


@pytest.mark.slow
def test_compare_with_a_model_from_the_browser_shows_the_comparison(qtbot, lock_dir, damper_run):
    from tests.rig.gui.gui_helpers import make_window

    window = make_window(qtbot, lock_dir)
    browser, bench = window.browser, window.workbench
    assert browser.open(damper_run) and browser.workbench_button.isEnabled()
    assert bench.model is None and bench.comparison is None
    with qtbot.waitSignal(bench.task_finished, timeout=120_000) as blocker:
        qtbot.mouseClick(browser.workbench_button, QtCore.Qt.MouseButton.LeftButton)
        assert window.tabs.currentWidget() is bench and bench.busy
    assert blocker.args == ["compare", True], bench.stage.text()
    # the run against the reference rig: the FRFs, the residual maps and a sentence
    assert bench.run_row.path.text() == str(damper_run)
    assert bench.model_label == "reference rig (nominal)"
    cmp = bench.comparison
    assert cmp is not None and cmp.rms_over_noise > 1
    assert bench.tabs.currentWidget() is bench.frfs
    assert len(bench.frfs.frf.magnitude[0].getPlotItem().listDataItems()) == 6  # 3 levels x 2
    assert bench.frfs.note.text() == f"residual {cmp.rms_over_noise:.3g} x noise"
    assert bench.residuals.map.values.shape == (3, 9)
    assert "compared with reference rig (nominal): residual" in bench.stage.text()


# -- the expert settings of the diagnosis behind "Advanced" --------------------------------------


def test_expert_diagnosis_settings_are_behind_advanced_with_their_defaults(qtbot):
    from rig.gui.diagnosis_options import ADVANCED, BASIC, GUI_DIAGNOSIS, DiagnosisOptions
    from rig.gui.settings_fields import format_value

    options = DiagnosisOptions()
    qtbot.addWidget(options)
    options.show()
    form = options.form
    assert len(ADVANCED) >= 15 and set(ADVANCED).isdisjoint(BASIC)
    # a first-time user sees the candidates, the starts and the time budget, and no more
    for widget in (options.locations, options.laws, options.starts):
        assert widget.isVisible()
    for name in BASIC:
        assert form.widget(f"diagnosis.{name}").isVisible()
    assert options.advanced.toggle.isVisible() and not options.advanced.expanded
    assert "Advanced (" in options.advanced.toggle.text()
    for name in ADVANCED:
        widget = form.widget(f"diagnosis.{name}")
        assert not widget.isVisible(), name
        tip = widget.toolTip()
        default = "1 here" if name == "workers" else format_value(getattr(GUI_DIAGNOSIS, name))
        assert tip.split("Default: ")[1].startswith(default), (name, tip)
        assert len(tip.split("Default: ")[0].strip()) > 10, (name, tip)  # what it does
    assert options.settings() == GUI_DIAGNOSIS

    qtbot.mouseClick(options.advanced.toggle, QtCore.Qt.MouseButton.LeftButton)
    assert options.advanced.expanded
    assert all(form.widget(f"diagnosis.{n}").isVisible() for n in ADVANCED)
    qtbot.mouseClick(options.advanced.toggle, QtCore.Qt.MouseButton.LeftButton)
    assert not form.widget("diagnosis.n_verify").isVisible()

    # a wrong expert setting opens the section and is shown at its entry
    form.widget("diagnosis.rescreen_ratio").setText("2")
    with pytest.raises(ValueError, match="rescreen_ratio"):
        options.settings()
    assert options.advanced.expanded
    assert "must be < 1, got 2" in form.error_text("diagnosis.rescreen_ratio")
    qtbot.mouseClick(options.restore, QtCore.Qt.MouseButton.LeftButton)
    assert options.settings() == GUI_DIAGNOSIS


# -- the FRF grid's axes -----------------------------------------------------------------------


def test_frf_grid_axis_titles_have_units_and_fit_in_their_plots(qtbot):
    from rig.gui.frf_view import FrfPlots

    plots = FrfPlots()
    qtbot.addWidget(plots)
    plots.configure(["1", "2", "3"], "(m/s²)/N", "acc7")
    plots.resize(850, 200)  # shorter than the grid's least height: the plots keep theirs
    plots.show()
    qtbot.waitExposed(plots)
    for mag, ph in zip(plots.magnitude, plots.phase, strict=True):
        assert ph.getPlotItem().getAxis("bottom").labelText == "fundamental frequency [Hz]"
        assert not mag.getPlotItem().getAxis("bottom").style["showValues"]  # the phase's axis
        for plot in (mag, ph):
            item = plot.getPlotItem()
            for name in ("left", "bottom"):
                axis = item.getAxis(name)
                if not axis.label.isVisible() or not axis.labelText:
                    continue
                text = axis.label.toPlainText().strip()
                assert "[" in text and text.endswith("]"), text  # a unit on every title
                shown = plot.mapFromScene(axis.label.mapRectToScene(axis.label.boundingRect()))
                box = shown.boundingRect()
                inside = plot.viewport().rect().adjusted(-4, -4, 4, 4)  # the text's margins
                assert inside.contains(box), (text, box, plot.viewport().rect())
        assert mag.getPlotItem().getAxis("left").width() == ph.getPlotItem().getAxis("left").width()
    widths = {p.getPlotItem().getAxis("left").width() for p in plots.magnitude + plots.phase}
    assert len(widths) == 1  # the columns line up
