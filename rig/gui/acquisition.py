"""The acquisition window's panel: set up a run, control it, watch it live.

Left: :class:`~rig.gui.run_setup.RunSetupPanel`. Right: the run-control strip, the live plots
and the status panel (amplifier, alarms, pretest). Events arrive from the
:class:`~rig.gui.controller.RunController` on the GUI thread and are accumulated in a
:class:`~rig.gui.live_data.LiveRun`; a timer redraws a few times a second, so a fast run (the
simulated rig runs many times faster than real time) never floods the GUI.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from rig.config.plans import SteppedSinePlan
from rig.gui.controller import LocalRunController, RunController, RunEnd, RunRequest
from rig.gui.live_data import Alarm, LiveRun
from rig.gui.live_plots import LivePlots
from rig.gui.run_control import RunControls, RunStatusPanel
from rig.gui.run_setup import RunSetupPanel
from rig.run.events import Event, PretestFinished, RunFinished, RunPaused, RunResumed, RunStarted

__all__ = ["AcquisitionPanel"]

logger = logging.getLogger(__name__)

REDRAW_MS = 200


class AcquisitionPanel(QtWidgets.QWidget):
    """Set up, run and watch a test.

    Parameters
    ----------
    controller : RunController, optional
        Who runs the test (default: :class:`LocalRunController`, this process).

    Signals
    -------
    run_ended(object)
        The :class:`RunEnd` of a run (not of a pretest alone).
    """

    run_ended = QtCore.Signal(object)

    def __init__(
        self,
        controller: RunController | None = None,
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.controller = controller or LocalRunController(self)
        self.live = LiveRun()
        self.state = "idle"
        self.request: RunRequest | None = None
        self.last_end: RunEnd | None = None
        self.setup_panel = RunSetupPanel()
        self.controls = RunControls()
        self.plots = LivePlots()
        self.status = RunStatusPanel()
        self.controller_label = QtWidgets.QLabel(f"runs on: {self.controller.description}")
        self.controller_label.setStyleSheet("color: #555555;")

        self._lay_out()
        self._connect()

    def _lay_out(self) -> None:
        """The setup panel on the left; the controls, plots and status on the right."""
        left = QtWidgets.QWidget()
        lv = QtWidgets.QVBoxLayout(left)
        lv.setContentsMargins(0, 0, 0, 0)
        lv.addWidget(self.setup_panel, 1)
        lv.addWidget(self.setup_panel.status)
        lv.addWidget(self.controller_label)
        right = QtWidgets.QWidget()
        rv = QtWidgets.QVBoxLayout(right)
        rv.setContentsMargins(4, 0, 0, 0)
        rv.addWidget(self.controls)
        # plots above, alarms and pretest below, the border movable: on a small screen the
        # plots keep their axis labels and the operator drags more room to the messages
        below = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        below.addWidget(self.plots)
        below.addWidget(self.status)
        below.setStretchFactor(0, 1)
        below.setStretchFactor(1, 0)
        below.setSizes([800, 150])
        below.setChildrenCollapsible(False)
        rv.addWidget(below, 1)
        split = QtWidgets.QSplitter()
        split.addWidget(left)
        split.addWidget(right)
        split.setStretchFactor(0, 0)
        split.setStretchFactor(1, 1)
        split.setSizes([430, 1200])
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(split)

    def _connect(self) -> None:
        """The redraw timer, the buttons and the controller's signals; what the controller
        cannot supply said where it would show."""
        self._timer = QtCore.QTimer(self)
        self._timer.setInterval(REDRAW_MS)
        self._timer.timeout.connect(self.redraw)
        c = self.controls
        c.start.clicked.connect(self.start_run)
        c.pretest.clicked.connect(self.start_pretest)
        c.pause.clicked.connect(self.pause)
        c.resume.clicked.connect(self.resume)
        c.abort.clicked.connect(self.abort)
        self.status.clear_overload.clicked.connect(self.controller.clear_amplifier_overload)
        self.controller.event.connect(self.on_event)
        self.controller.ended.connect(self.on_ended)
        self.controller.amplifier.connect(self.status.show_amplifier)
        self.setup_panel.validity_changed.connect(self._validity_changed)
        self.setup_panel.check()
        if "amplifier" not in self.controller.supports:
            self.status.show_amplifier(f"status not available from {self.controller.description}")
        if "time-traces" not in self.controller.supports:
            self.plots.traces.force.getPlotItem().setTitle(
                f"no samples from {self.controller.description}"
            )
        if not isinstance(self.controller, LocalRunController):
            self.setup_panel.run_box.set_remote(self.controller.description)

    # -- commands --------------------------------------------------------------------------
    def start_run(self) -> bool:
        """Start the run the setup panel describes; False (with the reason shown) if not."""
        return self._start(pretest_only=False)

    def start_pretest(self) -> bool:
        """Run the plan's pretest alone (noise floor, loop check, channel checks)."""
        return self._start(pretest_only=True)

    def _start(self, pretest_only: bool) -> bool:
        if self.controller.busy:
            return False
        try:
            request = self.setup_panel.request(pretest_only=pretest_only)
        except ValueError as exc:
            self._alarm("fault", "setup", f"cannot start: {exc}")
            return False
        self.request = request
        self.live = LiveRun()
        self.status.clear()
        plan = request.plan
        if isinstance(plan, SteppedSinePlan):
            orders = plan.excitation.orders
            tol = plan.control.settings.fundamental_amplitude_tolerance
        else:
            orders, tol = (), 0.01
        self.plots.prepare(request.setup.channels_for_points(plan.points), orders, tol)
        self.plots.redraw(self.live, None)
        self._set_state("pretest" if pretest_only else "starting")
        self.controller.start(request)
        self._timer.start()
        return True

    def pause(self) -> None:
        self.controller.pause()

    def resume(self) -> None:
        self.controller.resume()

    def abort(self) -> None:
        self.controller.abort()
        self._set_state("aborting")

    # -- from the controller ---------------------------------------------------------------
    @QtCore.Slot(object)
    def on_event(self, event: Event) -> None:
        self.live.add(event)
        if isinstance(event, RunStarted):
            self._set_state("running")
        elif isinstance(event, RunPaused):
            self._set_state("paused")
        elif isinstance(event, RunResumed):
            self._set_state("running")
        elif isinstance(event, PretestFinished) and self.state == "starting":
            self._set_state("running")
        elif isinstance(event, RunFinished) and self.state != "pretest":
            self._set_state("finished")

    @QtCore.Slot(object)
    def on_ended(self, end: RunEnd) -> None:
        self.last_end = end
        if not end.started:
            self._alarm("fault", "start", f"the run could not start: {end.message}")
        for line in end.lines:
            key, _, rest = line.partition(" ")
            self._alarm("info", "summary", f"{key}: {rest.strip()}")
        pretest = self.request is not None and self.request.pretest_only
        if pretest and end.status == "success":
            self._alarm("info", "pretest", "pre-test finished")
        self.setup_panel.after_run(end.path)  # the next run gets a new file
        self._set_state(end.status)
        self.redraw()
        self._timer.stop()
        if not pretest:
            self.run_ended.emit(end)

    # -- display ---------------------------------------------------------------------------
    def redraw(self) -> None:
        """Bring the plots, progress and alarms up to date (the timer calls this)."""
        self.controls.show_progress(self.live)
        self.plots.redraw(self.live, self.controller.time_traces())
        self.status.show_alarms(self.live)

    def _alarm(self, severity: str, kind: str, message: str) -> None:
        self.live.alarms.append(Alarm(time.time(), severity, kind, message))
        self.live.revision += 1
        self.status.show_alarms(self.live)

    def _set_state(self, state: str) -> None:
        self.state = state
        ready = self.setup_panel.valid
        plan = self.setup_panel.plan
        pretest_ok = (
            isinstance(plan, SteppedSinePlan)
            and "pretest" in self.controller.supports
            and not self.setup_panel.settings_problem
        )
        self.controls.set_state(state, can_start=ready, can_pretest=pretest_ok)
        self.setup_panel.setEnabled(state in ("idle", "success", "aborted", "failed", "finished"))

    def _validity_changed(self, ok: bool, _problem: str) -> None:
        self._set_state(self.state)
        panel = self.setup_panel
        if ok and not self.controller.busy and isinstance(panel.plan, SteppedSinePlan):
            plan = panel.plan
            self.plots.prepare(
                panel.setup.channels_for_points(plan.points),
                plan.excitation.orders,
                plan.control.settings.fundamental_amplitude_tolerance,
            )

    def set_resume(self, path: Path, data) -> None:
        """Prepare to complete an unfinished file (from the run browser)."""
        self.setup_panel.set_resume(path, data)

    def shutdown(self) -> None:
        self.controller.shutdown()
