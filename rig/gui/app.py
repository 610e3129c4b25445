"""The lab GUI's main window and entry point (``python -m rig gui``).

Three tabs: *Acquisition* (set up, run and watch a stepped-sine test), *Run browser* (open a
finished or interrupted measurement file) and *Workbench* (a run against a model: FRFs,
residual maps, diagnosis, adding an effect, calibration and planning results). A run that ends
opens in the browser; the browser hands an unfinished run back to the acquisition tab to be
completed, and a finished one to the workbench.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from PySide6 import QtGui, QtWidgets

from rig.gui.acquisition import AcquisitionPanel
from rig.gui.controller import LocalRunController, RunController, RunEnd
from rig.gui.qt_check import binding_problem, display_problem
from rig.gui.run_browser import RunBrowser
from rig.gui.style import configure_app
from rig.gui.workbench import WorkbenchPanel

__all__ = ["LabWindow", "run_gui"]

logger = logging.getLogger(__name__)


class LabWindow(QtWidgets.QMainWindow):
    """Acquisition, run browser and workbench in one window.

    Parameters
    ----------
    controller : RunController, optional
        Who runs tests (default: this process, :class:`LocalRunController`).
    """

    def __init__(
        self,
        controller: RunController | None = None,
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.setWindowTitle("clearance-rig lab")
        self.acquisition = AcquisitionPanel(controller or LocalRunController())
        self.browser = RunBrowser()
        self.workbench = WorkbenchPanel(self.acquisition.controller)
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.addTab(self.acquisition, "Acquisition")
        self.tabs.addTab(self.browser, "Run browser")
        self.tabs.addTab(self.workbench, "Workbench")
        self.setCentralWidget(self.tabs)
        self.statusBar().showMessage(
            f"runs on {self.acquisition.controller.description}; files as the command line writes"
        )
        self.acquisition.run_ended.connect(self._run_ended)
        self.browser.resume_requested.connect(self._resume)
        self.browser.workbench_requested.connect(self._to_workbench)
        self._menu()

    def _menu(self) -> None:
        menu = self.menuBar().addMenu("&File")
        open_run = QtGui.QAction("Open a measurement file…", self)
        open_run.triggered.connect(self._open_dialog)
        quit_ = QtGui.QAction("Quit", self)
        quit_.setShortcut(QtGui.QKeySequence.StandardKey.Quit)
        quit_.triggered.connect(self.close)
        menu.addAction(open_run)
        menu.addSeparator()
        menu.addAction(quit_)

    def _open_dialog(self) -> None:
        self.browser._open_dialog()
        self.tabs.setCurrentWidget(self.browser)

    def _run_ended(self, end: RunEnd) -> None:
        if end.path is not None and Path(end.path).exists():
            self.browser.open(end.path)
            self.statusBar().showMessage(f"run {end.status}: {end.path} (in the run browser)")

    def _resume(self, path, data) -> None:
        self.acquisition.set_resume(Path(path), data)
        self.tabs.setCurrentWidget(self.acquisition)

    def _to_workbench(self, path) -> None:
        """The browser's "Compare with a model…": the run against the workbench's model."""
        self.tabs.setCurrentWidget(self.workbench)
        self.workbench.compare_run(path)

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:  # noqa: N802 - Qt's name
        if self.acquisition.controller.busy:
            answer = QtWidgets.QMessageBox.question(
                self,
                "A run is under way",
                "Abort the run (the drive ramps to 0 V, completed steps are kept) and quit?",
            )
            if answer != QtWidgets.QMessageBox.StandardButton.Yes:
                event.ignore()
                return
        self.acquisition.shutdown()
        self.workbench.shutdown()
        event.accept()


def run_gui(
    *,
    backend: str = "sim",
    plan: str | None = None,
    setup: str | None = None,
    truth: str | None = None,
    seed: int | None = None,
    out: str | None = None,
    open_file: str | None = None,
    model: str | None = None,
    service: bool = False,
    service_dir: str | None = None,
    service_url: str | None = None,
    controller: RunController | None = None,
) -> int:
    """Start the GUI and run its event loop until the window closes.

    Parameters
    ----------
    backend : {"sim", "ni"}
        Backend preselected for runs in this process.
    plan, setup : str, optional
        Built-in name or file to preselect (default: the ``quick`` plan and its setup).
    truth, seed : optional
        Simulated rig: the truth structure and the noise seed.
    out : str, optional
        Measurement file of the next run.
    open_file : str, optional
        A measurement file to show in the run browser.
    model : str, optional
        A model file for the workbench.
    service : bool
        Run tests on the acquisition service (its directory ``service_dir`` or its address
        ``service_url``) instead of in this process.
    controller : RunController, optional
        Who runs tests (default: this process, or the service).
    """
    problem = binding_problem()
    app = QtWidgets.QApplication.instance()
    if app is None:
        # Qt aborts the process when its platform plugin cannot load: say why before it tries
        problem = problem or display_problem()
    if problem:
        raise RuntimeError(problem)
    app = app or QtWidgets.QApplication(sys.argv[:1])
    configure_app(app)
    if controller is None and service:
        from rig.gui.service_controller import ServiceRunController

        controller = ServiceRunController.connect(service_dir, url=service_url)
    window = LabWindow(controller)
    panel = window.acquisition.setup_panel
    if plan:
        panel.plan_editor.load(plan)
    if setup:
        panel.setup_editor.load(setup)
    box = panel.run_box
    box.ni.setChecked(backend == "ni")
    if truth:
        box.truth.setCurrentText(truth)
    if seed is not None:
        box.seed.setText(str(seed))
    if out:
        box.path.setText(out)
    panel.check()
    if open_file:
        window.browser.open(open_file)
        window.tabs.setCurrentWidget(window.browser)
    if model:
        window.workbench.open_model(model)
    _fit_to_screen(window, app)
    window.show()
    return app.exec()


def _fit_to_screen(window, app, preferred=(1600, 1000)) -> None:
    """Open at the preferred size or the screen's free area, whichever is smaller: a window
    larger than a laptop's or a lab PC's screen hides its right column (the run's status and
    the higher orders' plots) with no way to see them but to maximise it."""
    screen = app.primaryScreen()
    if screen is None:
        window.resize(*preferred)
        return
    free = screen.availableGeometry()
    window.resize(min(preferred[0], free.width()), min(preferred[1], free.height()))
