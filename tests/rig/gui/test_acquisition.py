"""The acquisition window driven like an operator: validation, pre-test, a whole run with pause
and resume, abort and completing the file from the run browser, the amplifier's overload."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore

from analysis.measurement_file import read_measurement
from sim_backend.amplifier import AmplifierModel
from sim_backend.serial_amplifier import SimulatedAmplifierPort
from tests.rig.gui.gui_helpers import make_window, prepare_run, screenshot

RUN_MS = 60_000


def _click(qtbot, button) -> None:
    assert button.isEnabled(), f"{button.text()} is disabled"
    qtbot.mouseClick(button, QtCore.Qt.MouseButton.LeftButton)


def test_a_wrong_setting_is_shown_next_to_its_field(qtbot, lock_dir, tmp_path):
    window = make_window(qtbot, lock_dir)
    panel = prepare_run(window, tmp_path / "run.h5")
    controls = window.acquisition.controls
    assert controls.start.isEnabled()
    plan_form = panel.plan_editor.form
    plan_form.widget("excitation.levels_n").setText("2, -8")
    qtbot.waitUntil(lambda: not panel.valid, timeout=3000)
    message = plan_form.error_text("excitation.levels_n")
    assert "levels_n[1]" in message and "must be > 0" in message, message
    assert plan_form.error_text("excitation.orders") == ""
    assert not controls.start.isEnabled()
    panel.setCurrentWidget(panel.plan_editor)
    qtbot.wait(200)
    screenshot(window, "run-setup-validation.png")

    plan_form.widget("excitation.levels_n").setText("2, 8")
    plan_form.widget("points").setText("3, 6, 14")
    qtbot.waitUntil(lambda: plan_form.error_text("points") != "", timeout=3000)
    assert "no accelerometer at point(s) [14]" in plan_form.error_text("points")
    assert plan_form.error_text("excitation.levels_n") == ""
    plan_form.widget("points").setText("3, 6, 7")

    setup_form = panel.setup_editor.form
    table = setup_form.widget("channels").table
    table.item(
        2, [c.name for c in setup_form.widget("channels").columns].index("sensitivity")
    ).setText("-10.2")
    qtbot.waitUntil(lambda: setup_form.error_text("channels") != "", timeout=3000)
    assert "channels[2]" in setup_form.error_text("channels")
    assert "sensitivity" in setup_form.error_text("channels")
    assert not controls.start.isEnabled()
    table.item(
        2, [c.name for c in setup_form.widget("channels").columns].index("sensitivity")
    ).setText("10.21")
    qtbot.waitUntil(lambda: panel.valid, timeout=3000)
    assert controls.start.isEnabled()


def _pretest_alone(qtbot, acq, path) -> None:
    """A pretest alone: every check passes and no file is written."""
    controls, status = acq.controls, acq.status
    _click(qtbot, controls.pretest)
    qtbot.waitUntil(lambda: acq.last_end is not None, timeout=RUN_MS)
    assert acq.last_end.status == "success", acq.last_end.message
    assert not path.exists()  # a pretest alone writes no file
    report = acq.live.pretest
    assert report is not None and report.ok and report.gain_n_per_v is not None
    assert status.pretest.rowCount() == 4
    assert [status.pretest.item(r, 1).text() for r in range(4)] == ["ok"] * 4


def _next_file_is_new(acq, path) -> None:
    """The next run gets a new file next to this one: ready, and nothing is overwritten."""
    controls = acq.controls
    box = acq.setup_panel.run_box
    assert Path(box.path.text()) == path.with_name("quick-2.h5")
    assert acq.setup_panel.valid and controls.start.isEnabled() and not controls.pause.isEnabled()
    box.path.setText(str(path))
    assert not acq.setup_panel.check() and not controls.start.isEnabled()
    assert "quick.h5 exists" in acq.setup_panel.problem
    assert "'New file'" in acq.setup_panel.problem  # and says what to do
    box.path.setText(str(path.with_name("quick-2.h5")))


@pytest.mark.slow
def test_pretest_then_a_whole_run_with_pause_and_resume(qtbot, lock_dir, tmp_path):
    window = make_window(qtbot, lock_dir)
    path = tmp_path / "quick.h5"
    prepare_run(window, path)
    acq = window.acquisition
    controls = acq.controls

    _pretest_alone(qtbot, acq, path)

    acq.last_end = None
    _click(qtbot, controls.start)
    qtbot.waitUntil(lambda: acq.live.n_done >= 3, timeout=RUN_MS)
    _click(qtbot, controls.pause)
    qtbot.waitUntil(lambda: acq.state == "paused", timeout=10_000)
    assert controls.resume.isEnabled() and not controls.pause.isEnabled()
    done_at_pause = acq.live.n_done
    qtbot.wait(600)  # paused: nothing more is measured
    assert acq.live.n_done == done_at_pause
    _click(qtbot, controls.resume)
    qtbot.waitUntil(lambda: acq.live.n_done >= done_at_pause + 2, timeout=RUN_MS)
    acq.redraw()
    plots = acq.plots
    x, y = plots.traces._curves["acc7"].getData()
    assert x is not None and x.size > 100 and np.ptp(y) > 0  # the newest samples are drawn
    traces = acq.controller.time_traces()
    assert traces is not None and traces.data.shape[1] == 4 and np.ptp(traces.data[:, 0]) > 1.0
    assert len(plots.frf.magnitude[0].getPlotItem().listDataItems()) >= 1
    if acq.state == "running":
        screenshot(window, "acquisition-running.png")

    qtbot.waitUntil(lambda: acq.last_end is not None, timeout=RUN_MS)
    assert acq.last_end.status == "success", acq.last_end.message
    data = read_measurement(path)
    assert data.complete and data.n_steps == 10
    assert acq.live.n_done == 10 and len(acq.live.steps) == 10
    alarms = [a.message for a in acq.live.alarms]
    assert any(m.startswith("paused: paused by the operator") for m in alarms), alarms
    assert "resumed" in alarms
    # the FRFs drawn are the file's: |H| of acc7, order 1, at the 2 N level
    f, lv, sweep, h = acq.live.frf(acq.live.channel_names.index("acc7"))
    rows = lv == 0
    np.testing.assert_allclose(h[rows, 0], data.select(level_index=0).frf("acc7")[:, 0], rtol=1e-12)
    _next_file_is_new(acq, path)
    # the finished run opened in the browser
    assert window.browser.path == path and window.browser.step_count() == 10
    screenshot(window, "acquisition-finished.png")


@pytest.mark.slow
def test_abort_then_browse_the_interrupted_file_and_complete_it(qtbot, lock_dir, tmp_path):
    window = make_window(qtbot, lock_dir)
    path = tmp_path / "aborted.h5"
    prepare_run(window, path)
    acq, browser = window.acquisition, window.browser
    _click(qtbot, acq.controls.start)
    qtbot.waitUntil(lambda: acq.live.n_done >= 7, timeout=RUN_MS)
    _click(qtbot, acq.controls.abort)
    qtbot.waitUntil(lambda: acq.last_end is not None, timeout=RUN_MS)
    assert acq.last_end.status == "aborted"
    assert "aborted by the operator" in acq.last_end.message
    n_kept = read_measurement(path).n_steps
    assert 7 <= n_kept < 10

    # the interrupted run is in the browser: how it ended, its steps, its FRFs
    assert browser.path == path and browser.step_count() == n_kept
    assert "ABORTED" in browser.header.text() and "aborted by the operator" in browser.header.text()
    assert f"<b>{n_kept}</b> of 10" in browser.header.text()
    assert len(browser.frf.magnitude[0].getPlotItem().listDataItems()) >= 1
    window.tabs.setCurrentWidget(browser)
    screenshot(window, "run-browser.png")

    # complete it: the browser hands it back to the acquisition tab
    _click(qtbot, browser.resume_button)
    assert window.tabs.currentWidget() is acq
    assert acq.setup_panel.resume_path == path and acq.setup_panel.check()
    acq.last_end = None
    _click(qtbot, acq.controls.start)
    qtbot.waitUntil(lambda: acq.last_end is not None, timeout=RUN_MS)
    assert acq.last_end.status == "success", acq.last_end.message
    data = read_measurement(path)
    assert data.complete and data.n_steps == 10
    assert acq.live.n_done_at_start == n_kept and len(acq.live.steps) == 10 - n_kept
    assert browser.step_count() == 10 and "SUCCESS" in browser.header.text()


@pytest.mark.slow
def test_amplifier_status_overload_alarm_clear_and_resume(qtbot, lock_dir, tmp_path):
    model = AmplifierModel()
    model.enable()
    with SimulatedAmplifierPort(model) as port:
        window = make_window(
            qtbot, lock_dir, extra_backend_options={"amplifier": model}, amplifier_poll_s=0.2
        )
        panel = prepare_run(window, tmp_path / "amp.h5", sample_rate_hz=5120.0)
        panel.setup_editor.form.widget("amplifier.port").setText(port.port)
        assert panel.check(), panel.problem
        acq = window.acquisition
        status = acq.status
        _click(qtbot, acq.controls.start)
        qtbot.waitUntil(lambda: "ON" in status.amplifier.text(), timeout=RUN_MS)
        qtbot.waitUntil(lambda: acq.live.n_done >= 2, timeout=RUN_MS)
        model.force_overload("test: shaker short circuit")
        qtbot.waitUntil(lambda: acq.state == "paused", timeout=RUN_MS)
        qtbot.waitUntil(lambda: "OVERLOAD" in status.amplifier.text(), timeout=10_000)
        faults = [a for a in acq.live.alarms if a.severity == "paused"]
        assert faults and faults[0].kind == "amplifier-overload"
        assert "overload" in faults[0].message
        assert status.clear_overload.isEnabled()
        _click(qtbot, status.clear_overload)
        qtbot.waitUntil(lambda: "ON" in status.amplifier.text(), timeout=10_000)
        assert not model.state().overload
        _click(qtbot, acq.controls.resume)
        qtbot.waitUntil(lambda: acq.last_end is not None, timeout=RUN_MS)
        assert acq.last_end.status == "success", acq.last_end.message
        assert read_measurement(tmp_path / "amp.h5").n_steps == 10
        # the engine muted the amplifier at the end; the last status shows it
        qtbot.waitUntil(lambda: "MUTED" in status.amplifier.text(), timeout=10_000)
