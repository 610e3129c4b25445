"""The acquisition window on the acquisition service: the run goes through the service's client
(submit, event stream, pause, resume) and is drawn as a run in this process is."""

from __future__ import annotations

import signal

import numpy as np
import pytest
from PySide6 import QtCore

from analysis.measurement_file import read_measurement
from rig.gui.app import LabWindow
from rig.gui.service_controller import ServiceRunController
from rig.service.codec import decode_event, encode_event
from tests.rig.service.conftest import Procs, ServiceProcess, bench  # noqa: F401

RUN_MS = 90_000


@pytest.fixture
def service(tmp_path, bench):  # noqa: F811 - the service tests' bench fixture
    procs = Procs()
    svc = ServiceProcess(procs, tmp_path / "service", bench).start()
    yield svc
    if svc.proc.poll() is None:
        svc.proc.send_signal(signal.SIGTERM)
        svc.proc.wait(60)
    assert not procs.cleanup()


def test_events_decode_to_what_the_engine_published():
    from analysis.measurement_file import StepRecord
    from rig.run.events import ControlIteration, StepFinished

    record = StepRecord(
        plan_index=3,
        level_index=1,
        sweep_direction=-1,
        frequency_target_hz=25.0,
        frequency_hz=25.01,
        force=np.array([2 + 1j, 0.04j, 0.04]),
        force_std=np.array([0.01, 0.002, 0.0]),
        response=np.arange(9).reshape(3, 3) * (1 - 2j),
        response_std=np.ones((3, 3)),
        drive=np.array([0.1, 0.01j, 0.0]),
        n_blocks=48,
        control_iterations=4,
        control_converged=True,
        control_error=0.004,
    )
    sent = StepFinished(record, None, ("force3", "acc3", "acc7"), 4, 10, True)
    got = decode_event(encode_event(sent, "r1", 7))
    assert isinstance(got, StepFinished) and got.n_done == 4 and got.time_s == sent.time_s
    np.testing.assert_array_equal(got.record.response, record.response)
    np.testing.assert_array_equal(got.record.force, record.force)
    assert got.record.sweep_direction == -1 and got.record.control_converged
    iteration = ControlIteration(
        3, 2, "continue", False, np.nan, 25.01, record.drive, record.force, record.force_std
    )
    back = decode_event(encode_event(iteration, "r1", 8))
    assert np.isnan(back.error) and back.iteration == 2
    np.testing.assert_array_equal(back.drive_v, record.drive)


@pytest.mark.slow
def test_a_run_on_the_service_drawn_live_with_pause_and_resume(qtbot, service, tmp_path):
    controller = ServiceRunController.connect(str(service.sdir))
    window = LabWindow(controller)
    qtbot.addWidget(window)
    window.resize(1600, 1000)
    window.show()
    acq = window.acquisition
    panel = acq.setup_panel
    assert not acq.controls.pretest.isEnabled()  # the service runs no pretest alone
    panel.run_box.path.setText(str(tmp_path / "on_service.h5"))
    assert panel.check(), panel.problem

    qtbot.mouseClick(acq.controls.start, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: acq.live.n_done >= 2, timeout=RUN_MS)
    qtbot.mouseClick(acq.controls.pause, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: acq.state == "paused", timeout=30_000)
    qtbot.mouseClick(acq.controls.resume, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: acq.last_end is not None, timeout=RUN_MS)

    end = acq.last_end
    assert end.status == "success", end.message
    assert end.path is not None and end.path.name == "on_service.h5"
    assert end.path.parent != tmp_path  # written in the service's results folder
    data = read_measurement(end.path)
    assert data.complete and data.n_steps == 10 == acq.live.n_done == len(acq.live.steps)
    assert acq.live.pretest is not None and acq.live.pretest.ok
    f, lv, sweep, h = acq.live.frf(acq.live.channel_names.index("acc7"))
    np.testing.assert_allclose(h[lv == 1, 0], data.select(level_index=1).frf("acc7")[:, 0])
    assert window.browser.path == end.path
